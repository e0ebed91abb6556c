//! The scenario's references (thesis Figure 6.6 plus approach and lift-off), in the task frame of
//! DESIGN section 3, as a small state machine driven by simulated time and the measured force:
//!
//! [return: a controller taking over a running plant first moves the TCP from where it is to the
//! start pose] → settle (hold the start pose) → approach from above at constant speed (position control along
//! y) until |F| > threshold → force ramp from the contact force to `force_ref` → dwell → roll
//! z_start → z_end with a cosine velocity profile → force ramp-down to 0 → lift-off (position
//! control along y back above the strip) → done (hold).
//!
//! Along a `[contour]` the reference is in path coordinates (`scenarios::path`: x lateral, y
//! height, z the arc length) and the roll follows the contour's [`TimeLaw`] instead of the cosine;
//! the law turns it into the moving frame.
//!
//! Positions are of the TCP (the wheel centre, one wheel radius above the contact point). All time profiles are C¹ (position and velocity
//! continuous) so the PD feed-forward never sees steps.

use std::sync::Arc;

use nalgebra::Vector3;
use scenarios::contour::TimeLaw;
use scenarios::{Scenario, MAX_FORCE_POINTS};

use scenarios::geometry::{self, STRIP_TOP_HEIGHT_M};

/// Phase of the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Take-over of a running plant: C¹ move from the measured TCP position to the start pose.
    Return,
    Settle,
    Approach,
    /// First contact: decelerate the approach speed to rest under position control before the
    /// force law takes over (bumpless onset, see [`TOUCHDOWN_S`]).
    Touchdown,
    ForceRamp,
    Dwell,
    Roll,
    RampDown,
    Lift,
    Done,
}

/// Reference of one tick, task frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskReference {
    pub phase: Phase,
    /// TCP position, velocity and acceleration references, task frame (m, m/s, m/s²).
    pub pos_m: Vector3<f64>,
    pub vel_mps: Vector3<f64>,
    pub acc_mps2: Vector3<f64>,
    /// Force set-point on the strip along task y (F_r), N (negative = pressing; messages/README.md,
    /// "Frames and signs"), and its rate, N/s.
    pub force_y_n: f64,
    pub force_rate_y_nps: f64,
    /// True while task y is force controlled (hybrid impedance); false for position control.
    pub force_mode: bool,
}

/// Parameters of the reference (SI), from `scenario.trajectory` and the geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceParams {
    /// TCP start position in the task frame.
    pub start_task_m: Vector3<f64>,
    pub settle_s: f64,
    pub approach_speed_mps: f64,
    /// Time over which the approach speed ramps in (cosine), s.
    pub approach_ramp_s: f64,
    /// Deepest the approach reference goes below the start height, m: the approach height plus
    /// [`APPROACH_OVERTRAVEL_M`]. Without contact (no strip, missed strip) the wheel stops there.
    pub approach_max_descent_m: f64,
    pub contact_threshold_n: f64,
    pub force_ref_n: f64,
    /// Force set-point along the strip as (z m, N) knots, the first `force_table_len` used; none
    /// means `force_ref_n` throughout (scenario `trajectory.force_ref_along_z`).
    pub force_table: [[f64; 2]; MAX_FORCE_POINTS],
    pub force_table_len: usize,
    pub force_ramp_s: f64,
    pub dwell_s: f64,
    pub z_start_m: f64,
    pub z_end_m: f64,
    pub roll_s: f64,
    pub ramp_down_s: f64,
    /// TCP height (task y) to lift to at the end.
    pub lift_y_m: f64,
    pub lift_s: f64,
}

impl ReferenceParams {
    /// From the scenario: the TCP starts where the plant starts it
    /// ([`geometry::start_tcp_task_m`]: the wheel's lowest point `approach_height_mm` above the
    /// nominal strip top at `z_start_mm`, the TCP, the wheel centre, one radius higher).
    pub fn from_scenario(s: &Scenario) -> ReferenceParams {
        let t = &s.trajectory;
        let r = s.robot.wheel_radius_mm * 1e-3;
        let z_start_m = t.z_start_mm * 1e-3;
        let mut force_table = [[0.0; 2]; MAX_FORCE_POINTS];
        for (k, &[z_mm, f_n]) in force_table.iter_mut().zip(&t.force_ref_along_z) {
            *k = [z_mm * 1e-3, f_n];
        }
        ReferenceParams {
            start_task_m: geometry::start_tcp_task_m(s),
            settle_s: t.settle_s,
            approach_speed_mps: t.approach_speed_mm_s * 1e-3,
            approach_ramp_s: 0.05,
            approach_max_descent_m: t.approach_height_mm * 1e-3 + APPROACH_OVERTRAVEL_M,
            contact_threshold_n: t.contact_threshold_n,
            force_ref_n: t.force_ref_n,
            force_table,
            force_table_len: t.force_ref_along_z.len().min(MAX_FORCE_POINTS),
            force_ramp_s: t.force_ramp_s,
            dwell_s: t.dwell_s,
            z_start_m,
            z_end_m: t.z_end_mm * 1e-3,
            roll_s: t.roll_s,
            ramp_down_s: t.ramp_down_s,
            lift_y_m: STRIP_TOP_HEIGHT_M + t.lift_mm * 1e-3 + r,
            lift_s: t.lift_s,
        }
    }
}

impl ReferenceParams {
    /// Force set-point (N) with the wheel at strip position `z_m`: cosine-blended between the
    /// table's knots ([`cosine_blend`]), held beyond its ends; `force_ref_n` without a table.
    pub fn force_at(&self, z_m: f64) -> f64 {
        self.force_and_slope_at(z_m).0
    }

    /// [`Self::force_at`] and its slope along the strip (N/m). Between knots the force follows a
    /// cosine blend, so the slope is continuous and zero at every knot (no velocity step in the
    /// feed-forward of the rate).
    pub fn force_and_slope_at(&self, z_m: f64) -> (f64, f64) {
        let k = &self.force_table[..self.force_table_len];
        match k {
            [] => (self.force_ref_n, 0.0),
            [first, ..] if z_m <= first[0] => (first[1], 0.0),
            [.., last] if z_m >= last[0] => (last[1], 0.0),
            _ => {
                let i = k.partition_point(|p| p[0] <= z_m);
                let ([z0, f0], [z1, f1]) = (k[i - 1], k[i]);
                let (b, db, _) = cosine_blend((z_m - z0) / (z1 - z0));
                (f0 + (f1 - f0) * b, (f1 - f0) * db / (z1 - z0))
            }
        }
    }
}

