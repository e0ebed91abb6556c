//! Scenario files: one TOML file describes a whole run (loop timing, robot, strip, contact,
//! references, controller gains, recording, safety). Every field is listed, with its unit, default,
//! valid range and meaning, in one table (`fields::FIELDS`, printed in `scenarios/README.md`);
//! loading checks every value against it before anything starts, and every error names the file,
//! the line (or that the value is a default) and the field. Lengths in files may carry an explicit
//! `_mm` suffix; everything is converted to SI by the accessors of the consumers.
//!
//! Every section has defaults equal to the default scenario (`scenarios/default.toml`), so a file
//! only lists what it changes.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

mod cell;
mod check;
pub mod fields;
pub use cell::{DrivesConfig, MismatchConfig, SensorConfig};
pub mod contour;
pub mod geometry;
pub mod path;
pub mod pieces_file;

/// Where a value of a scenario comes from, for messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// The file sets it on this line (1-based).
    Line(usize),
    /// The file does not set it: the built-in default (`fields::FIELDS` lists them).
    Default,
    /// A scenario built in code, not read from text: no line to name.
    Unstated,
}

impl std::fmt::Display for Place {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Place::Line(n) => write!(f, ", line {n}"),
            Place::Default => write!(f, ", default value (not set in the file)"),
            Place::Unstated => Ok(()),
        }
    }
}

/// Errors loading a scenario. Each names the file, the line (or that a default is meant) and the
/// field. A cause (the OS error of `Read`) is the error's `source()`, not part of its message, so
/// that `{:#}` chains print it once.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("cannot read scenario file {path}")]
    Read { path: PathBuf, source: std::io::Error },
    /// Not TOML.
    #[error("scenario file {path}, line {line}, column {column}: {message}")]
    Parse { path: PathBuf, line: usize, column: usize, message: String },
    /// A section or field (`what`) the table does not know (`known` lists what there is).
    #[error("scenario file {path}, line {line}: unknown {what} {key}; {known}")]
    Unknown { path: PathBuf, line: usize, what: &'static str, key: String, known: String },
    /// A value of the wrong type or out of its range.
    #[error("scenario file {path}{place}: field {field} = {value}: {why}")]
    Field { path: PathBuf, place: Place, field: String, value: String, why: String },
}

impl ScenarioError {
    /// The field (or section) the error is about, as `section.field`, `key[i]` for an element.
    pub fn field(&self) -> Option<&str> {
        match self {
            ScenarioError::Unknown { key, .. } => Some(key),
            ScenarioError::Field { field, .. } => Some(field),
            _ => None,
        }
    }

    /// Where the bad value stands.
    pub fn place(&self) -> Option<Place> {
        match self {
            ScenarioError::Parse { line, .. } | ScenarioError::Unknown { line, .. } => Some(Place::Line(*line)),
            ScenarioError::Field { place, .. } => Some(*place),
            ScenarioError::Read { .. } => None,
        }
    }
}

/// Loop mode of the plant (DESIGN section 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Absolute 1 ms deadlines, a torque budget per tick, misses held and counted.
    #[default]
    Realtime,
    /// Wait for every torque (with a watchdog); as fast as both processes allow; deterministic.
    Lockstep,
}

/// How the plant integrates the robot over one substep (the strip is always stepped exactly).
/// Both converge to the same tracking figures: the held contact wrench limits the coupled plant to
/// first order in the substep, so the robot integrator's own order shows only in free motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Explicit midpoint (second-order Runge–Kutta): 2 forward-dynamics calls per substep.
    #[default]
    Midpoint,
    /// Classic fourth-order Runge–Kutta: 4 forward-dynamics calls per substep.
    Rk4,
}

impl Integrator {
    /// The name used in scenario files and recording metadata.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Midpoint => "midpoint",
            Integrator::Rk4 => "rk4",
        }
    }
}

/// How the substrate holds the strip's bottom face (DESIGN section 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Boundary {
    /// All bottom DOFs fixed (double-sided tape).
    #[default]
    Bonded,
    /// Bottom normal fixed, frictionless in-plane.
    Sliding,
}

impl Boundary {
    /// The name used in scenario files.
    pub fn name(self) -> &'static str {
        match self {
            Boundary::Bonded => "bonded",
            Boundary::Sliding => "sliding",
        }
    }
}

impl Mode {
    /// Every mode, in the order the help lists them.
    pub const ALL: [Mode; 2] = [Mode::Realtime, Mode::Lockstep];

    /// The name used in scenario files, on command lines and in summaries.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Realtime => "realtime",
            Mode::Lockstep => "lockstep",
        }
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Mode::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| format!("unknown mode {s:?}: expected realtime or lockstep"))
    }
}

