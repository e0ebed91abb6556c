//! The realistic cell (DESIGN section 12): the force/torque sensor's chain, the drives and
//! encoders, and what the controller believes against what the plant is. Every part is off by
//! default (the ideal plant of the thesis, bit for bit), and every random draw comes from
//! `sensor.seed`. `scenarios/cell.toml` sets all of them at the values cited in the README
//! ("The realistic cell").
//!
//! Per-axis arrays of the sensor are `[Fx, Fy, Fz, Tx, Ty, Tz]` in the sensor's axes (N, N m).

use serde::{Deserialize, Serialize};

/// Six-axis force/torque sensor between the flange and the tool bracket (`plant-sim`'s
/// `sensor.rs` runs the chain in this order): true contact wrench + the tool's gravity and
/// inertial load → bias + drift + noise → low-pass → sample delay → quantisation → saturation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// `false`: the plant publishes the exact contact wrench (today's ideal sensor).
    pub enabled: bool,
    /// Seed of every random draw of the cell (bias, drift, noise): the same seed gives a
    /// bit-identical lockstep run, another seed other noise.
    pub seed: u64,
    /// Power-on bias, drawn uniformly within ± this per axis.
    pub bias_range: [f64; 6],
    /// Drift: a random walk whose standard deviation grows by this per √s, per axis.
    pub drift_per_sqrt_s: [f64; 6],
    /// White measurement noise, standard deviation per axis and sample.
    pub noise_sd: [f64; 6],
    /// First-order low-pass of the sensor's electronics, Hz (0: none).
    pub lowpass_hz: f64,
    /// Sample delay from the wrench acting to its sample reaching the plant's output, ticks.
    pub delay_ticks: u32,
    /// Quantisation step per axis (the output's resolution; 0: none).
    pub resolution: [f64; 6],
    /// Calibrated range per axis: the output clips at ± this and the state says so (0: none).
    pub range: [f64; 6],
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            seed: 0,
            bias_range: [0.0; 6],
            drift_per_sqrt_s: [0.0; 6],
            noise_sd: [0.0; 6],
            lowpass_hz: 0.0,
            delay_ticks: 0,
            resolution: [0.0; 6],
            range: [0.0; 6],
        }
    }
}

/// Joint drives and encoders (`plant-sim`'s `drives.rs`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DrivesConfig {
    /// `false`: ideal drives (the torque commanded is applied, q and q̇ exact).
    pub enabled: bool,
    /// Coulomb (kinetic) friction per joint, N m.
    pub coulomb_nm: [f64; 6],
    /// Breakaway (static) friction per joint, N m: at least the Coulomb level.
    pub breakaway_nm: [f64; 6],
    /// Stribeck velocity per joint, rad/s: friction falls from breakaway to Coulomb over it.
    pub stribeck_radps: [f64; 6],
    /// Viscous friction per joint on top of `robot.viscous_nms` (which the controller's model
    /// knows; this part it does not), N m s/rad.
    pub viscous_nms: [f64; 6],
    /// Torque-constant error per joint: the drive applies (1 + this) times the command.
    pub torque_constant_error: [f64; 6],
    /// Encoder counts per joint revolution (0: exact q).
    pub encoder_counts_per_rev: [f64; 6],
    /// Cut-off of the first-order filter on the encoder's difference quotient that the state's
    /// q̇ reports, Hz (0: the exact q̇).
    pub velocity_filter_hz: f64,
}

impl Default for DrivesConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            coulomb_nm: [0.0; 6],
            breakaway_nm: [0.0; 6],
            stribeck_radps: [0.01; 6],
            viscous_nms: [0.0; 6],
            torque_constant_error: [0.0; 6],
            encoder_counts_per_rev: [0.0; 6],
            velocity_filter_hz: 0.0,
        }
    }
}

/// What the controller believes against what the plant is. `robot.*` is the real tool and arm
/// (the plant's); the controller's model differs by these amounts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MismatchConfig {
    /// Relative error of the tool mass the controller believes: m_c = (1 + this) m.
    pub tool_mass_error: f64,
    /// Error of the tool's centre of mass the controller believes, flange axes, m.
    pub tool_com_error_m: [f64; 3],
    /// Relative error of the tool inertia the controller believes.
    pub tool_inertia_error: f64,
    /// Per link, the plant's mass and inertia against the controller's model (1 = exact;
    /// multiplies `robot.plant_inertia_scale`).
    pub link_inertia_scale: [f64; 6],
}

impl Default for MismatchConfig {
    fn default() -> Self {
        Self { tool_mass_error: 0.0, tool_com_error_m: [0.0; 3], tool_inertia_error: 0.0, link_inertia_scale: [1.0; 6] }
    }
}

impl MismatchConfig {
    /// True when the controller's model is the plant's (every field at its default).
    pub fn is_none(&self) -> bool {
        *self == MismatchConfig::default()
    }
}
