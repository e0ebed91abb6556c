//! The plant's physics: the IRB 2400 with its applicator wheel, (7.1)
//! `M(q) q̈ + C(q, q̇) q̇ + g(q) + Jᵀ(q) F_e = τ`, advanced one control tick at a time. F_e is the
//! wrench the tool exerts on the strip; the contact hands over its opposite, the wrench on the
//! tool W = −F_e, which enters as `+Jᵀ W` (messages/README.md, "Frames and signs").
//!
//! Integrator: `loop.substeps` equal substeps per tick (default 8, i.e. 125 µs at 1 kHz), each
//! one step of `loop.integrator` on `(q, q̇)`: explicit midpoint (second-order Runge–Kutta, the
//! default; one mass matrix, bias and factor per substep: see `midpoint`) or classic fourth-order Runge–Kutta (4 calls). The torque
//! is held constant over the tick (zero-order hold, as a real drive applies the controller's
//! command). Within a tick nothing in the robot is stiff: the controller acts only between ticks,
//! friction is viscous and small, and the contact acts through the shoulder and elbow (large
//! inertias; the wrist inertias M66 ≈ 6e-5 kg m² bare, a few 1e-4 with the tool, see no contact
//! moment about the wheel centre). Both methods resolve it with a wide margin at 100 µs.
//!
//! Why midpoint is the default: with the strip, the contact wrench is held over each substep, which
//! makes the coupled plant first order in the substep whatever the robot integrator's order; the
//! robot's own integration error is far below that. Measured on the default scenario (lockstep,
//! rolling-phase force tracking from the recordings): midpoint and RK4 agree to 2e-9 N at 5, 10,
//! 20 and 40 substeps, while 10 → 20 substeps changes the max error by 0.16 % and the RMS by
//! 0.015 % with either. Midpoint halves the plant's cost per tick (the lockstep speed target).
//! In free motion each method converges at its own order (tests below).

use std::path::Path;

use std::sync::Arc;

use anyhow::Context;
use robot::{Robot, Vec6};

use scenarios::{Boundary, Integrator, Scenario};

use crate::contact::StripTables;

/// The plant's integration substep of a scenario, s (`loop.period_s / loop.substeps`).
pub fn substep_s(s: &Scenario) -> f64 {
    s.loop_.period_s / s.loop_.substeps as f64
}

/// The plant robot of a scenario, built where the controller's is ([`scenarios::geometry::plant_robot`]):
/// the shared model with the plant's inertia mismatch on top.
pub use scenarios::geometry::plant_robot;

/// The contact tables of a scenario's strip at the reference bump and its substep (None without
/// the strip): from the on-disk cache beside the strip model (`table_cache`), else built from the
/// strip model (loaded or built in `cache_dir`) and cached. `rig sweep` calls it once per strip
/// for all its cases.
pub fn strip_tables(s: &Scenario, cache_dir: &Path) -> anyhow::Result<Option<Arc<StripTables>>> {
    if !s.strip.enabled {
        return Ok(None);
    }
    not_sliding_windows(s)?;
    tables_of(&model_params(s), substep_s(s), cache_dir).map(Some)
}

/// The reduced model the plant steps for a scenario's strip: the whole strip, or one window of
/// a windowed strip (`window_params`).
fn model_params(s: &Scenario) -> strip::StripParams {
    if s.strip.window_mm > 0.0 {
        window_params(s)
    } else {
        crate::contact::strip_params(s)
    }
}

/// One window of a windowed strip (issue 25): the scenario's strip `strip.window_mm` long. Its
/// bump (placed at the window's centre, half the window wide: for 40 mm windows the default
/// strip's, so the two share a cached model) is not used: the chain's substrate carries the
/// scenario's bumps, dips and seams.
pub fn window_params(s: &Scenario) -> strip::StripParams {
    let l = s.strip.window_mm * 1e-3;
    strip::StripParams {
        length_m: l,
        bulge_center_m: 0.5 * l,
        bulge_width_m: 0.5 * l,
        bulge_amplitude_m: strip::StripParams::BULGE_REFERENCE_M,
        ..crate::contact::strip_params(s)
    }
}