/// The whole scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Free text shown in summaries and recorded in the MCAP metadata.
    pub description: String,
    #[serde(rename = "loop")]
    pub loop_: LoopConfig,
    pub robot: RobotConfig,
    pub strip: StripConfig,
    pub bulge: BulgeConfig,
    /// Bumps, dips and seams along a windowed (long) strip (issue 25); empty by default.
    pub substrate: SubstrateConfig,
    pub placement: PlacementConfig,
    pub contact: ContactConfig,
    pub trajectory: TrajectoryConfig,
    pub controller: ControllerConfig,
    pub recording: RecordingConfig,
    pub safety: SafetyConfig,
    /// ABB Externally Guided Motion: the plant acts as the robot controller (off by default).
    pub egm: EgmConfig,
    /// The realistic cell's force/torque sensor (off by default: the exact wrench).
    pub sensor: SensorConfig,
    /// The realistic cell's drives and encoders (off by default: ideal drives).
    pub drives: DrivesConfig,
    /// What the controller believes against what the plant is (none by default).
    pub mismatch: MismatchConfig,
    /// A curved path on the substrate that the strip lies along (issue 26); none by default: the
    /// straight strip along base +x.
    pub contour: ContourConfig,
}

/// Reflex limits of the plant (DESIGN section 10): crossing one puts the plant into safe stop at
/// once, with an `/events` entry and `state_flags::REFLEX`. The joint speed limits are the robot's
/// own (`robot::params::VELOCITY_LIMIT_RADPS`), not a scenario value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// TCP speed limit, m/s (ISO 10218-1's reduced speed, 0.25 m/s, by default).
    pub max_tcp_speed_mps: f64,
    /// Contact force limit, magnitude of the wheel–strip force, N.
    pub max_contact_force_n: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self { max_tcp_speed_mps: 0.25, max_contact_force_n: 40.0 }
    }
}

/// ABB Externally Guided Motion (DESIGN section 11): with `enabled`, `plant-sim` acts as the
/// IRB 2400's controller. Every `cycle_s` it sends `EgmRobot` to the sensor at `sensor_address`
/// and takes its `EgmSensor` joint references; an emulated motion controller (reference delay,
/// position correction with a low-pass, joint servo with model feed-forward) turns them into the
/// torques the plant integrates. Defaults and their reasons: `plant-sim/README.md`, "EGM".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EgmConfig {
    pub enabled: bool,
    /// UDP address of the EGM sensor (the client program), `host:port`.
    pub sensor_address: String,
    /// EGM cycle, s: one `EgmRobot` and one `EgmSensor` per cycle (ABB: typically 4 ms).
    pub cycle_s: f64,
    /// No valid sensor message for this long ends the EGM session (the robot holds), s.
    pub comm_timeout_s: f64,
    /// Total lag from a sensor's joint reference to the joint following it on a ramp, s.
    pub lag_s: f64,
    /// Bandwidth of the position correction's first-order low-pass on the references, Hz.
    pub lowpass_hz: f64,
    /// EGM position-correction gain (ABB's `\PosCorrGain`, 0..1): 1 follows the position
    /// references, 0 only the speed references.
    pub pos_corr_gain: f64,
    /// Joint servo: natural frequency of the joint position/velocity loop, Hz.
    pub servo_bandwidth_hz: f64,
    /// Joint servo: damping ratio.
    pub servo_damping_ratio: f64,
    /// The EGM force controller's design target: phase margin of its force loop, degrees.
    pub force_phase_margin_deg: f64,
}

impl Default for EgmConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            sensor_address: "127.0.0.1:6510".into(),
            cycle_s: 0.004,
            comm_timeout_s: 1.0,
            lag_s: 0.012,
            lowpass_hz: 20.0,
            pos_corr_gain: 1.0,
            servo_bandwidth_hz: 30.0,
            servo_damping_ratio: 1.0,
            force_phase_margin_deg: 60.0,
        }
    }
}

impl EgmConfig {
    /// Ramp lag of the position correction, s: `1 / (pos_corr_gain 2π lowpass_hz)` (infinite at
    /// gain 0, where only speed references move the robot).
    pub fn correction_lag_s(&self) -> f64 {
        1.0 / (self.pos_corr_gain * 2.0 * std::f64::consts::PI * self.lowpass_hz)
    }

    /// The pure delay in front of the correction, s: the total lag less the correction's and
    /// less half a control period (the joint servo's torque is held over a tick, so the joint
    /// follows its reference half a tick behind). Gain 0: no correction lag.
    pub fn delay_s(&self, period_s: f64) -> f64 {
        let correction = if self.pos_corr_gain > 0.0 { self.correction_lag_s() } else { 0.0 };
        self.lag_s - correction - 0.5 * period_s
    }
}

