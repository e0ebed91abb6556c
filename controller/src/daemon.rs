//! The controller process loop (DESIGN section 6): wait on the plant's state event (ppoll on the
//! listener's fd; in real time a `loop.controller_spin_us` busy poll around the due time), read
//! the newest state and wrench, compute the law, publish torque + diagnostics, notify. Per tick: no allocation, no logging, no locks.
//!
//! Exits: `Ok` when the plant says `ShuttingDown`; an error (non-zero exit) on a contract version
//! mismatch (the message names both versions), when no state arrives within
//! [`DaemonConfig::startup_timeout`] of starting, when the plant's iceoryx2 node is dead (checked
//! once it has been silent for [`DaemonConfig::dead_plant_timeout`], 100 ms, in lockstep for the
//! scenario's `loop.lockstep_watchdog_s`), or when a live plant stays silent for
//! `loop.peer_stall_timeout_s`: silence alone is not death (a host stall).

use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use messages::{check_version, state_flags, JointState, PlantStatus, Wrench, WrenchFrame};
use nalgebra::Vector3;
use rig_process::ports::{ControllerPorts, Wake};
use robot::Vec6;
use scenarios::Scenario;

use crate::law::ControlLaw;
use crate::step::Controller;

/// How the daemon runs.
#[derive(Clone, Debug)]
pub struct DaemonConfig {
    pub rig: String,
    pub scenario: Scenario,
    /// Contract version this process speaks (normally `messages::CONTRACT_VERSION`; the hidden
    /// `--contract-version` flag lets tests pretend another one).
    pub contract_version: u32,
    /// Longest wait for the first state, s.
    pub startup_timeout: Duration,
    /// Longest silence of the plant after the first state.
    pub dead_plant_timeout: Duration,
    /// SCHED_FIFO priority to request.
    pub rt_priority: i32,
    /// Real time only: busy-poll for the next state from this long before it is due until this
    /// long after (0 = always sleep in `ppoll`). See [`ControllerPorts::wait_state_spinning`].
    pub state_spin: Duration,
}

impl DaemonConfig {
    pub fn new(rig: &str, scenario: Scenario) -> Self {
        let state_spin = Duration::from_secs_f64(scenario_spin_s(&scenario));
        DaemonConfig {
            rig: rig.to_string(),
            scenario,
            contract_version: messages::CONTRACT_VERSION,
            // A first run may build the strip model (seconds; minutes at 0.5 mm) before the first state.
            startup_timeout: Duration::from_secs(120),
            dead_plant_timeout: Duration::from_millis(100),
            rt_priority: 80,
            state_spin,
        }
    }
}

/// Summary of a finished run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DaemonSummary {
    pub ticks_answered: u64,
    pub last_tick: u64,
    pub max_compute_ns: u64,
    pub mean_compute_ns: f64,
}

/// Timer slack 1 ns, SCHED_FIFO (priority > 0) and mlockall when permitted
/// ([`rig_process::rt::setup_thread`], the plant's set-up); each outcome logged once.
fn setup_realtime(priority: i32) {
    let r = rig_process::rt::setup_thread((priority > 0).then_some(priority), true);
    if !r.timer_slack_1ns {
        tracing::warn!("could not lower the timer slack to 1 ns");
    }
    if r.sched_fifo {
        tracing::info!(priority, "SCHED_FIFO enabled");
    } else if priority <= 0 {
        tracing::info!("SCHED_FIFO not requested (--rt-priority 0): default scheduler");
    } else {
        tracing::warn!(
            priority,
            error = %std::io::Error::from_raw_os_error(r.sched_fifo_errno),
            "SCHED_FIFO not permitted (needs CAP_SYS_NICE or an rtprio limit); running with the default scheduler"
        );
    }
    if !r.mlockall {
        tracing::warn!("mlockall not permitted (memlock limit); pages may fault on the first ticks");
    }
}

/// Task-space mass of the controller's model along the task normal at `q`:
/// 1 / (n_yᵀ J M⁻¹ Jᵀ n_y) — the wheel's effective mass the gain rule reports.
pub fn effective_normal_mass(law: &ControlLaw, q: &Vec6) -> f64 {
    let robot = law.robot();
    let j = robot.jacobian_tcp(q);
    let m = robot.mass_matrix(q);
    let n = law.task().vector_to_base(&Vector3::new(0.0, 1.0, 0.0));
    let jn = j.transpose() * Vec6::new(n.x, n.y, n.z, 0.0, 0.0, 0.0);
    match m.cholesky() {
        Some(c) => 1.0 / jn.dot(&c.solve(&jn)),
        None => f64::NAN,
    }
}

fn controller_id(pid: u32) -> u64 {
    let nonce = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    (u64::from(pid) << 32) | u64::from(nonce)
}