/// The contact tables of the model `params` at its reference bump and substep `h_s`: from the
/// on-disk cache, else built (the model loaded or built in `cache_dir`) and cached.
fn tables_of(params: &strip::StripParams, h_s: f64, cache_dir: &Path) -> anyhow::Result<Arc<StripTables>> {
    let params = params.with_reference_bulge();
    let t0 = std::time::Instant::now();
    let path = crate::table_cache::path(cache_dir, &params, h_s);
    if let Some(t) = crate::table_cache::load(&path, &params, h_s) {
        tracing::info!(load_ms = t0.elapsed().as_secs_f64() * 1e3, "contact tables loaded from {}", path.display());
        return Ok(Arc::new(t));
    }
    let model =
        strip::StripModel::load_or_build_in(cache_dir, &params).with_context(|| format!("strip model (cache {})", cache_dir.display()))?;
    let t_model = t0.elapsed();
    let tables = StripTables::new(&model, h_s);
    if let Err(e) = crate::table_cache::save(&tables, &path) {
        tracing::warn!("could not cache the contact tables in {}: {e}", path.display());
    }
    // Two parts of the plant's start-up (README, "Lockstep start-up").
    tracing::info!(
        model_ms = t_model.as_secs_f64() * 1e3,
        tables_ms = (t0.elapsed() - t_model).as_secs_f64() * 1e3,
        "strip model loaded, contact tables built and cached"
    );
    Ok(Arc::new(tables))
}

/// The chain contact of a windowed scenario on the window's `tables`: the chain of windows and
/// the substrate's static offsets (solved on the window's full FE model, or loaded from
/// `cache_dir` where an earlier run solved them: `substrate_cache`; a flat substrate needs none).
fn chain_contact(s: &Scenario, tables: Arc<StripTables>, cache_dir: &Path) -> anyhow::Result<crate::contact::chain::ChainContact> {
    use crate::contact::chain::{substrate_profile, ChainContact, ChainSubstrate};
    let st = &s.strip;
    let element_m = st.element_mm * 1e-3;
    let chain = strip::chain::WindowChain::new(st.length_mm * 1e-3, st.window_mm * 1e-3, st.window_spacing_mm * 1e-3, element_m)
        .context("the window chain of the long strip")?;
    let profile = substrate_profile(s);
    let substrate = if profile.features.is_empty() {
        ChainSubstrate::flat(&chain, element_m)
    } else {
        let t0 = std::time::Instant::now();
        let window = window_params(s);
        let path = crate::substrate_cache::path(cache_dir, &window, &chain, element_m, &profile);
        match crate::substrate_cache::load(&path, &chain, element_m) {
            Some(sub) => {
                tracing::info!(load_ms = t0.elapsed().as_secs_f64() * 1e3, "substrate offsets loaded from {}", path.display());
                sub
            }
            None => {
                let full = strip::chain::FullStatics::build(&window).context("the window's full FE model (substrate offsets)")?;
                let sub = ChainSubstrate::new(&tables, &chain, &full, &profile);
                if let Err(e) = crate::substrate_cache::save(&sub, &path) {
                    tracing::warn!("could not cache the substrate offsets in {}: {e}", path.display());
                }
                tracing::info!(
                    ms = t0.elapsed().as_secs_f64() * 1e3,
                    windows = chain.len(),
                    "substrate offsets of the long strip solved and cached"
                );
                sub
            }
        }
    };
    ChainContact::new(tables, chain, substrate, crate::contact::ContactGeometry::from_scenario(s))
}

/// (sin, cos) of `q + dq` from those of `q` (`sc`) by the angle sums, with sin and cos of the
/// small `dq` (a joint's travel over half a substep, about 1e-4 rad) from their Taylor series:
/// the same values as `robot::sin_cos(q + dq)` to a few ulp, for a sixth of the cost. Up to
/// |dq| = 0.01 rad the series' first omitted terms (dq⁹/9!, dq⁸/8!) stay below 1e-20; a joint
/// that moved more takes the library's sin and cos.
#[inline]
fn sin_cos_advanced(sc: &robot::SinCos, dq: &Vec6) -> robot::SinCos {
    let mut out = *sc;
    for (i, (s, c)) in out.iter_mut().enumerate() {
        let d = dq[i];
        let (sd, cd) = if d.abs() < 0.01 {
            let d2 = d * d;
            (d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0))), 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0)))
        } else {
            d.sin_cos()
        };
        (*s, *c) = (*s * cd + *c * sd, *c * cd - *s * sd);
    }
    out
}

