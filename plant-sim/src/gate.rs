//! The torque gate: decides, every tick, which joint torque the plant applies (DESIGN section 6).
//!
//! - A fresh, valid torque for this tick is applied (blended in after a takeover, see below).
//! - A late, missing or refused torque is a *miss*: the last applied torque is held and counted.
//! - `max_consecutive_misses` misses in a row: safe stop, until a valid torque arrives again. The
//!   safe stop is a *position hold* (a category-2 stop of ISO 10218-1: brake to standstill with the
//!   drives on, then hold), `τ = g(q) + M(q) (ω² (q_a − q) − 2ω q̇)` about the anchor `q_a`, the
//!   joint position at the hold's first tick: computed torque with the plant's own model, so every
//!   joint is a critically damped pole pair at `ω = 2π loop.hold_bandwidth_hz`, the arm's coupling
//!   cancelled (only Coriolis and contact forces act besides). After a reflex the stop is
//!   *compliant* instead, `τ = g(q) − D q̇` (gravity compensation plus joint damping): it gives way,
//!   so the force or speed that tripped the reflex is relieved, not held. The wait for the first
//!   answer is compliant too: the arm is at rest and the gravity compensation exact, so it stays
//!   where it is either way (and the first controller's blend, part of every recording, starts
//!   from what it always did).
//! - Takeover without a torque jump: when a torque arrives from a new `controller_id`, or the first
//!   one after the safe stop or after start-up, the applied torque moves linearly from what the
//!   plant would otherwise apply (held torque or safe-stop torque) to the controller's over
//!   `takeover_blend_s`.
//! - Refusal: another contract version, NaN/infinite entries or entries beyond the joint torque
//!   limits make the torque a miss, reported with the reason.
//!
//! Pure logic, allocation-free, so it is unit-tested without processes.

use messages::{check_version, ControllerStatus, JointTorque, PlantStatus, VersionMismatch, CONTRACT_VERSION};
use robot::{Mat6, Vec6};

/// Why a torque was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    Version(VersionMismatch),
    NotFinite { joint: usize },
    OutOfLimit { joint: usize, value_nm: f64, limit_nm: f64 },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Version(v) => write!(f, "torque refused: {v}"),
            Refusal::NotFinite { joint } => write!(f, "torque refused: joint {} torque is not finite", joint + 1),
            Refusal::OutOfLimit { joint, value_nm, limit_nm } => {
                write!(f, "torque refused: joint {} torque {value_nm:.1} N m exceeds the limit {limit_nm:.1} N m", joint + 1)
            }
        }
    }
}

/// Check a torque message against the contract and the joint torque limits.
pub fn validate(t: &JointTorque, limit_nm: &[f64; 6]) -> Result<Vec6, Refusal> {
    check_version(CONTRACT_VERSION, t.contract_version, "joint torque").map_err(Refusal::Version)?;
    for (joint, (&v, &lim)) in t.tau.iter().zip(limit_nm.iter()).enumerate() {
        if !v.is_finite() {
            return Err(Refusal::NotFinite { joint });
        }
        if v.abs() > lim {
            return Err(Refusal::OutOfLimit { joint, value_nm: v, limit_nm: lim });
        }
    }
    Ok(Vec6::from(t.tau))
}

/// Gate parameters (from the scenario's `[loop]`).
#[derive(Debug, Clone, Copy)]
pub struct GateConfig {
    pub max_consecutive_misses: u32,
    /// Ticks over which a takeover is blended (0 = switch at once).
    pub blend_ticks: u32,
    /// Joint damping of the compliant stop (after a reflex) per joint, N m s/rad (see
    /// [`safe_stop_damping`]).
    pub safe_stop_damping_nms: [f64; 6],
    /// The position hold's ω = 2π `loop.hold_bandwidth_hz`, rad/s; 0 makes every hold compliant.
    /// Held over a tick the hold's poles are `1 − ωT` to first order: stable for the scenario's
    /// range, `ωT` ≤ 0.15 (5 Hz at 1 ms: `ωT` = 0.031).
    pub hold_omega_radps: f64,
    pub torque_limit_nm: [f64; 6],
}