/// Loop contract (DESIGN section 6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    pub mode: Mode,
    /// Control period, s.
    pub period_s: f64,
    /// Real-time mode: how long after publishing the state the plant waits for the torque, µs.
    pub torque_budget_us: f64,
    /// Consecutive misses that trigger the safe stop (libfranka stops after 20).
    pub max_consecutive_misses: u32,
    /// Lockstep mode: how long the plant waits for one torque before declaring the controller dead, s.
    pub lockstep_watchdog_s: f64,
    /// Run length, s (the launcher may override it). 0 = until the trajectory ends plus 0.2 s.
    pub duration_s: f64,
    /// Plant integration substeps per tick (robot integrator and strip ZOH steps).
    pub substeps: u32,
    /// Robot integrator per substep: "midpoint" (default) or "rk4".
    pub integrator: Integrator,
    /// Joint damping of the compliant hold (before the first answer, after a reflex: gravity
    /// compensation plus this damping), N m s/rad.
    pub safe_stop_damping_nms: f64,
    /// Bandwidth of the plant's position hold (every safe stop but a reflex's), Hz: each joint
    /// critically damped at it; 0 = a compliant hold.
    pub hold_bandwidth_hz: f64,
    /// How long the torque is blended from the held value to a new controller's value, s.
    pub takeover_blend_s: f64,
    /// Consecutive missed ticks of the active controller after which another controller that is
    /// publishing may take over (one controller at a time, DESIGN section 10).
    pub takeover_after_misses: u32,
    /// How long a peer that is alive (its iceoryx2 node is not dead) but silent is waited for
    /// before it is treated as dead, s (a stalled host or SIGSTOP is not a death).
    pub peer_stall_timeout_s: f64,
    /// How long `rig` waits, from the plant's first state, for the controller process it started
    /// to answer one (in lockstep: tick 0), s; a controller alive but silent that long is named, with what `rig`
    /// saw of it, and the run ends with exit 3.
    pub connect_timeout_s: f64,
    /// Real-time mode: the plant busy-polls for the torque this long after publishing before it
    /// sleeps on the event, µs (0 = never spin). Trades CPU for wake-up latency on VMs.
    pub spin_wait_us: f64,
    /// Real-time mode: the controller busy-polls for the next state from this long before it is
    /// due until this long after, µs (0 = always sleep on the event). Costs up to twice this much
    /// CPU per tick; saves the controller's wake-up from the round trip.
    pub controller_spin_us: f64,
    /// While the plant runs (either mode), hold the kernel's PM QoS CPU latency request at 0
    /// (`/dev/cpu_dma_latency`, as cyclictest does) so idle CPUs poll instead of halting and wake
    /// at once. Needs root; refused requests are logged and the run goes on. Only a cpuidle
    /// governor reads the request: on a kernel without a cpuidle driver it changes nothing (the
    /// plant's log says so).
    pub idle_poll: bool,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Realtime,
            period_s: 1e-3,
            torque_budget_us: 500.0,
            max_consecutive_misses: 20,
            lockstep_watchdog_s: 2.0,
            duration_s: 0.0,
            substeps: 8,
            integrator: Integrator::Midpoint,
            safe_stop_damping_nms: 20.0,
            hold_bandwidth_hz: 5.0,
            takeover_blend_s: 0.05,
            takeover_after_misses: 3,
            peer_stall_timeout_s: 5.0,
            connect_timeout_s: 5.0,
            spin_wait_us: 100.0,
            controller_spin_us: 100.0,
            idle_poll: true,
        }
    }
}

/// Robot and tool (DESIGN section 3); `plant_inertia_scale` ≠ 1 makes the plant's links heavier or
/// lighter than the controller's model (robustness studies).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    pub tool_mass_kg: f64,
    /// Tool centre point (wheel centre) offset from the flange along the flange z axis, m.
    pub tool_offset_m: f64,
    pub wheel_radius_mm: f64,
    /// Reflected motor inertia per joint, kg m².
    pub armature_kgm2: [f64; 6],
    /// Viscous joint friction, N m s/rad.
    pub viscous_nms: [f64; 6],
    /// Scale of every link and tool mass and inertia in the plant (1 = exact model).
    pub plant_inertia_scale: f64,
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            tool_mass_kg: 1.0,
            tool_offset_m: 0.1,
            wheel_radius_mm: 10.0,
            armature_kgm2: [0.0; 6],
            viscous_nms: [0.0; 6],
            plant_inertia_scale: 1.0,
        }
    }
}