/// Plant state and integrator.
pub struct Physics {
    robot: Robot,
    q: Vec6,
    qd: Vec6,
    /// Substeps per tick and their length, s.
    substeps: u32,
    dt_sub_s: f64,
    integrator: Integrator,
    /// Simulated time of the current state, s.
    time_s: f64,
    /// Where the strip lies, for the recorded wheel position without the strip.
    path: scenarios::path::StripPath,
    /// Strip + wheel contact (`contact.rs`); None when `strip.enabled = false` or windowed.
    contact: Option<crate::contact::StripContact>,
    /// The windowed long strip's contact (`contact::chain`); None unless `strip.window_mm > 0`.
    chain: Option<crate::contact::chain::ChainContact>,
    /// End stops and drive torque–speed limits, applied inside every integrator stage.
    limits: crate::limits::JointLimits,
    /// `[drives]`: friction with stiction and torque-constant errors (None: ideal drives).
    friction: Option<crate::drives::Friction>,
    /// The mass matrix factor and rigid-body bias of the last midpoint stage, for the next
    /// substep's first stage ([`Physics::midpoint`]); None before the first substep.
    lagged: Option<(robot::dynamics::MassFactor, Vec6)>,
}

/// A windowed (long) strip (issue 25, `strip.window_mm` > 0) is carried by the chain of windows
/// (`contact::chain`), built and validated for the bonded substrate only: a sliding bottom
/// carries load much farther along the strip than a window reaches (`strip::chain`).
fn not_sliding_windows(s: &Scenario) -> anyhow::Result<()> {
    anyhow::ensure!(
        !s.strip.enabled || s.strip.window_mm == 0.0 || s.strip.boundary != Boundary::Sliding,
        "strip.window_mm = {} mm with strip.boundary = \"sliding\": the windowed long strip (issue 25) holds for the bonded substrate only (a sliding bottom carries load farther than a window reaches)",
        s.strip.window_mm
    );
    Ok(())
}

impl Physics {
    /// Build the plant of a scenario, at rest in the start pose (IK of [`scenarios::path::start_tcp_pose`]).
    /// `cache_dir` is where a reduced strip model is cached (unused while the plant is robot-only).
    pub fn new(s: &Scenario, cache_dir: &Path) -> anyhow::Result<Physics> {
        Physics::with_strip_tables(s, strip_tables(s, cache_dir)?, cache_dir)
    }

    /// [`Physics::new`] with the strip's tables given (`rig sweep` builds them once for all its
    /// cases). `tables` must be those of the scenario's strip at the reference bump
    /// (`contact::strip_params(s).with_reference_bulge()`) and substep; this plant scales their
    /// bump to the scenario's height. None without the strip. A windowed strip's substrate
    /// offsets are cached in `cache_dir` (`substrate_cache`).
    pub fn with_strip_tables(s: &Scenario, tables: Option<Arc<StripTables>>, cache_dir: &Path) -> anyhow::Result<Physics> {
        not_sliding_windows(s)?;
        anyhow::ensure!(tables.is_some() == s.strip.enabled, "strip tables are needed exactly when strip.enabled");
        let mut chain = None;
        let contact = match tables {
            Some(tables) if s.strip.window_mm > 0.0 => {
                anyhow::ensure!(
                    *tables.params() == window_params(s) && tables.substep_s() == substep_s(s),
                    "the strip tables are not the scenario's window (substep {} s)",
                    substep_s(s)
                );
                chain = Some(chain_contact(s, tables, cache_dir)?);
                None
            }
            Some(tables) => {
                let params = crate::contact::strip_params(s);
                anyhow::ensure!(
                    *tables.params() == params.with_reference_bulge() && tables.substep_s() == substep_s(s),
                    "the strip tables are not the scenario's (its strip at the reference bump, substep {} s)",
                    substep_s(s)
                );
                let geo = crate::contact::ContactGeometry::from_scenario(s);
                Some(crate::contact::StripContact::with_tables(tables, geo, params.bulge_scale()))
            }
            None => None,
        };
        let robot = plant_robot(s);
        let target = scenarios::path::start_tcp_pose(s);
        let q = robot
            .ik_tcp(&target, &robot::ik_seed_tool_down())
            .with_context(|| format!("start pose {:?} of the scenario is not reachable", target.translation.vector))?;
        let limits = crate::limits::JointLimits::irb2400(&robot.mass_matrix(&q).diagonal());
        let friction = s.drives.enabled.then(|| crate::drives::Friction::new(&s.drives, &limits, &q));
        Ok(Physics {
            lagged: None,
            friction,
            limits,
            robot,
            q,
            qd: Vec6::zeros(),
            substeps: s.loop_.substeps,
            dt_sub_s: s.loop_.period_s / s.loop_.substeps as f64,
            integrator: s.loop_.integrator,
            time_s: 0.0,
            path: scenarios::path::StripPath::from_scenario(s),
            contact,
            chain,
        })
    }