/// Per-joint safe-stop damping: the scenario's `d_nms`, capped at `0.3 M_ii / T`. The damping
/// torque is held over a tick like any command, and a held damping torque `−D q̇` on an inertia
/// `M_ii` has the discrete pole `1 − D T / M_ii`: the wrist (M66 ≈ 5e-4 kg m²) would go unstable
/// with 20 N m s/rad at T = 1 ms. The cap keeps every pole in [0.7, 1) — what a drive's faster
/// inner damping loop achieves on the real robot.
pub fn safe_stop_damping(d_nms: f64, mass_diag: &Vec6, period_s: f64) -> [f64; 6] {
    std::array::from_fn(|i| d_nms.min(0.3 * mass_diag[i] / period_s))
}

/// Rare events of one tick, for the recording and the log.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GateEvents {
    /// First miss after a good tick.
    pub miss_streak_started: bool,
    pub safe_stop_entered: bool,
    pub safe_stop_cleared: bool,
    /// A controller took over: `(previous id or None at the first controller, new id)`.
    pub controller_change: Option<(Option<u64>, u64)>,
    /// The controller reported a fault of its own.
    pub controller_fault: bool,
    /// The controller acknowledged a latched reflex (`controller_status` = starting).
    pub reflex_acknowledged: bool,
}

/// What the plant applies over this tick.
#[derive(Debug, Clone, Copy)]
pub struct Decision {
    pub tau: Vec6,
    /// The torque was held or replaced (not this tick's fresh controller torque).
    pub held: bool,
    /// This tick counted as a miss.
    pub missed: bool,
    pub refused: Option<Refusal>,
    pub events: GateEvents,
}

#[derive(Debug, Clone, Copy)]
enum BlendFrom {
    Held(Vec6),
    SafeStop,
}

/// The arm as the plant has it at the start of a tick, for the hold: q, q̇, and g(q) and M(q)
/// on demand (only a hold needs them: a tick the controller's torque passes costs neither).
pub struct ArmNow<'a> {
    pub gravity: &'a dyn Fn() -> Vec6,
    pub q: Vec6,
    pub qd: Vec6,
    pub mass_matrix: &'a dyn Fn() -> Mat6,
}

/// The plant's hold ([`Gate`]'s docs).
#[derive(Debug, Clone, Copy)]
enum Hold {
    /// Gravity compensation plus joint damping: the arm gives way (and, at rest, stays).
    Compliant,
    /// About the anchor, once taken.
    Position(Option<Vec6>),
}

#[derive(Debug, Clone, Copy)]
struct Blend {
    from: BlendFrom,
    done_ticks: u32,
}

/// Gate state across ticks.
#[derive(Debug, Clone)]
pub struct Gate {
    cfg: GateConfig,
    status: PlantStatus,
    last_applied: Vec6,
    consecutive_misses: u32,
    total_misses: u64,
    safe_stops: u64,
    refusals: u64,
    controller_id: Option<u64>,
    blend: Option<Blend>,
    /// A reflex put the plant in safe stop; only a controller's acknowledgement (an answer with
    /// `controller_status` = starting) clears it, as libfranka's automatic error recovery does.
    reflex_latched: bool,
    reflexes: u64,
    /// The hold applied now (and blended from): compliant while waiting for the first answer
    /// and after a reflex, a position hold in any other safe stop. A position hold's anchor `q_a`
    /// is taken on its first tick; each safe stop begins a hold of its own.
    hold: Hold,
}

impl Gate {
    pub fn new(cfg: GateConfig) -> Gate {
        Gate {
            cfg,
            status: PlantStatus::WaitingForController,
            last_applied: Vec6::zeros(),
            consecutive_misses: 0,
            total_misses: 0,
            safe_stops: 0,
            refusals: 0,
            controller_id: None,
            blend: None,
            reflex_latched: false,
            reflexes: 0,
            hold: Hold::Compliant,
        }
    }

    /// A reflex tripped: safe stop at once, latched until acknowledged. Returns true if the plant
    /// was not in safe stop before.
    pub fn reflex(&mut self) -> bool {
        self.reflexes += 1;
        self.reflex_latched = true;
        self.blend = None;
        self.hold = Hold::Compliant;
        let entered = self.status != PlantStatus::SafeStop;
        if entered {
            self.safe_stops += 1;
        }
        self.status = PlantStatus::SafeStop;
        entered
    }