/// Run the controller until the plant shuts down (Ok) or a fault (Err, non-zero exit).
pub fn run(cfg: &DaemonConfig) -> anyhow::Result<DaemonSummary> {
    let s = &cfg.scenario;
    // Silence after which the plant is asked about: dead (its node, see rig_process::liveness) ends
    // the run at once; alive but silent (a stalled host, SIGSTOP) is waited for up to
    // `loop.peer_stall_timeout_s`. In lockstep the plant may legitimately be slow (a loaded
    // machine): its own torque watchdog is the first measure there. The watcher sets up its node
    // while this thread opens the ports and builds the controller (before the real-time set-up,
    // so it keeps the normal scheduling policy).
    let t_setup = Instant::now();
    let watch = rig_process::liveness::PeerWatch::start(&cfg.rig, "controller-watch", rig_process::liveness::Watched::Plant)
        .with_context(|| format!("controller for rig {:?}", cfg.rig))?;
    let ports = ControllerPorts::open(&cfg.rig, "controller").with_context(|| format!("controller for rig {:?}", cfg.rig))?;
    let t_ports = t_setup.elapsed();
    let mut controller =
        Controller::from_scenario(s).with_id(controller_id(std::process::id())).with_contract_version(cfg.contract_version);
    let t_model = t_setup.elapsed() - t_ports;
    let watch = watch.ready().with_context(|| format!("controller for rig {:?}", cfg.rig))?;
    let t_watch = t_setup.elapsed() - t_ports - t_model;
    setup_realtime(cfg.rt_priority);
    // The start-up's parts (README, "Lockstep start-up"): the iceoryx2 ports (beside the liveness
    // watch's node), the control law's model, the rest of the watch's wait, the real-time set-up.
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    tracing::info!(
        rig = %cfg.rig,
        contract_version = cfg.contract_version,
        ports_ms = ms(t_ports),
        model_ms = ms(t_model),
        watch_ms = ms(t_watch),
        setup_ms = ms(t_setup.elapsed()),
        "controller waiting for the plant"
    );

    let started = Instant::now();
    let mut last_state_at: Option<Instant> = None;
    let mut last_tick: Option<u64> = None;
    let mut wrench =
        Wrench { contract_version: cfg.contract_version, frame: WrenchFrame::BaseAtTcp as u32, tick: 0, force: [0.0; 3], torque: [0.0; 3] };
    // `wrench` is the plant's only once one came (its tick 0 says nothing before).
    let mut wrench_seen = false;
    let mut summary = DaemonSummary::default();
    let mut compute_sum_ns: u128 = 0;

    let stall_timeout = Duration::from_secs_f64(s.loop_.peer_stall_timeout_s).max(cfg.dead_plant_timeout);
    let lockstep_silence = cfg.dead_plant_timeout.max(Duration::from_secs_f64(s.loop_.lockstep_watchdog_s));
    let mut silence = cfg.dead_plant_timeout;
    let mut next_due: Option<Instant> = None;
    // The plant this controller answers (publisher id of its joint state); another plant's states
    // are not ours. A new plant after ours is gone is a new connection.
    let mut plant: Option<u128> = None;
    let mut stall_logged = false;
    loop {
        let deadline = match last_state_at {
            Some(t) if stall_logged => (t + stall_timeout).min(Instant::now() + rig_process::liveness::WATCH_PERIOD),
            Some(t) => t + silence,
            None => started + cfg.startup_timeout,
        };
        let wake = ports.wait_state_spinning(next_due.map(|due| (due, cfg.state_spin)), deadline);
        let woke = Instant::now();
        let woke_mono_ns = rig_process::clock::now_mono_ns();
        let received = if wake == Wake::Timeout {
            // A notification may have been consumed while we computed: one last look.
            match ports.receive_state_with_origin() {
                Some(x) => x,
                None => match (last_tick, last_state_at) {
                    (Some(t), Some(at)) => {
                        let quiet = woke.duration_since(at);
                        if plant.is_some_and(|p| watch.is_gone(p)) {
                            bail!(
                                "rig {:?}: no joint state for {} ms after tick {t}: the plant died (its iceoryx2 node is dead); exiting",
                                cfg.rig,
                                quiet.as_millis()
                            );
                        }
                        if quiet >= stall_timeout {
                            bail!(
                                "rig {:?}: no joint state for {:.1} s after tick {t}: the plant is alive but stalled; exiting",
                                cfg.rig,
                                quiet.as_secs_f64()
                            );
                        }
                        if !stall_logged {
                            tracing::warn!(
                                "rig {:?}: no joint state for {} ms after tick {t}, but the plant's node is alive: waiting up to {:.1} s (loop.peer_stall_timeout_s)",
                                cfg.rig,
                                quiet.as_millis(),
                                stall_timeout.as_secs_f64()
                            );
                            stall_logged = true;
                        }
                        continue;
                    }
                    _ => bail!(
                        "rig {:?}: no joint state within {:.1} s of starting: is plant-sim running on this rig?",
                        cfg.rig,
                        cfg.startup_timeout.as_secs_f64()
                    ),
                },
            }
        } else {
            match ports.receive_state_with_origin() {
                Some(x) => x,
                None => continue,
            }
        };
        let (state, origin) = received;
        match plant {
            Some(p) if p != origin => {
                if !watch.is_gone(p) {
                    continue; // another plant's state: not ours
                }
                // Ours is gone and a new plant runs: start over as on a first connection.
                tracing::warn!(rig = %cfg.rig, "a new plant replaced the one that died: connecting to it");
                last_tick = None;
                plant = Some(origin);
                watch.follow(origin);
            }
            None => {
                plant = Some(origin);
                watch.follow(origin);
            }
            _ => {}
        }
        if stall_logged {
            tracing::info!(rig = %cfg.rig, tick = state.tick, "the plant speaks again");
            stall_logged = false;
        }
        last_state_at = Some(woke);
        let lockstep = state.flags & state_flags::LOCKSTEP != 0;
        silence = if lockstep { lockstep_silence } else { cfg.dead_plant_timeout };
        // The plant publishes on an absolute 1 ms grid: the next state is due one period after
        // this one arrived. Lockstep has no grid (and both daemons share one CPU: never spin there).
        next_due = (!lockstep && !cfg.state_spin.is_zero()).then(|| woke + Duration::from_secs_f64(state.period_s));
        if handle_state_or_exit(cfg, &state)? {
            summary.mean_compute_ns = if summary.ticks_answered > 0 { compute_sum_ns as f64 / summary.ticks_answered as f64 } else { 0.0 };
            tracing::info!(
                ticks = summary.ticks_answered,
                last_tick = summary.last_tick,
                max_compute_us = summary.max_compute_ns as f64 * 1e-3,
                mean_compute_us = summary.mean_compute_ns * 1e-3,
                "plant shutting down; controller exits"
            );
            return Ok(summary);
        }
        // plant-sim publishes the wrench before the state; another plant (a replay tool, a
        // third-party simulator) may not, and a controller that polled the state's shared memory
        // would then be a few µs ahead of the wrench. Wait (bounded) for the wrench of this very
        // tick instead of answering with the last tick's force.
        let wrench_wait_until = Instant::now() + WRENCH_WAIT;
        loop {
            if let Some(w) = ports.receive_wrench() {
                check_version(cfg.contract_version, w.contract_version, "wrench").map_err(anyhow::Error::from)?;
                wrench = w;
                wrench_seen = true;
            }
            if (wrench_seen && wrench.tick >= state.tick) || Instant::now() >= wrench_wait_until {
                break;
            }
            std::hint::spin_loop();
        }
        if !wrench_seen {
            // No wrench yet: this subscriber connected after the plant sent this tick's, and
            // iceoryx2 hands a late subscriber the history only at the publisher's next send.
            // Answering now would feed a zero wrench to the sensor chain (the cell scenario's
            // tare averaged it, and 1 lockstep run in 4 came out different); the plant sends both
            // again (lockstep republishes tick 0 every 5 ms; real time sends the next tick).
            continue;
        }
        if last_tick.is_some_and(|t| state.tick <= t) {
            continue; // already answered
        }
        if last_tick.is_none() {
            controller.restart();
        }
        let first = controller.is_first();
        let (torque, mut diag) = controller.process(&state, &wrench);
        diag.computed_mono_ns = rig_process::clock::now_mono_ns();
        let compute_ns = woke.elapsed().as_nanos() as u64;
        diag.compute_time_ns = compute_ns;
        diag.woke_mono_ns = woke_mono_ns;
        // The stage stamps (messages README, ControllerDiagnostics): handed over now.
        diag.published_mono_ns = rig_process::clock::now_mono_ns();
        ports.publish(&torque, Some(&diag)).with_context(|| format!("rig {:?}: publish torque of tick {}", cfg.rig, state.tick))?;
        last_tick = Some(state.tick);
        summary.ticks_answered += 1;
        summary.last_tick = state.tick;
        summary.max_compute_ns = summary.max_compute_ns.max(compute_ns);
        compute_sum_ns += u128::from(compute_ns);
        if first {
            let law = controller.law();
            let f = &law.gains().force;
            let m_eff = effective_normal_mass(law, &Vec6::from(state.q));
            tracing::info!(
                tick = state.tick,
                k_s = f.strip_stiffness_n_per_m,
                m_d = f.m_d_kg,
                b_d = f.b_d_nspm,
                k_i = f.k_i_per_s,
                m_eff,
                contact_resonance_hz = (f.strip_stiffness_n_per_m / m_eff).sqrt() / std::f64::consts::TAU,
                predicted_pm_deg = f.predicted_phase_margin_deg,
                "first state answered; force gains from the design rule (controller::gains)"
            );
        }
    }
}

/// Longest wait for the wrench of the tick whose state arrived (it follows the state by a few
/// µs). Beyond it the newest wrench is used.
const WRENCH_WAIT: Duration = Duration::from_micros(50);

/// The scenario's `loop.controller_spin_us`, s.
fn scenario_spin_s(s: &Scenario) -> f64 {
    s.loop_.controller_spin_us * 1e-6
}

/// Version check and shutdown detection of one state: Ok(true) = the plant shuts down.
fn handle_state_or_exit(cfg: &DaemonConfig, st: &JointState) -> anyhow::Result<bool> {
    check_version(cfg.contract_version, st.contract_version, "joint state").map_err(anyhow::Error::from)?;
    Ok(PlantStatus::from_u32(st.plant_status) == Some(PlantStatus::ShuttingDown))
}

pub use crate::step::step;