/// Weatherstrip model (DESIGN section 4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StripConfig {
    /// `false` runs the robot alone (no strip, no contact).
    pub enabled: bool,
    pub length_mm: f64,
    pub element_mm: f64,
    pub youngs_modulus_pa: f64,
    pub poisson: f64,
    pub density_kg_m3: f64,
    /// Reduced model order (states).
    pub order: usize,
    /// How the substrate holds the bottom face.
    pub boundary: Boundary,
    /// Craig–Bampton fixed-interface mode cut-off, Hz.
    pub cutoff_hz: f64,
    /// Rayleigh damping B = alpha M + beta K (5.24).
    pub damping_alpha: f64,
    pub damping_beta: f64,
    /// Length of one window of a long strip, mm (issue 25): the strip is carried by a chain of
    /// overlapping windows, each the reduced model of a strip this long. 0 = one model of the
    /// whole strip (today's; the default).
    pub window_mm: f64,
    /// Distance between neighbouring windows' starts, mm (at most a quarter of `window_mm`, so
    /// the wheel stays a quarter window off the ends of the windows that carry it).
    pub window_spacing_mm: f64,
}

impl Default for StripConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            length_mm: 40.0,
            element_mm: 1.0,
            youngs_modulus_pa: 3.46e6,
            poisson: 0.49,
            density_kg_m3: 1080.0,
            order: 250,
            boundary: Boundary::Bonded,
            cutoff_hz: 2500.0,
            damping_alpha: 60.0,
            damping_beta: 3e-6,
            window_mm: 0.0,
            window_spacing_mm: 10.0,
        }
    }
}

/// Substrate bulge under the strip: a raised-cosine bump.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BulgeConfig {
    pub height_mm: f64,
    pub half_width_mm: f64,
    pub center_mm: f64,
}

impl Default for BulgeConfig {
    fn default() -> Self {
        Self { height_mm: 0.2, half_width_mm: 10.0, center_mm: 20.0 }
    }
}

/// Most rows `substrate.bumps` (and `substrate.seams`) may hold.
pub const MAX_SUBSTRATE_FEATURES: usize = 64;

/// The substrate along a windowed strip (issue 25): every bump or dip and every seam between two
/// panels, each a static offset of the linear model. Only a windowed strip (`strip.window_mm` >
/// 0) takes them; the single-model strip has its one `[bulge]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct SubstrateConfig {
    /// `[[center_mm, half_width_mm, height_mm], ...]`: raised-cosine bumps (negative height: dips).
    pub bumps: Vec<[f64; 3]>,
    /// `[[position_mm, step_mm, smoothing_mm], ...]`: the substrate steps by `step_mm` (negative:
    /// down) along a raised-cosine ramp `smoothing_mm` long centred on `position_mm`.
    pub seams: Vec<[f64; 3]>,
}

/// Most pieces `contour.pieces` may hold (written inline or read from `contour.pieces_file`).
pub const MAX_CONTOUR_PIECES: usize = 4096;

/// A contour on the substrate (issue 26, `scenarios/src/contour.rs`): the strip's start is
/// `[placement]`'s point, and it runs along these pieces from there, its arc length the strip's
/// z. The roll follows a time law along the arc length (`contour::TimeLaw`), not
/// `trajectory.roll_s`'s cosine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContourConfig {
    /// `[[line_mm, radius_mm, turn_deg], ...]`: a line `[length, 0, 0]` or an arc
    /// `[0, radius, turn]` (positive turn: to the left, seen from above), each continuing the
    /// tangent of the one before. Empty: no contour (the straight strip).
    pub pieces: Vec<[f64; 3]>,
    /// A file of segments that gives `pieces` instead (`pieces_file.rs`), relative to the
    /// scenario file. Empty: none.
    pub pieces_file: String,
    /// Heading of the contour at its start, from base +x towards base +y, degrees.
    pub heading_deg: f64,
    /// The contour closes on its start (a sunroof's opening): its end must meet its start with
    /// the start's tangent.
    pub closed: bool,
    /// Rolling speed on the straight pieces, mm/s.
    pub speed_mm_s: f64,
    /// Tangential acceleration of the time law (speeding up, slowing down), mm/s².
    pub accel_mm_s2: f64,
    /// The time law's rule in arcs: the rolling speed stays at or below sqrt(a_lat R), mm/s².
    pub lateral_accel_mm_s2: f64,
}

impl Default for ContourConfig {
    fn default() -> Self {
        Self {
            pieces: Vec::new(),
            pieces_file: String::new(),
            heading_deg: 0.0,
            closed: false,
            speed_mm_s: 80.0,
            accel_mm_s2: 100.0,
            lateral_accel_mm_s2: 50.0,
        }
    }
}