/// How far below the nominal strip top the approach may go looking for contact, m.
pub const APPROACH_OVERTRAVEL_M: f64 = 1e-3;

/// Smooth 0 → 1 blend `(1 − cos πx)/2` and its first two derivatives in x (clamped outside [0, 1]).
#[inline]
pub fn cosine_blend(x: f64) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    if x <= 0.0 {
        (0.0, 0.0, 0.0)
    } else if x >= 1.0 {
        (1.0, 0.0, 0.0)
    } else {
        let (s, c) = (PI * x).sin_cos();
        (0.5 * (1.0 - c), 0.5 * PI * s, 0.5 * PI * PI * c)
    }
}

/// Cosine velocity profile over `[0, duration]` covering `distance` (thesis Figure 6.6):
/// v(τ) = (d/T)(1 − cos 2πτ/T). Returns (position offset, velocity, acceleration).
#[inline]
pub fn cosine_velocity_profile(tau: f64, duration: f64, distance: f64) -> (f64, f64, f64) {
    use std::f64::consts::TAU;
    if tau <= 0.0 {
        return (0.0, 0.0, 0.0);
    }
    if tau >= duration {
        return (distance, 0.0, 0.0);
    }
    let w = TAU / duration;
    let v_mean = distance / duration;
    let (s, c) = (w * tau).sin_cos();
    (v_mean * (tau - s / w), v_mean * (1.0 - c), v_mean * w * s)
}

/// Approach descent below the start height after `tau` s: speed ramps in with a cosine over
/// `ramp` s, then stays constant; the descent stops at `max_descent` (the speed ramps out with the
/// same cosine, so the reference stays C¹). Returns (descent, speed, acceleration), all ≥ 0 downwards.
#[inline]
fn approach_profile(tau: f64, ramp: f64, speed: f64, max_descent: f64) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    // Ramp-in and ramp-out each cover speed·ramp/2; the cruise time follows from max_descent.
    let t_cruise_end = (max_descent / speed).max(ramp);
    if tau <= 0.0 {
        (0.0, 0.0, 0.0)
    } else if tau < ramp {
        let (s, c) = (PI * tau / ramp).sin_cos();
        (speed * (0.5 * tau - ramp / (2.0 * PI) * s), speed * 0.5 * (1.0 - c), speed * 0.5 * PI / ramp * s)
    } else if tau < t_cruise_end {
        (speed * (tau - 0.5 * ramp), speed, 0.0)
    } else if tau < t_cruise_end + ramp {
        let x = tau - t_cruise_end;
        let (s, c) = (PI * x / ramp).sin_cos();
        let d_cruise = speed * (t_cruise_end - 0.5 * ramp);
        (d_cruise + speed * (0.5 * x + ramp / (2.0 * PI) * s), speed * 0.5 * (1.0 + c), -speed * 0.5 * PI / ramp * s)
    } else {
        (speed * t_cruise_end, 0.0, 0.0)
    }
}

/// Duration of the touchdown: the approach speed v0 decelerates to rest with a cosine velocity
/// profile, peak deceleration π v0 / (2 T). Why: the hybrid impedance law (6.3) makes the 21 kg
/// arm behave like m_d ≈ 0.2 kg along the normal, so switching it on while the wheel still moves
/// at v0 stops the arm within a tick (today's 404 N m joint-2 step at 10 mm/s). Stopping it over
/// T instead changes the torque per tick by about m_eff π² v0 T_tick / (2 T²) at the shoulder:
/// a few N m for 30 ms; the strip is pressed v0 T / 2 = 0.15 mm further (about 4 N more), which
/// the force ramp then starts from.
pub const TOUCHDOWN_S: f64 = 0.03;
/// After a re-engagement (the plant held or stopped the arm) the measured pose and force are
/// blended back into the planned ones over this time, s (C¹ cosine).
pub const REENGAGE_S: f64 = 0.3;

/// Cosine stop from speed `v0` over `T` (touchdown): `(distance travelled, speed, deceleration)`
/// after `tau`, all positive along the motion: v = v0 (1 + cos πτ/T)/2.
#[inline]
pub fn touchdown_profile(tau: f64, t: f64, v0: f64) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    let tau = tau.clamp(0.0, t);
    let (s, c) = (PI * tau / t).sin_cos();
    (v0 * (0.5 * tau + t / (2.0 * PI) * s), v0 * 0.5 * (1.0 + c), v0 * 0.5 * PI / t * s)
}

/// Re-approach after `tau` s from height `y0` and vertical velocity `v0` (signed, task y): the
/// velocity blends (cosine, over `ramp`) to the approach speed downwards, then stays there, and
/// the descent stops at `y_min` with the same cosine (the first approach's deepest point: without
/// a strip the wheel does not go on into the table). Returns the signed (displacement from `y0`,
/// velocity, acceleration) along task y.
#[inline]
pub fn reapproach_profile(tau: f64, ramp: f64, y0: f64, v0: f64, approach_speed: f64, y_min: f64) -> (f64, f64, f64) {
    use std::f64::consts::PI;
    let v = approach_speed;
    let dv = -v - v0;
    // Cruise after the ramp: y = y0 - v tau - dv ramp / 2. The ramp-out (covering v ramp / 2)
    // starts where that reaches y_min + v ramp / 2.
    let tau_out = (y0 - dv * ramp / 2.0 - (y_min + v * ramp / 2.0)) / v;
    if tau_out >= ramp && tau >= tau_out {
        let x = (tau - tau_out).min(ramp);
        let (s, c) = (PI * x / ramp).sin_cos();
        let y_out = y_min + v * ramp / 2.0;
        let d = y_out - v * (0.5 * x + ramp / (2.0 * PI) * s) - y0;
        return if tau - tau_out >= ramp { (y_min - y0, 0.0, 0.0) } else { (d, -v * 0.5 * (1.0 + c), v * 0.5 * PI / ramp * s) };
    }
    let r = if tau <= 0.0 {
        (0.0, v0, 0.0)
    } else if tau < ramp {
        let (s, c) = (PI * tau / ramp).sin_cos();
        (v0 * tau + dv * (0.5 * tau - ramp / (2.0 * PI) * s), v0 + dv * 0.5 * (1.0 - c), dv * 0.5 * PI / ramp * s)
    } else {
        (v0 * tau + dv * (tau - 0.5 * ramp), -v, 0.0)
    };
    // Started too close to the bottom for a smooth stop: hold at it (rare: the arm is already
    // lower than the first approach ever went).
    if y0 + r.0 < y_min && r.1 < 0.0 {
        return (y_min - y0, 0.0, 0.0);
    }
    r
}