    /// Joint positions, rad.
    pub fn q(&self) -> Vec6 {
        self.q
    }

    /// Joint velocities, rad/s.
    pub fn qd(&self) -> Vec6 {
        self.qd
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The plant's robot model.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Gravity torque g(q) of the plant at the current state, N m (the safe stop's feed-forward).
    pub fn gravity_torque(&self) -> Vec6 {
        self.robot.gravity_torque(&self.q)
    }

    /// The same plant on a bare arm: no end stops, ideal drives (the integrator's own tests).
    pub fn without_limits(mut self) -> Physics {
        self.limits = crate::limits::JointLimits::none();
        self
    }

    /// The cell's limits (end stops, drives).
    pub fn limits(&self) -> &crate::limits::JointLimits {
        &self.limits
    }

    /// Joint accelerations at `(q, qd)` under the drive torque for the command `tau.0`, the
    /// external torque `tau.1` (contact) and the end stops, all evaluated at this stage's state.
    /// Inside the ranges and below the drives' knee this is `forward_dynamics(q, qd, τ + τ_ext)`
    /// exactly (the limits add exact zeros). `sc`: the joints' (sin, cos) at `q`.
    #[inline]
    fn qdd(&self, q: &Vec6, sc: &robot::SinCos, qd: &Vec6, tau: &(Vec6, Vec6)) -> Vec6 {
        self.robot.forward_dynamics_sc(sc, qd, &self.applied_torque(q, qd, tau))
    }

    /// Everything but the arm's own dynamics at a stage's state: the drive torque for the
    /// command `tau.0`, the external torque `tau.1` (contact), the end stops and the drives'
    /// friction.
    #[inline]
    fn applied_torque(&self, q: &Vec6, qd: &Vec6, tau: &(Vec6, Vec6)) -> Vec6 {
        let mut total = self.limits.drive_torque(&tau.0, qd) + tau.1 + self.limits.end_stop_torque(q, qd);
        if let Some(f) = &self.friction {
            total += f.torque(q, qd);
        }
        total
    }

    /// TCP speed |J q̇| (translation), m/s, at the current state (the reflex's input).
    pub fn tcp_speed_mps(&self) -> f64 {
        let frames = self.robot.frames(&self.q);
        let p = self.robot.tcp_position(&frames);
        let v = self.robot.jacobian_point(&frames, &p) * self.qd;
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    }

    /// Force of the wheel on the strip along task y, N: F_e's task-y component, negative when
    /// pressing (0 without a strip).
    pub fn contact_force_n(&self) -> f64 {
        match (&self.contact, &self.chain) {
            (Some(c), _) => c.contact_force_n(),
            (None, Some(c)) => c.contact_force_n(),
            (None, None) => 0.0,
        }
    }