    /// The active controller is gone (its process ended or its node is dead) and nobody took
    /// over: safe stop now instead of after `max_consecutive_misses`. Returns true if entered.
    pub fn controller_gone(&mut self) -> bool {
        self.blend = None;
        let entered = self.status != PlantStatus::SafeStop && self.status != PlantStatus::WaitingForController;
        if entered {
            self.safe_stops += 1;
            self.status = PlantStatus::SafeStop;
            self.hold = self.position_hold();
        }
        entered
    }

    /// The safe stop is latched by a reflex.
    pub fn reflex_latched(&self) -> bool {
        self.reflex_latched
    }
    pub fn reflexes(&self) -> u64 {
        self.reflexes
    }

    /// Status to publish with the next state (it describes the torque applied over the last tick).
    pub fn status(&self) -> PlantStatus {
        self.status
    }
    pub fn consecutive_misses(&self) -> u32 {
        self.consecutive_misses
    }
    pub fn total_misses(&self) -> u64 {
        self.total_misses
    }
    pub fn safe_stops(&self) -> u64 {
        self.safe_stops
    }
    pub fn refusals(&self) -> u64 {
        self.refusals
    }
    pub fn controller_id(&self) -> Option<u64> {
        self.controller_id
    }
    /// Torque applied over the last tick.
    /// EGM: the robot controller's own servo applied `tau` (no controller answer went through
    /// the gate); the next state reports it as applied.
    pub fn servo_applied(&mut self, tau: Vec6) {
        self.last_applied = tau;
    }

    pub fn last_applied(&self) -> Vec6 {
        self.last_applied
    }

    /// The hold's anchor, if the plant holds a position (None: compliant, or before the hold's
    /// first tick).
    pub fn hold_anchor(&self) -> Option<Vec6> {
        match self.hold {
            Hold::Position(anchor) => anchor,
            Hold::Compliant => None,
        }
    }

    /// The hold a safe stop begins (not a reflex's): a position hold, unless its ω is zero.
    fn position_hold(&self) -> Hold {
        if self.cfg.hold_omega_radps > 0.0 {
            Hold::Position(None)
        } else {
            Hold::Compliant
        }
    }

    /// Enter the safe stop from a running or holding controller (misses, its fault).
    fn enter_safe_stop(&mut self) {
        self.status = PlantStatus::SafeStop;
        self.safe_stops += 1;
        self.hold = self.position_hold();
    }

    /// The hold's torque this tick: the position hold about its anchor (taken now if it has
    /// none yet), or the compliant hold.
    fn safe_stop_torque(&mut self, arm: &ArmNow) -> Vec6 {
        let w = self.cfg.hold_omega_radps;
        match &mut self.hold {
            Hold::Compliant => (arm.gravity)() - arm.qd.component_mul(&Vec6::from(self.cfg.safe_stop_damping_nms)),
            Hold::Position(anchor) => {
                let anchor = *anchor.get_or_insert(arm.q);
                (arm.gravity)() + (arm.mass_matrix)() * ((anchor - arm.q) * (w * w) - arm.qd * (2.0 * w))
            }
        }
    }