/// Inside a force-controlled phase: is the wheel pressing, or finding the strip again after it
/// lost contact (a safe stop lifted it off)?
#[derive(Clone, Copy, Debug, PartialEq)]
enum Contact {
    Pressing,
    /// Position-controlled descent from `y0` and vertical velocity `v0` (task y, signed) to the
    /// approach speed, started at `t0` ([`reapproach_profile`]).
    Reapproach {
        t0: f64,
        y0: f64,
        v0: f64,
    },
    /// Stopping from `v0` at `y0`, started at `t0`.
    Touchdown {
        t0: f64,
        y0: f64,
        v0: f64,
    },
}

/// The reference state machine. `update` is allocation-free.
#[derive(Clone, Debug)]
pub struct ReferenceGenerator {
    p: ReferenceParams,
    /// The roll's time law along a contour (None: the cosine velocity profile over `roll_s`).
    time_law: Option<Arc<TimeLaw>>,
    phase: Phase,
    /// Time the current phase began, s.
    t0: f64,
    /// Force at contact detection (start of the ramp), N.
    force_at_contact_n: f64,
    /// TCP height when the lift-off began, m.
    lift_from_y_m: f64,
    /// TCP height reference when force control took over, m (held as the y reference in force mode).
    y_at_contact_m: f64,
    /// Return phase: where the TCP was at take-over (task frame) and how long the move takes.
    return_from_m: Vector3<f64>,
    return_s: f64,
    /// Touchdown: the approach's height and speed at contact (the cosine stop starts there).
    touchdown_y_m: f64,
    touchdown_v_mps: f64,
    /// Re-contact inside the force phases.
    contact: Contact,
    /// Re-engagement: measured − planned pose at `reengage_t0` (decays over [`REENGAGE_S`]), and
    /// the force to blend from (None: none pending) with the time its blend starts.
    reengage_t0: f64,
    pos_offset_m: Vector3<f64>,
    vel_offset_mps: Vector3<f64>,
    force_from: Option<(f64, f64)>,
    /// Time the plan stood still (re-contact, or the plant not running: [`Self::hold`]), s; the
    /// plan runs on `t − held_s`, the re-engagement and re-contact on `t` itself.
    held_s: f64,
    last_t: Option<f64>,
}

/// Speed of the take-over return move (average), m/s, and its shortest duration, s.
pub const RETURN_SPEED_MPS: f64 = 0.02;
pub const RETURN_MIN_S: f64 = 0.3;
/// A take-over closer than this to the start pose skips the return move, m.
pub const RETURN_TOLERANCE_M: f64 = 0.5e-3;

impl ReferenceGenerator {
    pub fn new(p: ReferenceParams) -> Self {
        ReferenceGenerator {
            p,
            time_law: None,
            phase: Phase::Settle,
            t0: 0.0,
            force_at_contact_n: 0.0,
            lift_from_y_m: p.start_task_m.y,
            y_at_contact_m: p.start_task_m.y,
            return_from_m: p.start_task_m,
            return_s: 0.0,
            touchdown_y_m: p.start_task_m.y,
            touchdown_v_mps: 0.0,
            contact: Contact::Pressing,
            reengage_t0: 0.0,
            pos_offset_m: Vector3::zeros(),
            vel_offset_mps: Vector3::zeros(),
            force_from: None,
            held_s: 0.0,
            last_t: None,
        }
    }

    /// The scenario's references: [`ReferenceParams::from_scenario`], and along a contour its
    /// time law for the roll (whose duration becomes `roll_s`).
    pub fn from_scenario(s: &Scenario) -> Self {
        let mut p = ReferenceParams::from_scenario(s);
        let Some(law) = TimeLaw::of_scenario(s) else {
            return ReferenceGenerator::new(p);
        };
        p.roll_s = law.duration_s();
        ReferenceGenerator { time_law: Some(Arc::new(law)), ..ReferenceGenerator::new(p) }
    }

    /// Let the plan stand still for `dt` s: the plant held or stopped the arm this tick, so the
    /// trajectory must not run ahead of it (anti-windup of the reference clock).
    pub fn hold(&mut self, dt: f64) {
        self.held_s += dt;
    }

    /// True while the plan's clock should stand still: re-finding the strip inside a force phase
    /// (the roll waits for the wheel to press again). The caller does not advance `t` then.
    pub fn holds_clock(&self) -> bool {
        !matches!(self.contact, Contact::Pressing)
    }

    /// Re-engage at time `t` after the plant held or stopped the arm: the pose the arm is in
    /// (`tcp_task_m`) becomes the reference, blended back into the plan over [`REENGAGE_S`], and in
    /// a force phase the force set-point starts from the measured `force_y_n` (or, if the wheel
    /// is off the strip, the strip is found again first). No torque step: the law starts from
    /// the measured state, like the take-over return move.
    pub fn reengage(&mut self, t: f64, tcp_task_m: &Vector3<f64>, tcp_vel_task_mps: &Vector3<f64>, force_y_n: f64) {
        // The plan stood still since the last tick this controller saw (the plant was stopped).
        if let Some(last) = self.last_t {
            self.held_s += t - last;
        }
        self.last_t = Some(t);
        self.pos_offset_m = Vector3::zeros();
        self.vel_offset_mps = Vector3::zeros();
        self.force_from = None;
        self.contact = Contact::Pressing;
        let t_plan = t - self.held_s;
        if self.reference_at(t_plan, t).force_mode {
            if force_y_n.abs() > self.p.contact_threshold_n {
                self.force_from = Some((t, force_y_n));
            } else {
                self.contact = Contact::Reapproach { t0: t, y0: tcp_task_m.y, v0: tcp_vel_task_mps.y };
            }
        }
        // The plan as it now runs (standing still while the strip is found again).
        let plan = self.reference_at(t_plan, t);
        self.reengage_t0 = t;
        self.pos_offset_m = tcp_task_m - plan.pos_m;
        self.vel_offset_mps = tcp_vel_task_mps - plan.vel_mps;
    }