    /// Advance one tick with the joint torque `tau` (N m) held constant: `substeps` steps of the
    /// integrator. With the strip, each substep first advances the contact (`contact.rs`: strip
    /// exact, force implicit at the substep end) from the TCP state at the substep start; its
    /// wrench on the tool W = −F_e enters the robot as the generalized force J(q)ᵀ W held over the substep.
    pub fn step_tick(&mut self, tau_cmd: &Vec6) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { self.step_tick_avx2(tau_cmd) };
        }
        self.step_tick_portable(tau_cmd)
    }

    /// [`Physics::step_tick`] compiled for AVX2 (the rigid-body algebra inlined into it gets
    /// 4-wide vectors). The same bits as the baseline path: AVX2 brings no fused multiply-add and
    /// Rust lets the compiler neither contract nor reorder floating-point operations
    /// (`tests/tests/tick_identity.rs` pins the digests).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn step_tick_avx2(&mut self, tau_cmd: &Vec6) {
        self.step_tick_portable(tau_cmd)
    }

    #[inline(always)]
    fn step_tick_portable(&mut self, tau_cmd: &Vec6) {
        let h = self.dt_sub_s;
        // The drives apply the command through their torque constants.
        let applied = self.friction.as_ref().map(|f| f.applied(tau_cmd));
        let tau_cmd = applied.as_ref().unwrap_or(tau_cmd);
        for _ in 0..self.substeps {
            let (q, qd) = (self.q, self.qd);
            // One (sin, cos) of q for the contact's frames and the first stage's dynamics.
            let sc = robot::sin_cos(&q);
            let tau_ext = match self.contact.as_mut() {
                Some(c) => {
                    let frames = self.robot.frames_from_sin_cos(&sc);
                    let p = self.robot.tcp_position(&frames);
                    let jac = self.robot.jacobian_point(&frames, &p);
                    let w = c.substep(&p, &frames.rot[6], &(jac * qd));
                    jac.transpose() * w.as_vec6()
                }
                None => match self.chain.as_mut() {
                    Some(c) => {
                        let frames = self.robot.frames_from_sin_cos(&sc);
                        let p = self.robot.tcp_position(&frames);
                        let jac = self.robot.jacobian_point(&frames, &p);
                        let w = c.substep(&p, &frames.rot[6], &(jac * qd));
                        jac.transpose() * w.as_vec6()
                    }
                    None => Vec6::zeros(),
                },
            };
            let tau = &(*tau_cmd, tau_ext);
            (self.q, self.qd) = match self.integrator {
                Integrator::Midpoint => self.midpoint(&q, &sc, &qd, tau, h),
                Integrator::Rk4 => self.rk4(&q, &sc, &qd, tau, h),
            };
            self.limits.limit_driven_speed(tau_cmd, &mut self.qd);
            if let Some(f) = self.friction.as_mut() {
                f.slip(&self.q, &self.qd);
            }
        }
        self.time_s += h * self.substeps as f64;
    }

    /// One explicit-midpoint step of length h (second order). The first stage's accelerations
    /// only predict the midpoint velocity (`vm = q̇ + h/2 k1`), so an O(h) error in them costs
    /// O(h³) per step, like the method's own: that stage solves with the mass matrix factor and
    /// rigid-body bias of the previous substep's midpoint (half a substep old; the drive, contact,
    /// end-stop, friction and viscous torques are this stage's), and each substep costs one mass
    /// matrix, one bias and one factorisation instead of two. The first substep of a run has no
    /// previous midpoint and evaluates both stages in full.
    #[inline]
    fn midpoint(&mut self, q: &Vec6, sc: &robot::SinCos, qd: &Vec6, tau: &(Vec6, Vec6), h: f64) -> (Vec6, Vec6) {
        let k1a = match &self.lagged {
            Some((factor, bias)) => factor.solve(&(self.applied_torque(q, qd, tau) - bias - self.robot.friction_torque(qd))),
            None => self.qdd(q, sc, qd, tau),
        };
        let qm = q + qd * (0.5 * h);
        let vm = qd + k1a * (0.5 * h);
        let (factor, bias) = self.robot.dynamics_parts_sc(&sin_cos_advanced(sc, &(qd * (0.5 * h))), &vm);
        let km = factor.solve(&(self.applied_torque(&qm, &vm, tau) - bias - self.robot.friction_torque(&vm)));
        self.lagged = Some((factor, bias));
        (q + vm * h, qd + km * h)
    }

    /// One classic RK4 step of length h (fourth order).
    #[inline]
    fn rk4(&self, q: &Vec6, sc: &robot::SinCos, qd: &Vec6, tau: &(Vec6, Vec6), h: f64) -> (Vec6, Vec6) {
        let k1v = qd;
        let k1a = self.qdd(q, sc, qd, tau);
        let q2 = q + k1v * (0.5 * h);
        let v2 = qd + k1a * (0.5 * h);
        let k2a = self.qdd(&q2, &robot::sin_cos(&q2), &v2, tau);
        let q3 = q + v2 * (0.5 * h);
        let v3 = qd + k2a * (0.5 * h);
        let k3a = self.qdd(&q3, &robot::sin_cos(&q3), &v3, tau);
        let q4 = q + v3 * h;
        let v4 = qd + k3a * h;
        let k4a = self.qdd(&q4, &robot::sin_cos(&q4), &v4, tau);
        (q + (k1v + v2 * 2.0 + v3 * 2.0 + v4) * (h / 6.0), qd + (k1a + k2a * 2.0 + k3a * 2.0 + k4a) * (h / 6.0))
    }

    /// End-effector wrench the strip exerts on the tool (−F_e), as the sensor reports it
    /// ([`messages::WrenchFrame::SensorAtTcp`]): `(force N, torque N m)`. Zero without contact.
    pub fn wrench_on_tool(&self) -> ([f64; 3], [f64; 3]) {
        if self.contact.is_none() && self.chain.is_none() {
            return ([0.0; 3], [0.0; 3]);
        }
        self.wrench_on_tool_at(&self.robot.frames(&self.q).rot[6])
    }

    /// [`Physics::wrench_on_tool`] with the tool's orientation `rot_base_tool` (the current
    /// state's `frames.rot[6]`) given, for a caller that has the frames already.
    pub fn wrench_on_tool_at(&self, rot_base_tool: &nalgebra::Matrix3<f64>) -> ([f64; 3], [f64; 3]) {
        match (&self.contact, &self.chain) {
            (Some(c), _) => c.wrench_on_tool_sensor(rot_base_tool),
            (None, Some(c)) => c.wrench_on_tool_sensor(rot_base_tool),
            (None, None) => ([0.0; 3], [0.0; 3]),
        }
    }

    /// True while the wheel touches the strip.
    pub fn in_contact(&self) -> bool {
        self.contact.as_ref().is_some_and(|c| c.in_contact()) || self.chain.as_ref().is_some_and(|c| c.in_contact())
    }

    /// The strip's centre line from its state, for the recorder's writer thread (records of
    /// [`crate::contact::StripDetail::Modal`]): the single-model strip's whose state a record
    /// holds; None otherwise (the loop fills the centre line in).
    pub fn centre_line(&self) -> Option<std::sync::Arc<dyn recordings::CentreLineFromState>> {
        let c = self.contact.as_ref()?.centre_line()?;
        Some(std::sync::Arc::new(c))
    }

    /// The windowed long strip's contact, if the scenario has one.
    pub fn chain(&self) -> Option<&crate::contact::chain::ChainContact> {
        self.chain.as_ref()
    }

    /// The strip contact, if the scenario has a single-model strip (centre-line z for the recording metadata).
    pub fn contact(&self) -> Option<&crate::contact::StripContact> {
        self.contact.as_ref()
    }

    /// Strip outputs of the current state for the recording. Robot-only: the wheel position along
    /// the strip (the TCP's task z) and zero forces.
    pub fn fill_strip_record(&self, r: &mut recordings::StripRecord) {
        self.fill_strip_record_with(r, crate::contact::StripDetail::Full);
    }

    /// [`Physics::fill_strip_record`] to the given detail (the single-model strip's).
    pub fn fill_strip_record_with(&self, r: &mut recordings::StripRecord, detail: crate::contact::StripDetail) {
        r.modal_len = 0;
        if let Some(c) = &self.contact {
            c.fill_record_with(r, detail);
            return;
        }
        if let Some(c) = &self.chain {
            c.fill_record(r);
            return;
        }
        let tcp = self.robot.tcp_pose(&self.q);
        // (without a strip, a closed contour's first lap: no wheel on it to follow)
        r.wheel_z_m = self.path.to_path(&tcp.translation.vector, 0.0).z;
        r.contact_force_n = 0.0;
        r.bottom_force_n = 0.0;
        r.max_bottom_pressure_pa = 0.0;
        r.top_displacement_m = 0.0;
        r.n_centreline = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario() -> Scenario {
        let mut s = Scenario::default();
        s.strip.enabled = false;
        s
    }

    #[test]
    fn a_windowed_strip_on_a_sliding_substrate_is_refused_before_any_model_is_built() {
        // issue 25: the chain of windows holds for the bonded bottom only (the cache directory
        // does not exist: nothing may be written)
        let mut s = Scenario::default();
        s.strip.length_mm = 600.0;
        s.strip.window_mm = 40.0;
        s.strip.boundary = Boundary::Sliding;
        let e = Physics::new(&s, Path::new("/nonexistent/strip-cache")).err().expect("refused").to_string();
        assert!(e.contains("strip.window_mm = 40 mm") && e.contains("bonded substrate only"), "{e}");
    }

    #[test]
    fn starts_at_rest_in_the_start_pose() {
        let s = scenario();
        let p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
        let tcp = p.robot().tcp_pose(&p.q());
        let err = (tcp.translation.vector - scenarios::geometry::start_tcp_pose(&s).translation.vector).norm();
        assert!(err < 1e-9, "TCP {err} m from the start pose");
        assert_eq!(p.qd(), Vec6::zeros());
    }

    #[test]
    fn gravity_compensation_holds_the_arm_still() {
        let s = scenario();
        let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
        let q0 = p.q();
        for _ in 0..100 {
            let tau = p.gravity_torque();
            p.step_tick(&tau);
        }
        assert!((p.q() - q0).norm() < 1e-9, "drift {}", (p.q() - q0).norm());
        assert!((p.time_s() - 0.1).abs() < 1e-12);
    }

    /// Free fall (no torque, no friction) for `ticks` ms with `substeps` of `integrator`, on the
    /// bare arm (the end stops would take energy out of the swing).
    fn free_fall(integrator: Integrator, substeps: u32, ticks: usize, mut each_tick: impl FnMut(&Physics)) -> Physics {
        let mut s = scenario();
        s.loop_.substeps = substeps;
        s.loop_.integrator = integrator;
        let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap().without_limits();
        for _ in 0..ticks {
            p.step_tick(&Vec6::zeros());
            each_tick(&p);
        }
        assert!(p.qd().norm() > 1e-3, "the arm should be moving");
        p
    }

    /// Each integrator converges at its order: with the arm falling freely, the state after 100 ms
    /// changes 2^order times less between 2 and 4 substeps than between 1 and 2 (Richardson):
    /// ~16 for RK4, ~4 for midpoint.
    #[test]
    fn substep_refinement_converges_at_the_integrators_order() {
        for (integrator, order) in [(Integrator::Rk4, 4), (Integrator::Midpoint, 2)] {
            let run = |substeps| free_fall(integrator, substeps, 100, |_| {}).q();
            let (q1, q2, q4) = (run(1), run(2), run(4));
            let (e_coarse, e_fine) = ((q1 - q2).norm(), (q2 - q4).norm());
            eprintln!("{integrator:?} substep refinement: {e_coarse:.3e} rad (1 vs 2), {e_fine:.3e} rad (2 vs 4)");
            assert!(e_fine > 1e-14, "{integrator:?}: {e_fine}");
            let ratio = e_coarse / e_fine;
            let expect = (1u32 << order) as f64;
            assert!(ratio > 0.625 * expect && ratio < 1.5 * expect, "{integrator:?}: ratio {ratio}, order {order} gives {expect}");
        }
    }

    /// Energy: swinging freely for 0.5 s, T + V stays constant (no friction, no torque) to well
    /// under a millionth of the peak kinetic energy at the default substeps, and the error
    /// shrinks at the integrator's order when the substep is halved.
    #[test]
    fn free_swing_conserves_energy() {
        for (integrator, order) in [(Integrator::Rk4, 4), (Integrator::Midpoint, 2)] {
            let drift = |substeps| {
                let (mut e0, mut worst, mut t_peak) = (None, 0.0f64, 0.0f64);
                free_fall(integrator, substeps, 500, |p| {
                    let (t, v) = (p.robot().kinetic_energy(&p.q(), &p.qd()), p.robot().potential_energy(&p.q()));
                    let e0 = *e0.get_or_insert(v + t);
                    worst = worst.max((t + v - e0).abs());
                    t_peak = t_peak.max(t);
                });
                (worst, t_peak)
            };
            let (e10, t_peak) = drift(10);
            let (e5, _) = drift(5);
            eprintln!("{integrator:?}: energy error {e5:.3e} J (5 substeps), {e10:.3e} J (10), peak kinetic {t_peak:.3} J");
            assert!(t_peak > 1.0, "the arm hardly moved: {t_peak} J");
            assert!(e10 < 1e-6 * t_peak, "{integrator:?}: energy error {e10} J");
            // Round-off floors RK4's error; the order shows where the error is above it.
            if e10 > 1e-12 * t_peak {
                let ratio = e5 / e10;
                let expect = (1u32 << order) as f64;
                assert!(
                    ratio > 0.625 * expect && ratio < 1.5 * expect,
                    "{integrator:?}: energy error ratio {ratio}, order {order} gives {expect}"
                );
            }
        }
    }

    /// Each joint in turn, driven with half its torque limit on top of gravity compensation (the
    /// drive holds it at about its axis speed), runs into its end stop, which holds it within
    /// 2 degrees past the range (the stop is sized for 0.25 degree at the torque limit).
    #[test]
    fn end_stops_hold_a_joint_driven_into_them() {
        let s = scenario();
        for j in 0..6 {
            let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
            // The other joints held by gravity compensation and the safe stop's (capped) damping.
            let d = Vec6::from(crate::gate::safe_stop_damping(20.0, &p.robot().mass_matrix(&p.q()).diagonal(), 1e-3));
            let (mut worst, mut top_speed) = (0.0f64, 0.0f64);
            let [lo, hi] = p.limits().range_rad[j];
            for _ in 0..3000 {
                let mut tau = p.gravity_torque() - p.qd().component_mul(&d);
                tau[j] = p.gravity_torque()[j] + 0.5 * p.limits().torque_nm[j];
                p.step_tick(&tau);
                worst = worst.max(p.q()[j] - hi).max(lo - p.q()[j]);
                if worst <= 0.0 {
                    top_speed = top_speed.max(p.qd()[j].abs());
                }
            }
            eprintln!(
                "joint {}: {:.3} deg past its range, top speed before the stop {:.3} of the axis speed",
                j + 1,
                worst.to_degrees(),
                top_speed / p.limits().speed_radps[j]
            );
            assert!(worst > 0.0, "joint {} never reached its stop", j + 1);
            assert!(worst < 2f64.to_radians(), "joint {}: {} deg past its range", j + 1, worst.to_degrees());
        }
    }

    /// `[drives]`: joint 1 (vertical axis, no gravity) under 0.8 of its breakaway torque does not
    /// move by one encoder count (2^22 per turn) from 0.2 s to 1.2 s (the stick spring's
    /// deflection settles first); under twice its breakaway it accelerates as the closed form of
    /// the Coulomb + viscous joint says, v(t) = (τ − τ_c)/b (1 − exp(−b t / M₁₁)), within 3 %
    /// at 0.5 s. The other joints are held by gravity compensation and their own stiction.
    #[test]
    fn a_joint_sticks_below_breakaway_and_accelerates_above_it_as_the_closed_form_says() {
        let mut s = scenario();
        s.drives.enabled = true;
        s.drives.coulomb_nm = [5.0, 5.0, 2.5, 0.3, 0.3, 0.15];
        s.drives.breakaway_nm = [6.5, 6.5, 3.25, 0.4, 0.4, 0.2];
        s.drives.viscous_nms = [2.0, 2.0, 1.0, 0.1, 0.1, 0.05];
        let count = std::f64::consts::TAU / 4_194_304.0;
        let run = |tau1: f64, ticks: usize| {
            let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
            let mut trace = Vec::new();
            for _ in 0..ticks {
                let mut tau = p.gravity_torque();
                tau[0] += tau1;
                p.step_tick(&tau);
                trace.push((p.q()[0], p.qd()[0]));
            }
            (p, trace)
        };
        let (_, held) = run(0.8 * 6.5, 1200);
        let drift = (held[1199].0 - held[199].0).abs();
        eprintln!("joint 1 at 0.8 breakaway: drift {drift:.3e} rad over 1 s (one count {count:.3e} rad)");
        assert!(drift < count, "drift {drift} rad");
        let (p, moving) = run(2.0 * 6.5, 500);
        let m11 = p.robot().mass_matrix(&p.q()).diagonal()[0];
        let (tau, tc, b, t) = (13.0, 5.0, 2.0, 0.5);
        let want = (tau - tc) / b * (1.0 - (-b * t / m11).exp());
        let got = moving[499].1;
        eprintln!("joint 1 at twice breakaway: {got:.5} rad/s at 0.5 s, closed form {want:.5} (M11 {m11:.3} kg m^2)");
        assert!((got / want - 1.0).abs() < 0.03, "{got} vs {want}");
    }

    /// The midpoint stage's (sin, cos) from the substep start's agree with the library's at the
    /// midpoint to 1e-15 (a few ulp), over the range of joint travel per half substep and beyond
    /// the series'.
    #[test]
    fn advanced_sin_cos_equals_the_librarys() {
        let q = Vec6::new(0.3, -1.2, 2.9, -3.1, 0.0, 1.5);
        for d in [0.0, 1e-9, -3e-6, 1e-4, -2e-3, 9.9e-3, -0.05, 0.7] {
            let dq = Vec6::from_element(d);
            let got = sin_cos_advanced(&robot::sin_cos(&q), &dq);
            for (i, &(s, c)) in got.iter().enumerate() {
                let (ws, wc) = (q[i] + d).sin_cos();
                assert!((s - ws).abs() < 1e-15 && (c - wc).abs() < 1e-15, "q {} + {d}: ({s}, {c}) vs ({ws}, {wc})", q[i]);
            }
        }
    }

    #[test]
    fn identical_inputs_give_bit_identical_states() {
        for integrator in [Integrator::Midpoint, Integrator::Rk4] {
            identical_inputs_give_bit_identical_states_with(integrator);
        }
    }

    fn identical_inputs_give_bit_identical_states_with(integrator: Integrator) {
        let mut s = scenario();
        s.loop_.integrator = integrator;
        let run = || {
            let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
            for k in 0..50 {
                let tau = p.gravity_torque() + Vec6::from_element((k as f64 * 0.1).sin());
                p.step_tick(&tau);
            }
            (p.q(), p.qd())
        };
        let (a, b) = (run(), run());
        assert!(a.0.iter().zip(b.0.iter()).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert!(a.1.iter().zip(b.1.iter()).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}