    /// Decide the torque of one tick. `torque` is this tick's answer (None if none arrived in
    /// time); `arm` is the plant's arm now, for the hold.
    pub fn decide(&mut self, torque: Option<&JointTorque>, arm: &ArmNow) -> Decision {
        let mut events = GateEvents::default();
        let verdict = torque.map(|t| (t, validate(t, &self.cfg.torque_limit_nm)));
        let refused = match verdict {
            Some((_, Err(r))) => Some(r),
            _ => None,
        };
        if let Some((t, Ok(tau))) = verdict {
            if t.controller_status == ControllerStatus::Fault as u32 {
                // The controller asks for the safe stop; it is not a miss.
                events.controller_fault = true;
                if self.status != PlantStatus::SafeStop {
                    events.safe_stop_entered = true;
                    self.enter_safe_stop();
                }
                self.consecutive_misses = 0;
                self.blend = None;
                let tau = self.safe_stop_torque(arm);
                self.last_applied = tau;
                return Decision { tau, held: true, missed: false, refused: None, events };
            }
            if self.reflex_latched {
                if t.controller_status != ControllerStatus::Starting as u32 {
                    // Answered, but the reflex holds: not a miss, the safe stop goes on.
                    self.consecutive_misses = 0;
                    let tau = self.safe_stop_torque(arm);
                    self.last_applied = tau;
                    return Decision { tau, held: true, missed: false, refused: None, events };
                }
                self.reflex_latched = false;
                events.reflex_acknowledged = true;
            }
            let new_controller = self.controller_id != Some(t.controller_id);
            if new_controller {
                events.controller_change = Some((self.controller_id, t.controller_id));
                self.controller_id = Some(t.controller_id);
            }
            let from = match self.status {
                PlantStatus::WaitingForController | PlantStatus::SafeStop => Some(BlendFrom::SafeStop),
                _ if new_controller => Some(BlendFrom::Held(self.last_applied)),
                _ => None,
            };
            if self.status == PlantStatus::SafeStop {
                events.safe_stop_cleared = true;
            }
            if let Some(from) = from {
                self.blend = (self.cfg.blend_ticks > 0).then_some(Blend { from, done_ticks: 0 });
            }
            let applied = match self.blend {
                Some(mut b) => {
                    b.done_ticks += 1;
                    let a = b.done_ticks as f64 / self.cfg.blend_ticks as f64;
                    let from = match b.from {
                        BlendFrom::Held(x) => x,
                        BlendFrom::SafeStop => self.safe_stop_torque(arm),
                    };
                    self.blend = (b.done_ticks < self.cfg.blend_ticks).then_some(b);
                    from + (tau - from) * a
                }
                None => tau,
            };
            self.status = PlantStatus::Running;
            self.consecutive_misses = 0;
            self.last_applied = applied;
            return Decision { tau: applied, held: false, missed: false, refused: None, events };
        }

        // Miss: nothing in time, or refused. Before any controller, only refusals count.
        if refused.is_some() {
            self.refusals += 1;
        }
        let counts = refused.is_some() || self.status != PlantStatus::WaitingForController;
        if counts {
            self.total_misses += 1;
            self.consecutive_misses += 1;
            if self.consecutive_misses == 1 {
                events.miss_streak_started = true;
            }
            if self.consecutive_misses >= self.cfg.max_consecutive_misses && self.status != PlantStatus::SafeStop {
                self.enter_safe_stop();
                events.safe_stop_entered = true;
            } else if self.status == PlantStatus::Running {
                self.status = PlantStatus::HoldingTorque;
            }
        }
        let tau = match self.status {
            PlantStatus::WaitingForController | PlantStatus::SafeStop => self.safe_stop_torque(arm),
            _ => self.last_applied,
        };
        self.last_applied = tau;
        Decision { tau, held: true, missed: counts, refused, events }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMIT: [f64; 6] = [100.0; 6];

    fn cfg() -> GateConfig {
        GateConfig {
            max_consecutive_misses: 3,
            blend_ticks: 4,
            safe_stop_damping_nms: [2.0; 6],
            hold_omega_radps: 0.0,
            torque_limit_nm: LIMIT,
        }
    }

    /// A gate whose holds are position holds at ω = 10 rad/s.
    fn holding() -> GateConfig {
        GateConfig { hold_omega_radps: 10.0, ..cfg() }
    }

    /// The tests' arm: inertia 2 kg m² on every joint, uncoupled.
    fn mass() -> Mat6 {
        Mat6::identity() * 2.0
    }

    fn arm(q: Vec6, qd: Vec6) -> ArmNow<'static> {
        ArmNow { gravity: &g, q, qd, mass_matrix: &mass }
    }