    pub fn params(&self) -> &ReferenceParams {
        &self.p
    }

    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Restart the state machine at time `t` (a controller taking over a running plant starts
    /// from the approach's start pose).
    pub fn reset(&mut self, t: f64) {
        *self = ReferenceGenerator { time_law: self.time_law.take(), ..ReferenceGenerator::new(self.p) };
        self.t0 = t;
    }

    /// Restart at time `t` with the TCP measured at `tcp_task_m`: if it is away from the start
    /// pose (a controller taking over a plant that is mid-run or sagged in its safe stop), first
    /// move it there with a C¹ cosine blend instead of commanding the start pose as a step, so the
    /// take-over torque stays near the one that was holding the arm.
    pub fn reset_from(&mut self, t: f64, tcp_task_m: &Vector3<f64>) {
        self.reset(t);
        let dist = (self.p.start_task_m - tcp_task_m).norm();
        if dist > RETURN_TOLERANCE_M {
            self.phase = Phase::Return;
            self.return_from_m = *tcp_task_m;
            self.return_s = (dist / RETURN_SPEED_MPS).max(RETURN_MIN_S);
        }
    }

    /// Advance to time `t` (s) given the measured force on the strip along task y (N) and the
    /// measured TCP height (task y, m), and return the reference for this tick.
    pub fn update(&mut self, t_run: f64, force_y_n: f64, tcp_y_m: f64) -> TaskReference {
        let p = self.p;
        if let Some(last) = self.last_t {
            if self.holds_clock() {
                self.held_s += t_run - last;
            }
        }
        self.last_t = Some(t_run);
        let t = t_run - self.held_s;
        // Phase transitions (at most one per tick is enough at 1 kHz, but loop for robustness).
        for _ in 0..8 {
            let tau = t - self.t0;
            let next = match self.phase {
                Phase::Return if tau >= self.return_s => Some(Phase::Settle),
                Phase::Settle if tau >= p.settle_s => Some(Phase::Approach),
                Phase::Approach if force_y_n.abs() > p.contact_threshold_n => {
                    let (d, v, _) = approach_profile(tau, p.approach_ramp_s, p.approach_speed_mps, p.approach_max_descent_m);
                    self.touchdown_y_m = p.start_task_m.y - d;
                    self.touchdown_v_mps = v;
                    Some(Phase::Touchdown)
                }
                Phase::Touchdown if tau >= TOUCHDOWN_S => {
                    self.force_at_contact_n = force_y_n;
                    self.y_at_contact_m = tcp_y_m;
                    Some(Phase::ForceRamp)
                }
                Phase::ForceRamp if tau >= p.force_ramp_s => Some(Phase::Dwell),
                Phase::Dwell if tau >= p.dwell_s => Some(Phase::Roll),
                Phase::Roll if tau >= p.roll_s => Some(Phase::RampDown),
                Phase::RampDown if tau >= p.ramp_down_s => {
                    self.lift_from_y_m = tcp_y_m;
                    Some(Phase::Lift)
                }
                Phase::Lift if tau >= p.lift_s => Some(Phase::Done),
                _ => None,
            };
            match next {
                Some(ph) => {
                    // Event-driven transitions start now; timed ones at their exact boundary.
                    self.t0 = match self.phase_duration() {
                        Some(d) => self.t0 + d,
                        None => t,
                    };
                    self.phase = ph;
                }
                None => break,
            }
        }
        self.update_contact(t_run, force_y_n, tcp_y_m);
        self.reference_at(t, t_run)
    }

    /// Inside the force phases: lose contact (|F| under half the threshold) → re-approach; find
    /// it again → touchdown; touchdown over → pressing, the force blended from the measured one.
    /// `t` is the caller's (held) plan time; the sub-state runs on it too, so the caller keeps
    /// advancing `t` by the ticks spent here but does not move the plan (see [`Self::holds_clock`]).
    fn update_contact(&mut self, t: f64, force_y_n: f64, tcp_y_m: f64) {
        let force_phase = matches!(self.phase, Phase::ForceRamp | Phase::Dwell | Phase::Roll);
        if !force_phase {
            self.contact = Contact::Pressing;
            return;
        }
        let p = self.p;
        self.contact = match self.contact {
            Contact::Pressing if force_y_n.abs() < 0.5 * p.contact_threshold_n => Contact::Reapproach { t0: t, y0: tcp_y_m, v0: 0.0 },
            Contact::Reapproach { t0, y0, v0 } if force_y_n.abs() > p.contact_threshold_n => {
                let (d, v, _) = reapproach_profile(
                    t - t0,
                    p.approach_ramp_s,
                    y0,
                    v0,
                    p.approach_speed_mps,
                    p.start_task_m.y - p.approach_max_descent_m,
                );
                Contact::Touchdown { t0: t, y0: y0 + d, v0: -v }
            }
            // The hand-over also waits for the re-engagement's fade to end: the arm must not
            // still be moving along the strip (over the bulge that is a normal velocity the
            // impedance would damp at once).
            Contact::Touchdown { t0, .. } if t - t0 >= TOUCHDOWN_S && t - self.reengage_t0 >= REENGAGE_S => {
                self.force_from = Some((t, force_y_n));
                // The plan moves again: ease into its velocity instead of stepping to it (the
                // arm stood still while the strip was found again).
                // Re-base the fade on the reference as it stands (still re-engaging, the plan
                // standing still), so that neither position nor velocity steps.
                let before = self.reference_at(t - self.held_s, t);
                self.contact = Contact::Pressing;
                self.pos_offset_m = Vector3::zeros();
                self.vel_offset_mps = Vector3::zeros();
                let plan = self.reference_at(t - self.held_s, t);
                self.pos_offset_m = before.pos_m - plan.pos_m;
                self.vel_offset_mps = before.vel_mps - plan.vel_mps;
                self.reengage_t0 = t;
                Contact::Pressing
            }
            c => c,
        };
    }

    /// Duration of a timed phase.
    fn phase_duration(&self) -> Option<f64> {
        let p = &self.p;
        match self.phase {
            Phase::Return => Some(self.return_s),
            Phase::Settle => Some(p.settle_s),
            Phase::Touchdown => Some(TOUCHDOWN_S),
            Phase::ForceRamp => Some(p.force_ramp_s),
            Phase::Dwell => Some(p.dwell_s),
            Phase::Roll => Some(p.roll_s),
            Phase::RampDown => Some(p.ramp_down_s),
            Phase::Lift => Some(p.lift_s),
            Phase::Approach | Phase::Done => None,
        }
    }

    /// The reference of the current phase at plan time `t` (run time `t_run`).
    fn reference_at(&self, t: f64, t_run: f64) -> TaskReference {
        let p = &self.p;
        let tau = t - self.t0;
        let s = p.start_task_m;
        let mut r = TaskReference {
            phase: self.phase,
            pos_m: s,
            vel_mps: Vector3::zeros(),
            acc_mps2: Vector3::zeros(),
            force_y_n: 0.0,
            force_rate_y_nps: 0.0,
            force_mode: false,
        };
        let z_end_offset = p.z_end_m - p.z_start_m;
        match self.phase {
            Phase::Return => {
                let (b, db, ddb) = cosine_blend(tau / self.return_s);
                let d = s - self.return_from_m;
                r.pos_m = self.return_from_m + d * b;
                r.vel_mps = d * (db / self.return_s);
                r.acc_mps2 = d * (ddb / (self.return_s * self.return_s));
            }
            Phase::Settle => {}
            Phase::Approach => {
                let (d, v, a) = approach_profile(tau, p.approach_ramp_s, p.approach_speed_mps, p.approach_max_descent_m);
                r.pos_m.y = s.y - d;
                r.vel_mps.y = -v;
                r.acc_mps2.y = -a;
            }
            Phase::Touchdown => {
                let (d, v, a) = touchdown_profile(tau, TOUCHDOWN_S, self.touchdown_v_mps);
                r.pos_m.y = self.touchdown_y_m - d;
                r.vel_mps.y = -v;
                r.acc_mps2.y = a;
            }
            Phase::ForceRamp => {
                let (b, db, _) = cosine_blend(tau / p.force_ramp_s.max(1e-9));
                let step = p.force_at(p.z_start_m) - self.force_at_contact_n;
                r.force_y_n = self.force_at_contact_n + step * b;
                r.force_rate_y_nps = step * db / p.force_ramp_s.max(1e-9);
                r.force_mode = true;
                r.pos_m.y = self.y_at_contact_m;
            }
            Phase::Dwell => {
                r.force_y_n = p.force_at(p.z_start_m);
                r.force_mode = true;
                r.pos_m.y = self.y_at_contact_m;
            }
            Phase::Roll => {
                let (z, v, a) = match &self.time_law {
                    Some(law) => law.at(tau),
                    None => cosine_velocity_profile(tau, p.roll_s, z_end_offset),
                };
                r.pos_m.z = s.z + z;
                r.vel_mps.z = v;
                r.acc_mps2.z = a;
                let (f, slope) = p.force_and_slope_at(r.pos_m.z);
                r.force_y_n = f;
                r.force_rate_y_nps = slope * v;
                r.force_mode = true;
                r.pos_m.y = self.y_at_contact_m;
            }
            Phase::RampDown => {
                let (b, db, _) = cosine_blend(tau / p.ramp_down_s.max(1e-9));
                r.pos_m.z = p.z_end_m;
                r.force_y_n = p.force_at(p.z_end_m) * (1.0 - b);
                r.force_rate_y_nps = -p.force_at(p.z_end_m) * db / p.ramp_down_s.max(1e-9);
                r.force_mode = true;
                r.pos_m.y = self.y_at_contact_m;
            }
            Phase::Lift => {
                let (b, db, ddb) = cosine_blend(tau / p.lift_s.max(1e-9));
                let dy = p.lift_y_m - self.lift_from_y_m;
                r.pos_m.z = p.z_end_m;
                r.pos_m.y = self.lift_from_y_m + dy * b;
                r.vel_mps.y = dy * db / p.lift_s;
                r.acc_mps2.y = dy * ddb / (p.lift_s * p.lift_s);
            }
            Phase::Done => {
                r.pos_m.z = p.z_end_m;
                r.pos_m.y = p.lift_y_m;
            }
        }
        if self.holds_clock() {
            // The plan stands still: so do its velocities (the roll waits for the strip).
            r.vel_mps = Vector3::zeros();
            r.acc_mps2 = Vector3::zeros();
            r.force_rate_y_nps = 0.0;
        }
        self.adjust(t_run, &mut r);
        r
    }

    /// The re-engagement's and re-contact's changes to the plan at `t`.
    fn adjust(&self, t: f64, r: &mut TaskReference) {
        let p = &self.p;
        if r.force_mode {
            match self.contact {
                Contact::Pressing => {
                    if let Some((t0, f0)) = self.force_from {
                        let (b, db, _) = cosine_blend((t - t0) / REENGAGE_S);
                        r.force_rate_y_nps = r.force_rate_y_nps * b + (r.force_y_n - f0) * db / REENGAGE_S;
                        r.force_y_n = f0 + (r.force_y_n - f0) * b;
                    }
                }
                Contact::Reapproach { t0, y0, v0 } => {
                    let (d, v, a) = reapproach_profile(
                        t - t0,
                        p.approach_ramp_s,
                        y0,
                        v0,
                        p.approach_speed_mps,
                        p.start_task_m.y - p.approach_max_descent_m,
                    );
                    r.force_mode = false;
                    r.pos_m.y = y0 + d;
                    r.vel_mps.y = v;
                    r.acc_mps2.y = a;
                }
                Contact::Touchdown { t0, y0, v0 } => {
                    let (d, v, a) = touchdown_profile(t - t0, TOUCHDOWN_S, v0);
                    r.force_mode = false;
                    r.pos_m.y = y0 - d;
                    r.vel_mps.y = -v;
                    r.acc_mps2.y = a;
                }
            }
        }
        // Measured − planned pose and velocity at the re-engagement, fading out along a quintic
        // Hermite curve over REENGAGE_S: value and slope matched at the start, value, slope and
        // acceleration zero at both ends (no step in the acceleration feed-forward either).
        if self.pos_offset_m != Vector3::zeros() || self.vel_offset_mps != Vector3::zeros() {
            let tt = REENGAGE_S;
            let x = ((t - self.reengage_t0) / tt).clamp(0.0, 1.0);
            let (x2, x3) = (x * x, x * x * x);
            let h0 = 1.0 - 10.0 * x3 + 15.0 * x2 * x2 - 6.0 * x3 * x2;
            let d0 = (-30.0 * x2 + 60.0 * x3 - 30.0 * x2 * x2) / tt;
            let a0 = (-60.0 * x + 180.0 * x2 - 120.0 * x3) / (tt * tt);
            let h1 = (x - 6.0 * x3 + 8.0 * x2 * x2 - 3.0 * x3 * x2) * tt;
            let d1 = 1.0 - 18.0 * x2 + 32.0 * x3 - 15.0 * x2 * x2;
            let a1 = (-36.0 * x + 96.0 * x2 - 60.0 * x3) / tt;
            let (mut o, mut ov) = (self.pos_offset_m, self.vel_offset_mps);
            // Task y belongs to the force law or to the re-contact's own profile there.
            if r.force_mode || !matches!(self.contact, Contact::Pressing) {
                o.y = 0.0;
                ov.y = 0.0;
            }
            if x < 1.0 {
                r.pos_m += o * h0 + ov * h1;
                r.vel_mps += o * d0 + ov * d1;
                r.acc_mps2 += o * a0 + ov * a1;
            }
        }
    }

    /// Time from the start of the roll to the end of the lift-off (for run-length estimates), s.
    pub fn tail_duration_s(&self) -> f64 {
        let p = &self.p;
        p.force_ramp_s + p.dwell_s + p.roll_s + p.ramp_down_s + p.lift_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gen() -> ReferenceGenerator {
        ReferenceGenerator::new(ReferenceParams::from_scenario(&Scenario::default()))
    }

    #[test]
    fn cosine_velocity_integral_is_the_distance() {
        let (t_roll, d) = (2.0, 0.036);
        let n = 20_000;
        let h = t_roll / n as f64;
        // Trapezoidal integral of the velocity against the closed-form end position.
        let mut integral = 0.0;
        for i in 0..n {
            let (_, v0, _) = cosine_velocity_profile(i as f64 * h, t_roll, d);
            let (_, v1, _) = cosine_velocity_profile((i + 1) as f64 * h, t_roll, d);
            integral += 0.5 * (v0 + v1) * h;
        }
        assert!((integral - d).abs() < 1e-9 * d.max(1.0), "{integral}");
        assert_eq!(cosine_velocity_profile(t_roll, t_roll, d).0, d);
        // Peak speed 2 d / T at mid-roll.
        let (_, vmax, amid) = cosine_velocity_profile(0.5 * t_roll, t_roll, d);
        assert!((vmax - 2.0 * d / t_roll).abs() < 1e-12 && amid.abs() < 1e-12);
        // Acceleration is the derivative of velocity (central difference).
        let (tau, e) = (0.37, 1e-6);
        let dv = (cosine_velocity_profile(tau + e, t_roll, d).1 - cosine_velocity_profile(tau - e, t_roll, d).1) / (2.0 * e);
        assert!((dv - cosine_velocity_profile(tau, t_roll, d).2).abs() < 1e-6);
    }

    /// Drive the whole state machine with a synthetic contact (force once the reference goes
    /// below the strip top) and check position/velocity continuity tick to tick.
    #[test]
    fn profile_is_continuous_through_every_phase() {
        let mut g = gen();
        let p = *g.params();
        let dt = 1e-4;
        let contact_y = p.start_task_m.y - 0.003;
        let mut prev: Option<TaskReference> = None;
        let mut seen = Vec::new();
        let mut t = 0.0;
        while g.phase() != Phase::Done && t < 10.0 {
            let y_meas = prev.map_or(p.start_task_m.y, |r| r.pos_m.y);
            let f = if y_meas < contact_y { -1.0 } else { 0.0 };
            let r = g.update(t, f, y_meas);
            if seen.last() != Some(&r.phase) {
                seen.push(r.phase);
            }
            if let Some(q) = prev {
                // Position steps bounded by max speed * dt, velocity steps by max accel * dt
                // (largest: the touchdown's stop, v π / (2 T_touchdown) = 0.52 m/s²).
                // Task y is not a motion reference while force controlled: compare it only when
                // both ticks are position controlled.
                let mask = if r.force_mode || q.force_mode { Vector3::new(1.0, 0.0, 1.0) } else { Vector3::new(1.0, 1.0, 1.0) };
                let dp = (r.pos_m - q.pos_m).component_mul(&mask).norm();
                let dv = (r.vel_mps - q.vel_mps).component_mul(&mask).norm();
                assert!(dp <= 0.04 * dt + 1e-12, "position jump {dp} at t={t} {:?}", r.phase);
                assert!(dv <= 0.55 * dt + 1e-12, "velocity jump {dv} at t={t} {:?}", r.phase);
                // Force ramps: at most 10 N · π / (2 · 0.2 s) = 79 N/s.
                // (The set-point starts at the measured force when the touchdown hands over.)
                assert!((r.force_y_n - q.force_y_n).abs() <= 100.0 * dt + 1e-12 || q.phase == Phase::Touchdown);
            }
            prev = Some(r);
            t += dt;
        }
        assert_eq!(
            seen,
            vec![
                Phase::Settle,
                Phase::Approach,
                Phase::Touchdown,
                Phase::ForceRamp,
                Phase::Dwell,
                Phase::Roll,
                Phase::RampDown,
                Phase::Lift,
                Phase::Done
            ]
        );
        let last = prev.unwrap();
        assert!((last.pos_m.z - p.z_end_m).abs() < 1e-15);
        assert!((last.pos_m.y - p.lift_y_m).abs() < 1e-12);
    }

    /// Without contact the approach stops at the nominal strip top minus the overtravel, smoothly
    /// (velocity continuous, acceleration the derivative of velocity).
    #[test]
    fn approach_without_contact_stops_below_the_strip_top() {
        let mut g = gen();
        let p = *g.params();
        let dt = 1e-4;
        let mut prev = g.update(0.0, 0.0, p.start_task_m.y);
        let mut t = dt;
        while t < 2.0 {
            let r = g.update(t, 0.0, p.start_task_m.y);
            assert!((r.vel_mps.y - prev.vel_mps.y).abs() <= 0.5 * dt, "velocity jump at {t}");
            let a_fd = (r.vel_mps.y - prev.vel_mps.y) / dt;
            assert!((a_fd - 0.5 * (r.acc_mps2.y + prev.acc_mps2.y)).abs() < 1e-3, "accel at {t}: {a_fd}");
            prev = r;
            t += dt;
        }
        assert_eq!(prev.phase, Phase::Approach);
        assert!(prev.vel_mps.y == 0.0);
        let r = Scenario::default().robot.wheel_radius_mm * 1e-3;
        let expect = STRIP_TOP_HEIGHT_M + r - APPROACH_OVERTRAVEL_M;
        assert!((prev.pos_m.y - expect).abs() < 1e-12, "{} vs {expect}", prev.pos_m.y);
    }

    #[test]
    fn force_ramp_starts_at_the_contact_force() {
        let mut g = gen();
        let p = *g.params();
        g.update(0.0, 0.0, p.start_task_m.y);
        g.update(p.settle_s + 0.01, 0.0, p.start_task_m.y);
        // Contact: first the touchdown (position control stops the approach), then the ramp from
        // the force measured when the touchdown ends.
        let r = g.update(p.settle_s + 0.02, -0.7, p.start_task_m.y);
        assert_eq!(r.phase, Phase::Touchdown);
        assert!(!r.force_mode && r.vel_mps.y < 0.0 && r.acc_mps2.y == 0.0, "starts at the approach speed: {r:?}");
        let r = g.update(p.settle_s + 0.02 + TOUCHDOWN_S, -2.5, p.start_task_m.y);
        assert_eq!(r.phase, Phase::ForceRamp);
        assert!(r.force_mode && (r.force_y_n + 2.5).abs() < 1e-12);
        let r = g.update(p.settle_s + 0.02 + TOUCHDOWN_S + p.force_ramp_s - 1e-9, -10.0, p.start_task_m.y);
        assert!((r.force_y_n - p.force_ref_n).abs() < 1e-6);
    }

    #[test]
    fn take_over_returns_smoothly_from_the_measured_pose_to_the_start_pose() {
        let p = ReferenceParams::from_scenario(&Scenario::default());
        let mut g = ReferenceGenerator::new(p);
        // Taken over mid-roll: the TCP is 20 mm along the strip and 0.3 mm into it.
        let here = Vector3::new(0.0, p.start_task_m.y - 3.3e-3, 0.020);
        let t0 = 1.234;
        g.reset_from(t0, &here);
        assert_eq!(g.phase(), Phase::Return);
        // First reference: where the TCP is, at rest; no force control (no force step either).
        let r = g.update(t0, 0.0, here.y);
        assert!((r.pos_m - here).norm() < 1e-15 && r.vel_mps.norm() < 1e-15 && !r.force_mode);
        // Position and velocity continuous tick to tick (C1), peak speed of a cosine blend.
        let dist = (p.start_task_m - here).norm();
        let dur = (dist / RETURN_SPEED_MPS).max(RETURN_MIN_S);
        let (mut prev, mut vmax) = (r, 0.0f64);
        let mut t = t0;
        while g.phase() == Phase::Return {
            t += 1e-3;
            let r = g.update(t, 0.0, here.y);
            assert!((r.pos_m - prev.pos_m).norm() <= 1e-3 * 0.5 * std::f64::consts::PI * dist / dur * 1.0001);
            vmax = vmax.max(r.vel_mps.norm());
            prev = r;
        }
        assert!((vmax - 0.5 * std::f64::consts::PI * dist / dur).abs() < 1e-3 * vmax);
        assert_eq!(g.phase(), Phase::Settle);
        assert!((t - t0 - dur).abs() <= 1e-3 + 1e-12);
        assert!((prev.pos_m - p.start_task_m).norm() < 1e-9);
        // Close to the start pose: no return move.
        let mut g = ReferenceGenerator::new(p);
        g.reset_from(0.0, &(p.start_task_m + Vector3::new(0.0, 1e-4, 0.0)));
        assert_eq!(g.phase(), Phase::Settle);
    }

    /// Back from a safe stop mid-roll with the wheel lifted 1 mm and 0.4 mm off in x: the
    /// reference starts at the measured pose (no step), re-finds the strip by position control
    /// while the plan stands still, touches down, then blends the force from the measured one.
    #[test]
    fn reengagement_starts_from_the_measured_pose_and_refinds_the_strip() {
        let mut g = gen();
        let p = *g.params();
        let y = p.start_task_m.y;
        g.update(0.0, 0.0, y);
        g.update(p.settle_s + 0.01, -1.0, y);
        let t_roll = p.settle_s + 0.01 + TOUCHDOWN_S + p.force_ramp_s + p.dwell_s;
        g.update(p.settle_s + 0.01 + TOUCHDOWN_S, -1.0, y);
        let t = t_roll + 0.5;
        let planned = g.update(t, -10.0, y);
        assert_eq!(planned.phase, Phase::Roll);
        let here = planned.pos_m + Vector3::new(0.4e-3, 1e-3, 0.0);
        g.reengage(t, &here, &Vector3::new(0.0, 0.02, 0.0), 0.0);
        assert!(g.holds_clock(), "off the strip: the roll waits");
        let r = g.update(t, 0.0, here.y);
        assert!(!r.force_mode);
        assert!((r.pos_m - here).norm() < 1e-12, "starts where the arm is: {:?} vs {here:?}", r.pos_m);
        assert!((r.vel_mps - Vector3::new(0.0, 0.02, 0.0)).norm() < 1e-12, "and as fast as it moves: {:?}", r.vel_mps);
        // Descend until contact; the roll does not advance meanwhile.
        let mut k = 1;
        let mut r = r;
        while r.pos_m.y > here.y - 0.8e-3 {
            r = g.update(t + k as f64 * 1e-3, 0.0, r.pos_m.y);
            k += 1;
            assert!(k < 2000, "never descended");
        }
        assert!((r.pos_m.z - planned.pos_m.z).abs() < 1e-12, "the roll stood still");
        let t_touch = t + k as f64 * 1e-3;
        let r = g.update(t_touch, -1.0, r.pos_m.y);
        assert!(!r.force_mode && r.vel_mps.y < 0.0, "touchdown from the approach speed");
        // The force law takes over once the touchdown is over and the re-engagement's fade has
        // ended (the arm no longer moves along the strip), from the force measured then.
        let mut tk = t_touch;
        let mut r = r;
        while !r.force_mode {
            tk += 1e-3;
            r = g.update(tk, -2.0, r.pos_m.y);
            assert!(tk < t_touch + 1.0, "never handed over");
        }
        assert!(tk >= t_touch + TOUCHDOWN_S - 1e-9 && tk >= t + REENGAGE_S - 1e-9, "handed over at {tk}");
        assert!((r.force_y_n + 2.0).abs() < 1e-12, "force starts at the measured -2 N: {}", r.force_y_n);
        assert!(!g.holds_clock());
        let r = g.update(tk + REENGAGE_S + 1e-3, -10.0, r.pos_m.y);
        assert!((r.force_y_n + 10.0).abs() < 1e-9 && r.phase == Phase::Roll);
    }

    /// Without a strip to find, the re-approach stops where the first approach would (1 mm below
    /// the nominal strip top), C¹: velocity continuous, acceleration its derivative.
    #[test]
    fn reapproach_without_contact_stops_at_the_first_approachs_deepest_point() {
        let p = ReferenceParams::from_scenario(&Scenario::default());
        let y_min = p.start_task_m.y - p.approach_max_descent_m;
        let (y0, v0) = (p.start_task_m.y + 1e-3, 0.02);
        let dt = 1e-4;
        let (mut prev, mut t) = (reapproach_profile(0.0, p.approach_ramp_s, y0, v0, p.approach_speed_mps, y_min), dt);
        // The largest acceleration: the cosine blend from v0 to the approach speed, π Δv / (2 ramp).
        let a_max = (v0 + p.approach_speed_mps) * std::f64::consts::PI / (2.0 * p.approach_ramp_s);
        assert_eq!(prev, (0.0, v0, 0.0));
        while t < 3.0 {
            let r = reapproach_profile(t, p.approach_ramp_s, y0, v0, p.approach_speed_mps, y_min);
            assert!((r.1 - prev.1).abs() <= a_max * dt * (1.0 + 1e-9), "velocity jump at {t}: {prev:?} -> {r:?}");
            let a_fd = (r.1 - prev.1) / dt;
            assert!((a_fd - 0.5 * (r.2 + prev.2)).abs() < 2e-3, "acceleration at {t}: {a_fd} vs {}", r.2);
            assert!((r.0 - prev.0 - 0.5 * (r.1 + prev.1) * dt).abs() < 1e-8, "position is the integral of the velocity at {t}");
            assert!(y0 + r.0 >= y_min - 1e-12, "below the deepest point at {t}");
            prev = r;
            t += dt;
        }
        assert!((y0 + prev.0 - y_min).abs() < 1e-12 && prev.1 == 0.0, "stopped at {} (deepest {y_min})", y0 + prev.0);
    }

    #[test]
    fn force_table_interpolates_holds_its_ends_and_drives_the_roll() {
        let mut sc = Scenario::default();
        sc.trajectory.force_ref_along_z = vec![[8.0, -10.0], [12.0, -14.0], [30.0, -12.0]];
        let p = ReferenceParams::from_scenario(&sc);
        assert_eq!(ReferenceParams::from_scenario(&Scenario::default()).force_at(0.011), -10.0);
        assert_eq!(p.force_at(0.002), -10.0);
        assert_eq!(p.force_at(0.012), -14.0);
        assert!((p.force_at(0.010) + 12.0).abs() < 1e-12);
        assert!((p.force_at(0.021) + 13.0).abs() < 1e-12);
        assert_eq!(p.force_at(0.038), -12.0);
        // Off the midpoints the blend is (1 - cos pi x)/2, not linear: a quarter of the way from
        // 8 mm (-10 N) to 12 mm (-14 N), -10 - 4 (1 - cos pi/4)/2 = -10.586 N (linear: -11 N).
        let quarter = -10.0 - 4.0 * (1.0 - (std::f64::consts::PI / 4.0).cos()) / 2.0;
        assert!((p.force_at(0.009) - quarter).abs() < 1e-12, "{} vs {quarter}", p.force_at(0.009));
        // The slope is the derivative of the set-point (central differences) and zero at a knot
        // from both sides (a linear table: 1,000 N/m and 111 N/m each side of 12 mm), so the
        // fed-forward rate has no step there.
        for z in [0.0085, 0.009, 0.0115, 0.02, 0.029] {
            let h = 1e-7;
            let fd = (p.force_at(z + h) - p.force_at(z - h)) / (2.0 * h);
            let slope = p.force_and_slope_at(z).1;
            assert!((slope - fd).abs() < 1e-6 * (1.0 + fd.abs()), "z {z}: slope {slope} vs {fd}");
        }
        for knot in [0.008, 0.012, 0.030] {
            for side in [-1e-9, 1e-9] {
                let slope = p.force_and_slope_at(knot + side).1;
                assert!(slope.abs() < 1e-2, "slope at {knot} {side:+}: {slope} N/m");
            }
        }
        // Through the phases: the dwell presses with the table's force at z_start, the roll with
        // the force at the reference's own z, and the ramp-down starts from the force at z_end.
        let mut g = ReferenceGenerator::new(p);
        let y = p.start_task_m.y;
        g.update(0.0, 0.0, y);
        let t_contact = p.settle_s + 0.01;
        g.update(t_contact, -1.0, y);
        let t_roll = t_contact + TOUCHDOWN_S + p.force_ramp_s + p.dwell_s;
        g.update(t_contact + TOUCHDOWN_S, -1.0, y);
        let r = g.update(t_roll - 1e-6, -10.0, y);
        assert_eq!((r.phase, r.force_y_n), (Phase::Dwell, -10.0));
        // The rate is the time derivative of the set-point (central differences, step 1 µs).
        let mut t = t_roll;
        let mut last = r;
        let h = 1e-6;
        while t < t_roll + p.roll_s - h {
            let r = g.update(t, -10.0, y);
            assert_eq!(r.phase, Phase::Roll);
            assert_eq!(r.force_y_n, p.force_at(r.pos_m.z));
            let fd = (g.reference_at(t + h, t + h).force_y_n - g.reference_at(t - h, t - h).force_y_n) / (2.0 * h);
            assert!((r.force_rate_y_nps - fd).abs() < 1e-4 * (1.0 + fd.abs()), "t {t}: rate {} vs {fd}", r.force_rate_y_nps);
            last = r;
            t += 1e-3;
        }
        let r = g.update(t_roll + p.roll_s + 1e-6, -12.0, y);
        assert_eq!(r.phase, Phase::RampDown);
        assert!((r.force_y_n - last.force_y_n).abs() < 1e-6, "ramp-down starts at {} after {}", r.force_y_n, last.force_y_n);
    }
}