impl ContourConfig {
    /// True when the scenario gives a contour.
    pub fn is_given(&self) -> bool {
        !self.pieces.is_empty()
    }
}

/// Where the strip lies in the robot base frame (DESIGN section 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlacementConfig {
    /// Base z of the table top (strip bottom), m.
    pub table_z_m: f64,
    /// Base x of the strip's start (task z = 0), m.
    pub strip_start_x_m: f64,
    /// Base y of the strip's centre line (task x = 0), m.
    pub strip_y_m: f64,
}

impl Default for PlacementConfig {
    fn default() -> Self {
        Self { table_z_m: 0.70, strip_start_x_m: 0.88, strip_y_m: 0.0 }
    }
}

/// Wheel–strip contact law (unilateral penalty with damping).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactConfig {
    pub stiffness_n_per_m: f64,
    pub damping_ns_per_m: f64,
}

impl Default for ContactConfig {
    fn default() -> Self {
        Self { stiffness_n_per_m: 1.0e6, damping_ns_per_m: 50.0 }
    }
}

/// Most points `trajectory.force_ref_along_z` may hold (the controller keeps them in a fixed
/// array: nothing is allocated on its 1 kHz path).
pub const MAX_FORCE_POINTS: usize = 32;

/// References (thesis Figure 6.6, plus approach and lift-off).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrajectoryConfig {
    /// Start height of the wheel's lowest point above the undeformed strip top, mm.
    pub approach_height_mm: f64,
    /// Time to hold the start pose before moving, s.
    pub settle_s: f64,
    /// Approach speed towards the strip until contact is detected, mm/s.
    pub approach_speed_mm_s: f64,
    /// Contact detection threshold on |F|, N.
    pub contact_threshold_n: f64,
    /// Force set-point on the strip while rolling, N (negative = pressing, thesis sign).
    pub force_ref_n: f64,
    /// Optional force set-point along the strip: `[[z_mm, force_n], ...]`, z strictly ascending,
    /// linear in between and held beyond the ends. When given it replaces `force_ref_n` from the
    /// force ramp to the ramp-down (a process plan that presses harder where the substrate's
    /// shape eats the bond pressure; `rig model bond` computes what the strip needs).
    pub force_ref_along_z: Vec<[f64; 2]>,
    /// Force ramp time, s.
    pub force_ramp_s: f64,
    /// Dwell at full force before rolling, s.
    pub dwell_s: f64,
    pub z_start_mm: f64,
    pub z_end_mm: f64,
    /// Rolling time with the cosine velocity profile, s.
    pub roll_s: f64,
    /// Force ramp-down time after rolling, s.
    pub ramp_down_s: f64,
    /// Lift-off height above the strip after the ramp-down, mm.
    pub lift_mm: f64,
    pub lift_s: f64,
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        Self {
            approach_height_mm: 3.0,
            settle_s: 0.1,
            approach_speed_mm_s: 10.0,
            contact_threshold_n: 0.5,
            force_ref_n: -10.0,
            force_ref_along_z: Vec::new(),
            force_ramp_s: 0.3,
            dwell_s: 0.2,
            z_start_mm: 2.0,
            z_end_mm: 38.0,
            roll_s: 2.0,
            ramp_down_s: 0.2,
            lift_mm: 3.0,
            lift_s: 0.3,
        }
    }
}

/// Controller gains (the force loop's follow from the design rule, controller::gains).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// Desired crossover of the force loop, Hz (Section 6.2: about 25 Hz).
    pub force_crossover_hz: f64,
    /// Integral action on the force error (the thesis has none).
    pub force_integral: bool,
    /// Integral gain relative to the crossover: ki = ratio * 2 pi f_c (1/s).
    pub force_integral_ratio: f64,
    /// Anti-windup clamp on the integral's contribution, N.
    pub force_integral_limit_n: f64,
    /// Feed the force set-point's rate forward as the wheel velocity the strip's stiffness asks
    /// for (dF_r/dt / strip_stiffness_n_per_m): a changing set-point is then followed without the
    /// lag of the loop. The thesis has none.
    pub force_rate_feedforward: bool,
    /// Translational PD bandwidth (other directions), Hz, and damping ratio.
    pub motion_bandwidth_hz: f64,
    pub motion_damping_ratio: f64,
    /// Rotational PD bandwidth, Hz.
    pub rotation_bandwidth_hz: f64,
    /// Joint-space damping added in the null of nothing (small, for the wrist), N m s/rad.
    pub joint_damping_nms: f64,
    /// Driving-point stiffness of the strip under the wheel, N/m: the force-loop design rule's
    /// plant (controller::gains). The controller does not link the strip model, so the value
    /// comes from here; the default is 1/G(0) of the default reduced model (1 mm mesh, bonded)
    /// under the wheel at z_a = 20 mm, as `rig design` reports it.
    pub strip_stiffness_n_per_m: f64,
    /// Tare in free air: for this long from its first state (the start pose, before the
    /// approach) the controller averages the measured wrench less the tool's nominal load and
    /// takes the mean as the sensor's offset, s (0: no tare).
    pub tare_s: f64,
    /// Subtract the tool's nominal gravity load (mass and centre of `robot.*` as the controller
    /// believes them, rotating with the tool) from the measured wrench.
    pub tool_load_compensation: bool,
    /// First-order low-pass on the measured wrench, Hz (0: none).
    pub force_filter_hz: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            force_crossover_hz: 25.0,
            force_integral: true,
            force_integral_ratio: 0.2,
            force_integral_limit_n: 5.0,
            force_rate_feedforward: true,
            motion_bandwidth_hz: 10.0,
            motion_damping_ratio: 1.0,
            rotation_bandwidth_hz: 10.0,
            joint_damping_nms: 0.0,
            strip_stiffness_n_per_m: 2.87e4,
            tare_s: 0.0,
            tool_load_compensation: false,
            force_filter_hz: 0.0,
        }
    }
}

/// Recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    pub enabled: bool,
    /// Bounded queue between the loop thread and the writer thread, records.
    pub queue_capacity: usize,
    /// MCAP chunk size bound, bytes (a killed run loses at most the open chunk).
    pub chunk_size_bytes: u64,
    /// Rate of the Foxglove transforms and strip scene, Hz of simulated time (decimated from
    /// the ticks on the writer thread).
    pub scene_rate_hz: f64,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        Self { enabled: true, queue_capacity: 8192, chunk_size_bytes: 512 * 1024, scene_rate_hz: 100.0 }
    }
}

impl Scenario {
    /// Parse a scenario from TOML text and check every field (`fields::FIELDS`); `path` is only
    /// used in error messages.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let spans = check::walk(text, path)?;
        let s: Scenario = toml::from_str(text).map_err(|e| {
            // The walk checked every type the table knows; what serde still refuses (a count
            // too large for its integer type) is named by the field whose value holds the span.
            let at = e.span().and_then(|sp| spans.field_at(sp.start));
            match at {
                Some((field, line)) => ScenarioError::Field {
                    path: path.to_path_buf(),
                    place: Place::Line(line),
                    field: field.to_string(),
                    value: e.span().and_then(|sp| text.get(sp)).unwrap_or("?").trim().to_string(),
                    why: e.message().trim().to_string(),
                },
                None => check::syntax_error(text, path, &e),
            }
        })?;
        let mut spans = spans;
        let mut s = s;
        let file = Self::read_pieces_file(&mut s, path, &mut spans)?;
        check::values(&s, path, Some(&spans)).map_err(|e| match &file {
            Some(f) => f.relocate(e),
            None => e,
        })?;
        Ok(s)
    }

    /// `contour.pieces_file`'s rows into `contour.pieces` (see `pieces_file`); errors about the
    /// whole list then name the `pieces_file` line.
    fn read_pieces_file(s: &mut Scenario, path: &Path, spans: &mut check::Spans) -> Result<Option<pieces_file::PiecesFile>, ScenarioError> {
        let name = s.contour.pieces_file.clone();
        if name.is_empty() {
            return Ok(None);
        }
        let bad = |why: String| ScenarioError::Field {
            path: path.to_path_buf(),
            place: spans.place("contour.pieces_file"),
            field: "contour.pieces_file".into(),
            value: format!("{name:?}"),
            why,
        };
        if !s.contour.pieces.is_empty() {
            return Err(bad("must be left out when contour.pieces is given: a contour's pieces come from one place".into()));
        }
        let file_path = pieces_file::resolve(path, &name);
        let file = match pieces_file::read(&file_path) {
            Err(ScenarioError::Read { source, .. }) => {
                return Err(bad(format!("must name a readable file of pieces ({}: {source})", file_path.display())))
            }
            other => other?,
        };
        s.contour.pieces = file.rows.clone();
        spans.alias("contour.pieces", "contour.pieces_file");
        Ok(Some(file))
    }

    /// Load and validate a scenario file.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, path)
    }

    /// The default scenario, as shipped in `scenarios/default.toml`.
    pub fn default_file() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("default.toml")
    }

    /// Checks every value of a scenario built in code against `fields::FIELDS` (messages name
    /// `path` and the field, no line).
    pub fn validate(&self, path: &Path) -> Result<(), ScenarioError> {
        check::values(self, path, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_scenarios_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut n = 0;
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") && p.file_name().unwrap() != "Cargo.toml" {
                Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
        assert!(n >= 1, "no scenario files found");
    }

    #[test]
    fn default_file_equals_built_in_defaults_where_it_is_silent() {
        let s = Scenario::load(&Scenario::default_file()).unwrap();
        assert_eq!(s.loop_.period_s, 1e-3);
        assert_eq!(s.trajectory.force_ref_n, -10.0);
        assert_eq!(s.bulge, BulgeConfig::default());
    }

    #[test]
    fn unknown_field_names_file_line_and_field() {
        let text = "[loop]\nperiod_s = 0.001\nbudget_typo = 3\n";
        let e = Scenario::from_toml_str(text, Path::new("x/bad.toml")).unwrap_err().to_string();
        assert!(e.contains("x/bad.toml"), "{e}");
        assert!(e.contains("line 3"), "{e}");
        assert!(e.contains("budget_typo"), "{e}");
    }

    #[test]
    fn integrator_is_named_in_the_file_and_unknown_names_are_refused() {
        let s = Scenario::from_toml_str("[loop]\nintegrator = \"rk4\"\n", Path::new("t.toml")).unwrap();
        assert_eq!(s.loop_.integrator, Integrator::Rk4);
        assert_eq!(s.loop_.integrator.name(), "rk4");
        let e = Scenario::from_toml_str("[loop]\nintegrator = \"euler\"\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("euler"), "{e}");
    }

    #[test]
    fn boundary_is_named_in_the_file_and_unknown_names_are_refused_with_their_line() {
        let s = Scenario::from_toml_str("[strip]\nboundary = \"sliding\"\n", Path::new("t.toml")).unwrap();
        assert_eq!(s.strip.boundary, Boundary::Sliding);
        assert_eq!(Scenario::default().strip.boundary, Boundary::Bonded);
        let e = Scenario::from_toml_str("[strip]\nboundary = \"glued\"\n", Path::new("t.toml")).unwrap_err().to_string();
        assert_eq!(e, "scenario file t.toml, line 2: field strip.boundary = \"glued\": must be one of \"bonded\", \"sliding\"");
    }

    #[test]
    fn wrong_type_names_line() {
        let text = "[trajectory]\nroll_s = \"fast\"\n";
        let e = Scenario::from_toml_str(text, Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn out_of_range_value_names_field_and_value() {
        let text = "[loop]\ntorque_budget_us = 5000\n";
        let e = Scenario::from_toml_str(text, Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("loop.torque_budget_us") && e.contains("5000"), "{e}");
        let text = "[strip]\nboundary = \"glued\"\n";
        let e = Scenario::from_toml_str(text, Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("strip.boundary") && e.contains("glued"), "{e}");
    }

    #[test]
    fn egm_fields_are_checked_against_each_other() {
        let e = Scenario::from_toml_str("[egm]\nsensor_address = \"localhost\"\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("egm.sensor_address") && e.contains("IP socket address"), "{e}");
        // 4.5 ms is no whole number of 1 ms ticks
        let e = Scenario::from_toml_str("[egm]\ncycle_s = 0.0045\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("egm.cycle_s") && e.contains("whole number"), "{e}");
        // the 20 Hz correction alone lags 7.96 ms, plus the servo's half tick
        let e = Scenario::from_toml_str("[egm]\nlag_s = 0.008\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(e.contains("egm.lag_s") && e.contains("that lag is"), "{e}");
        let s = Scenario::from_toml_str("[egm]\nlag_s = 0.009\n", Path::new("t.toml")).unwrap();
        assert!((s.egm.delay_s(1e-3) - (0.009 - 1.0 / (std::f64::consts::TAU * 20.0) - 0.0005)).abs() < 1e-15);
    }

    #[test]
    fn force_table_is_read_and_its_bad_points_are_named() {
        let ok = "[trajectory]\nforce_ref_along_z = [[2, -10], [11, -13.5], [38, -10]]\n";
        let s = Scenario::from_toml_str(ok, Path::new("t.toml")).unwrap();
        assert_eq!(s.trajectory.force_ref_along_z, vec![[2.0, -10.0], [11.0, -13.5], [38.0, -10.0]]);
        for (text, field, value) in [
            ("[[2, -10], [2, -12]]", "force_ref_along_z[1] z_mm", "2"),
            ("[[2, -10], [50, -12]]", "force_ref_along_z[1] z_mm", "50"),
            ("[[2, 10]]", "force_ref_along_z[0] force_n", "10"),
            ("[[2, nan]]", "force_ref_along_z[0] force_n", "NaN"),
        ] {
            let e = Scenario::from_toml_str(&format!("[trajectory]\nforce_ref_along_z = {text}\n"), Path::new("t.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(field) && e.contains(&format!("= {value}:")), "{text}: {e}");
        }
        let many: Vec<String> = (0..=MAX_FORCE_POINTS).map(|i| format!("[{i}, -10]")).collect();
        let e = Scenario::from_toml_str(&format!("[trajectory]\nforce_ref_along_z = [{}]\n", many.join(", ")), Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("must have at most 32 points"), "{e}");
    }

    #[test]
    fn long_strip_substrate_is_read_and_its_bad_rows_are_named_with_file_line_and_field() {
        let ok = "[strip]\nlength_mm = 600\nwindow_mm = 40\nwindow_spacing_mm = 10\n\n[trajectory]\nz_end_mm = 590\nroll_s = 10\n\n\
                  [substrate]\nbumps = [[100, 10, 0.2], [250, 15, -0.3]]\nseams = [[300, 0.3, 4], [400, -0.3, 4]]\n";
        let s = Scenario::from_toml_str(ok, Path::new("long.toml")).unwrap();
        assert_eq!(s.substrate.bumps, vec![[100.0, 10.0, 0.2], [250.0, 15.0, -0.3]]);
        assert_eq!(s.substrate.seams[1], [400.0, -0.3, 4.0]);
        let head = "[strip]\nlength_mm = 600\nwindow_mm = 40\n\n[trajectory]\nz_end_mm = 590\nroll_s = 10\n\n[substrate]\n";
        for (body, line, field, value, why) in [
            // a bulge beyond the strip (its second row, on line 11)
            (
                "bumps = [\n  [100, 10, 0.2],\n  [595, 10, 0.2],\n]\n",
                12,
                "substrate.bumps[1] center_mm",
                "595",
                "must lie on the strip: the bump spans 585 to 605 mm",
            ),
            // overlapping seams
            (
                "seams = [\n  [300, 0.3, 4],\n  [302, 0.3, 4],\n]\n",
                12,
                "substrate.seams[1] position_mm",
                "302",
                "must not overlap the seam before it",
            ),
            // a seam before the one above it in the list
            ("seams = [[300, 0.3, 4], [200, 0.3, 4]]\n", 10, "substrate.seams[1] position_mm", "200", "must not overlap"),
        ] {
            let e = Scenario::from_toml_str(&format!("{head}{body}"), Path::new("x/long.toml")).unwrap_err();
            let msg = e.to_string();
            assert_eq!(e.field(), Some(field), "{msg}");
            assert_eq!(e.place(), Some(Place::Line(line)), "{msg}");
            assert!(msg.starts_with("scenario file x/long.toml") && msg.contains(&format!("= {value}: {why}")), "{msg}");
        }
        // a window longer than the strip
        let e = Scenario::from_toml_str("[strip]\nwindow_mm = 50\n", Path::new("x/w.toml")).unwrap_err();
        let msg = e.to_string();
        assert_eq!((e.field(), e.place()), (Some("strip.window_mm"), Some(Place::Line(2))), "{msg}");
        assert!(
            msg.contains("x/w.toml") && msg.contains("field strip.window_mm = 50: must be in [0, strip.length_mm] = [0, 40] mm"),
            "{msg}"
        );
        // the single model's [bulge] on a windowed strip is one more bump: it must lie on the strip
        let e = Scenario::from_toml_str(
            "[strip]\nlength_mm = 600\nwindow_mm = 40\n\n[bulge]\nheight_mm = 0.2\nhalf_width_mm = 10\ncenter_mm = 595\n",
            Path::new("x/b.toml"),
        )
        .unwrap_err();
        let msg = e.to_string();
        assert_eq!((e.field(), e.place()), (Some("bulge.center_mm"), Some(Place::Line(8))), "{msg}");
        assert!(msg.contains("x/b.toml") && msg.contains("the bump spans 585 to 605 mm, beyond [0, 600] mm"), "{msg}");
        // substrate features need a windowed strip; a long strip needs windows
        let e = Scenario::from_toml_str("[substrate]\nbumps = [[20, 5, 0.1]]\n", Path::new("t.toml")).unwrap_err();
        assert_eq!((e.field(), e.place()), (Some("substrate.bumps"), Some(Place::Line(2))), "{e}");
        let e = Scenario::from_toml_str("[strip]\nlength_mm = 1500\n", Path::new("t.toml")).unwrap_err();
        assert_eq!(e.field(), Some("strip.length_mm"), "{e}");
        let e = Scenario::from_toml_str("[strip]\nwindow_mm = 40\nwindow_spacing_mm = 12\n", Path::new("t.toml")).unwrap_err();
        assert_eq!((e.field(), e.place()), (Some("strip.window_spacing_mm"), Some(Place::Line(3))), "{e}");
    }
}