    /// The joint position the tests' plant reports unless a test moves it.
    const Q: Vec6 = Vec6::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);

    fn torque(id: u64, tau: f64) -> JointTorque {
        JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status: ControllerStatus::Active as u32,
            tick: 0,
            controller_id: id,
            tau: [tau; 6],
        }
    }

    const G: f64 = 10.0;
    fn g() -> Vec6 {
        Vec6::from_element(G)
    }

    #[test]
    fn first_controller_blends_in_from_gravity_compensation() {
        let mut gate = Gate::new(cfg());
        let qd = Vec6::zeros();
        let d = gate.decide(None, &arm(Q, qd));
        assert_eq!(d.tau, g());
        assert!(!d.missed, "no miss before the first controller");
        let taus: Vec<f64> = (0..5).map(|_| gate.decide(Some(&torque(1, 30.0)), &arm(Q, qd)).tau[0]).collect();
        // Linear from 10 to 30 over 4 ticks, then the controller's value.
        assert_eq!(taus, vec![15.0, 20.0, 25.0, 30.0, 30.0]);
        assert_eq!(gate.status(), PlantStatus::Running);
    }

    #[test]
    fn misses_hold_then_safe_stop_then_resume_without_jump() {
        let mut gate = Gate::new(GateConfig { blend_ticks: 0, ..cfg() });
        let qd = Vec6::from_element(1.0);
        gate.decide(Some(&torque(1, 50.0)), &arm(Q, qd));
        let d1 = gate.decide(None, &arm(Q, qd));
        assert!(d1.held && d1.missed && d1.events.miss_streak_started);
        assert_eq!(d1.tau[0], 50.0);
        assert_eq!(gate.status(), PlantStatus::HoldingTorque);
        gate.decide(None, &arm(Q, qd));
        let d3 = gate.decide(None, &arm(Q, qd));
        assert!(d3.events.safe_stop_entered);
        assert_eq!(gate.status(), PlantStatus::SafeStop);
        assert_eq!(d3.tau[0], G - 2.0 * 1.0, "gravity minus damping");
        assert_eq!(gate.total_misses(), 3);
        assert_eq!(gate.safe_stops(), 1);
        // With blending on, the comeback starts near the safe-stop torque.
        let mut gate2 = Gate::new(cfg());
        gate2.decide(Some(&torque(1, 50.0)), &arm(Q, qd));
        for _ in 0..3 {
            gate2.decide(None, &arm(Q, qd));
        }
        let back = gate2.decide(Some(&torque(1, 50.0)), &arm(Q, qd));
        assert!(back.events.safe_stop_cleared);
        assert_eq!(back.tau[0], 8.0 + (50.0 - 8.0) / 4.0);
    }

    #[test]
    fn new_controller_id_blends_from_the_held_torque() {
        let mut gate = Gate::new(cfg());
        let qd = Vec6::zeros();
        for _ in 0..4 {
            gate.decide(Some(&torque(1, 20.0)), &arm(Q, qd));
        }
        assert_eq!(gate.last_applied()[0], 20.0);
        let d = gate.decide(Some(&torque(2, 60.0)), &arm(Q, qd));
        assert_eq!(d.events.controller_change, Some((Some(1), 2)));
        assert_eq!(d.tau[0], 30.0);
    }

    #[test]
    fn refusals_are_misses_with_reasons() {
        let mut gate = Gate::new(cfg());
        let qd = Vec6::zeros();
        gate.decide(Some(&torque(1, 20.0)), &arm(Q, qd));
        let mut bad = torque(1, 20.0);
        bad.tau[2] = f64::NAN;
        let d = gate.decide(Some(&bad), &arm(Q, qd));
        assert!(d.missed && d.held);
        assert_eq!(d.refused, Some(Refusal::NotFinite { joint: 2 }));
        let d = gate.decide(Some(&torque(1, 150.0)), &arm(Q, qd));
        assert!(matches!(d.refused, Some(Refusal::OutOfLimit { joint: 0, .. })));
        let mut other = torque(1, 20.0);
        other.contract_version = CONTRACT_VERSION + 1;
        let d = gate.decide(Some(&other), &arm(Q, qd));
        let text = d.refused.unwrap().to_string();
        assert!(text.contains(&format!("version {}", CONTRACT_VERSION + 1)), "{text}");
        assert!(text.contains(&format!("version {CONTRACT_VERSION}")), "{text}");
        assert_eq!(gate.refusals(), 3);
        assert_eq!(gate.status(), PlantStatus::SafeStop, "3 refusals in a row reach the limit");
    }

    /// The capped damping held over a tick is stable on every joint: pole 1 − D T / M in (−1, 1).
    #[test]
    fn safe_stop_damping_is_stable_as_a_held_torque() {
        let robot = robot::Robot::irb2400_with_tool(robot::Tool::default());
        let m = robot.mass_matrix(&robot::ik_seed_tool_down()).diagonal();
        let d = safe_stop_damping(20.0, &m, 1e-3);
        for i in 0..6 {
            let pole = 1.0 - d[i] * 1e-3 / m[i];
            assert!(pole > 0.0 && pole < 1.0, "joint {}: pole {pole}", i + 1);
        }
        assert_eq!(d[1], 20.0, "the heavy shoulder keeps the scenario's damping");
        assert!(d[5] < 20.0, "the light wrist is capped");
    }

    #[test]
    fn a_reflex_latches_the_safe_stop_until_the_controller_acknowledges_it() {
        let mut gate = Gate::new(cfg());
        let qd = Vec6::zeros();
        for _ in 0..5 {
            gate.decide(Some(&torque(1, 30.0)), &arm(Q, qd));
        }
        assert!(gate.reflex(), "entered the safe stop");
        assert!(!gate.reflex(), "already in it");
        assert_eq!(gate.safe_stops(), 1);
        for _ in 0..10 {
            let d = gate.decide(Some(&torque(1, 30.0)), &arm(Q, qd));
            assert!(d.held && !d.missed && d.refused.is_none());
            assert_eq!(d.tau, g(), "safe-stop torque while latched");
        }
        assert_eq!(gate.status(), PlantStatus::SafeStop);
        let mut ack = torque(1, 30.0);
        ack.controller_status = ControllerStatus::Starting as u32;
        let d = gate.decide(Some(&ack), &arm(Q, qd));
        assert!(d.events.reflex_acknowledged && d.events.safe_stop_cleared);
        assert_eq!(d.tau[0], G + (30.0 - G) / 4.0, "blended in from the safe stop");
        assert!(!gate.reflex_latched());
        assert_eq!(gate.total_misses(), 0);
    }

    #[test]
    fn a_position_hold_anchors_on_its_first_tick_and_each_safe_stop_takes_its_own() {
        let mut gate = Gate::new(GateConfig { blend_ticks: 0, ..holding() });
        let qd = Vec6::from_element(0.1);
        let at = |x: f64| Vec6::from_element(x);
        // Waiting for the first answer the hold is compliant (the scenario's damping, 2).
        let d = gate.decide(None, &arm(at(0.2), qd));
        assert_eq!(d.tau[0], G - 2.0 * 0.1);
        assert_eq!(gate.hold_anchor(), None);
        gate.decide(Some(&torque(1, 50.0)), &arm(at(0.3), qd));
        // Three misses: the third is the safe stop's first tick, anchored where the arm is then.
        gate.decide(None, &arm(at(0.4), qd));
        gate.decide(None, &arm(at(0.5), qd));
        let d = gate.decide(None, &arm(at(0.6), qd));
        assert!(d.events.safe_stop_entered);
        // τ = g + M (ω² (q_a − q) − 2ω q̇), M = 2, ω = 10.
        assert_eq!(d.tau[0], G - 2.0 * 20.0 * 0.1, "on the anchor only the hold's damping acts");
        assert_eq!(gate.hold_anchor(), Some(at(0.6)));
        let d = gate.decide(None, &arm(at(0.61), qd));
        assert!((d.tau[0] - (G + 2.0 * (100.0 * (0.6 - 0.61) - 20.0 * 0.1))).abs() < 1e-12, "pulled back to 0.6 rad");
        // The controller comes back, then is lost: the new stop holds where the arm is now.
        gate.decide(Some(&torque(1, 50.0)), &arm(at(0.7), qd));
        assert!(gate.controller_gone());
        let d = gate.decide(None, &arm(at(0.8), qd));
        assert_eq!(d.tau[0], G - 2.0 * 20.0 * 0.1);
        assert_eq!(gate.hold_anchor(), Some(at(0.8)));
    }

    #[test]
    fn a_reflex_stop_is_compliant_even_when_holds_hold_position() {
        let mut gate = Gate::new(holding());
        let qd = Vec6::from_element(0.1);
        gate.decide(None, &arm(Q, qd));
        for _ in 0..5 {
            gate.decide(Some(&torque(1, 30.0)), &arm(Q, qd));
        }
        gate.reflex();
        assert_eq!(gate.hold_anchor(), None);
        // Far from any earlier anchor: no spring pulls, the scenario's damping alone acts.
        let d = gate.decide(Some(&torque(1, 30.0)), &arm(Vec6::from_element(1.0), qd));
        assert_eq!(d.tau, g() - qd * 2.0);
        assert_eq!(gate.hold_anchor(), None);
    }

    #[test]
    fn controller_fault_requests_safe_stop() {
        let mut gate = Gate::new(cfg());
        let qd = Vec6::zeros();
        let mut t = torque(1, 20.0);
        t.controller_status = ControllerStatus::Fault as u32;
        let d = gate.decide(Some(&t), &arm(Q, qd));
        assert!(d.events.safe_stop_entered && d.events.controller_fault && !d.missed);
        assert_eq!(d.tau, g());
    }
}
