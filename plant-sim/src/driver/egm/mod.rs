//! The plant as an ABB robot controller speaking Externally Guided Motion (DESIGN section 11),
//! chosen by the scenario's `[egm] enabled = true` instead of the iceoryx2 torque loop.
//!
//! Every EGM cycle (`egm.cycle_s`, a whole number of ticks) the plant sends `EgmRobot` over UDP
//! to the sensor at `egm.sensor_address`: header (sequence number, simulated time in ms), feedback
//! and planned joints in ABB's axis convention and degrees (`egm::axes`), the TCP pose in the base
//! frame (mm, quaternion u0 = scalar), motor, EGM (MCI) and RAPID state, and the wheel's measured
//! force (sensor frame at the TCP, N and N m, as `/wrench`). The sensor answers with `EgmSensor`
//! joint (and optional speed) references, checked by [`session::Rules`] and tracked by the
//! emulated motion controller [`servo::Servo`], whose torques the plant's one tick core
//! ([`PlantTick::advance_servo`]) integrates each 1 ms tick exactly as on the torque path: the
//! same physics, sensor chain, encoders, reflexes and end stops, and the same pacing ([`Pacer`]).
//!
//! Session (as on the robot):
//! - *waiting*: until the first valid sensor message the robot holds its start pose. Real time:
//!   the clock runs and `EgmRobot` goes out every cycle. Lockstep: the plant does not advance and
//!   sends the waiting state again every 100 ms (a sensor started late sees it).
//! - *running*: real time: the plant takes whatever replies arrived by each tick (the latest
//!   valid one wins). Lockstep: after each `EgmRobot` the plant waits for one reply, so a run is
//!   bit-identical run to run. No valid message for `egm.comm_timeout_s` (wall clock) ends the
//!   session.
//! - *stopped*: after a comm timeout or a reflex the robot holds where its servo reference is, a
//!   last `EgmRobot` says `MCI_STOPPED`, and no more are sent; the run goes on to its end, and the
//!   summary counts a safe stop (`rig run` exits 4). The run's end also sends a last
//!   `MCI_STOPPED` message.
//!
//! Refused sensor messages (sequence, limits, malformed) change nothing; each streak is one
//! `/events` entry (`egm_refused`) and the summary counts each (`refusals`). The per-tick path
//! allocates nothing (the messages and their buffers are reused) and logs only those events.

pub mod servo;
pub mod session;

use std::fmt::Write as _;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::Duration;

use egm::pb;
use messages::PlantStatus;
use robot::{Robot, Vec6};
use scenarios::{Mode, Scenario};

use crate::driver::pacer::Pacer;
use crate::recording::{EgmRecord, EventKind, EventRecord, Recorder, TimingRecord};
use crate::signals::Signals;
use crate::stack_text::StackText;
use crate::stats::LoopStats;
use crate::tick::PlantTick;
use crate::tick_events::{EventHandOn, PlantEvent};
use rig_process::clock;
use servo::{Servo, ServoParams};
use session::{Refusal, Rules, SensorBuffer};

/// How often a lockstep plant resends the waiting state until the sensor first answers.
const LOCKSTEP_RESEND: Duration = Duration::from_millis(100);

/// The EGM session's state, as `/egm` records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum SessionState {
    Waiting = 0,
    Running = 1,
    Stopped = 2,
}

/// What the loop needs from `run.rs`.
pub struct EgmParams {
    pub mode: Mode,
    pub period_ns: u64,
    pub n_ticks: u64,
    pub cycle_ticks: u64,
    pub comm_timeout_ns: u64,
    pub sensor: SocketAddr,
}

impl EgmParams {
    pub fn from_scenario(s: &Scenario, mode: Mode, n_ticks: u64) -> anyhow::Result<EgmParams> {
        let e = &s.egm;
        let sensor: SocketAddr =
            e.sensor_address.parse().map_err(|err| anyhow::anyhow!("egm.sensor_address {:?}: {err}", e.sensor_address))?;
        Ok(EgmParams {
            mode,
            period_ns: (s.loop_.period_s * 1e9).round() as u64,
            n_ticks,
            cycle_ticks: (e.cycle_s / s.loop_.period_s).round().max(1.0) as u64,
            comm_timeout_ns: (e.comm_timeout_s * 1e9).round() as u64,
            sensor,
        })
    }
}

/// The EGM robot controller and its plant.
pub struct EgmLoop<'a> {
    /// The plant's tick core, driven by the servo's torques.
    pub plant: &'a mut PlantTick,
    pub recorder: Option<&'a mut Recorder>,
    pub params: EgmParams,
    pub servo: Servo,
    sock: UdpSocket,
    /// Stop requests (SIGINT/SIGTERM).
    signals: Signals,
    rules: Rules,
    sensor_buf: SensorBuffer,
    robot_msg: pb::EgmRobot,
    out: Vec<u8>,
    state: SessionState,
    robot_seqno: u32,
    /// Wall clock of the run's start (the `EgmRobot` feedback time is it plus simulated time).
    start_wall_ns: u64,
}

fn joints(n: usize) -> Option<pb::EgmJoints> {
    Some(pb::EgmJoints { joints: Vec::with_capacity(n) })
}

fn pose() -> Option<pb::EgmPose> {
    Some(pb::EgmPose { pos: Some(pb::EgmCartesian::default()), orient: Some(pb::EgmQuaternion::default()), euler: None })
}

/// Fill an `EgmPose` with a base-frame pose: position in mm, orientation as a quaternion.
fn fill_pose(p: &mut Option<pb::EgmPose>, iso: &nalgebra::Isometry3<f64>) {
    if let Some(p) = p.as_mut() {
        let t = iso.translation.vector * 1e3;
        p.pos = Some(pb::EgmCartesian { x: t.x, y: t.y, z: t.z });
        let q = iso.rotation;
        p.orient = Some(pb::EgmQuaternion { u0: q.w, u1: q.i, u2: q.j, u3: q.k });
    }
}

fn fill_joints(j: &mut Option<pb::EgmJoints>, values: &[f64; 6]) {
    if let Some(j) = j.as_mut() {
        j.joints.clear();
        j.joints.extend_from_slice(values);
    }
}

impl<'a> EgmLoop<'a> {
    /// Bind the robot's UDP socket (an ephemeral port; the sensor answers to it) and set up the
    /// servo at the plant's start pose.
    pub fn new(
        s: &Scenario,
        plant: &'a mut PlantTick,
        recorder: Option<&'a mut Recorder>,
        params: EgmParams,
        signals: Signals,
    ) -> anyhow::Result<EgmLoop<'a>> {
        let bind: SocketAddr = if params.sensor.is_ipv4() { "0.0.0.0:0".parse()? } else { "[::]:0".parse()? };
        let sock = UdpSocket::bind(bind).map_err(|e| anyhow::anyhow!("binding the EGM robot's UDP socket: {e}"))?;
        sock.set_nonblocking(true)?;
        let q0 = plant.physics().q();
        let servo = Servo::new(ServoParams::from_scenario(s), scenarios::geometry::nominal_robot(s), q0);
        let robot_msg = pb::EgmRobot {
            header: Some(pb::EgmHeader::default()),
            feed_back: Some(pb::EgmFeedBack {
                joints: joints(6),
                cartesian: pose(),
                external_joints: None,
                time: Some(pb::EgmClock::default()),
            }),
            planned: Some(pb::EgmPlanned { joints: joints(6), cartesian: pose(), external_joints: None, time: None }),
            motor_state: Some(pb::EgmMotorState { state: pb::egm_motor_state::MotorStateType::MotorsOn as i32 }),
            mci_state: Some(pb::EgmMciState::default()),
            mci_convergence_met: Some(false),
            rapid_exec_state: Some(pb::EgmRapidCtrlExecState {
                state: pb::egm_rapid_ctrl_exec_state::RapidCtrlExecStateType::RapidRunning as i32,
            }),
            measured_force: Some(pb::EgmMeasuredForce { fc_active: Some(true), force: Vec::with_capacity(6) }),
            utilization_rate: None,
        };
        Ok(EgmLoop {
            rules: Rules::new(s.egm.cycle_s, q0),
            plant,
            recorder,
            params,
            servo,
            sock,
            signals,
            sensor_buf: SensorBuffer::default(),
            robot_msg,
            out: Vec::with_capacity(2048),
            state: SessionState::Waiting,
            robot_seqno: 0,
            start_wall_ns: clock::now_wall_ns(),
        })
    }

    /// The UDP port the robot sends from (and the sensor answers to).
    pub fn local_port(&self) -> u16 {
        self.sock.local_addr().map_or(0, |a| a.port())
    }

    fn event(&mut self, tick: u64, kind: EventKind, text: &str) {
        let t = tick as f64 * self.params.period_ns as f64 * 1e-9;
        if let Some(r) = self.recorder.as_deref_mut() {
            r.record_event(&EventRecord::new(tick, t, kind, text));
        }
    }

    /// Encode and send this tick's `EgmRobot`: the state as the plant reports it (the encoders'
    /// joints, the force/torque sensor's wrench when the scenario models them).
    fn send_robot(&mut self, tick: u64) {
        let (state, wrench) = self.plant.outputs();
        let q = Vec6::from(state.q);
        let q_r = self.servo.servo_reference();
        let robot = self.plant.physics().robot();
        let sim_ns = tick * self.params.period_ns;
        let wall_ns = self.start_wall_ns + sim_ns;
        let fb_pose = robot.tcp_pose(&q);
        let planned_pose = robot.tcp_pose(&q_r);
        let (force, torque) = (wrench.force, wrench.torque);
        let q_deg = egm::axes::abb_deg_from_dh(&q.into());
        let r_deg = egm::axes::abb_deg_from_dh(&q_r.into());
        let m = &mut self.robot_msg;
        self.robot_seqno = self.robot_seqno.wrapping_add(1);
        m.header = Some(pb::EgmHeader {
            seqno: Some(self.robot_seqno),
            tm: Some((sim_ns / 1_000_000) as u32),
            mtype: Some(pb::egm_header::MessageType::MsgtypeData as i32),
        });
        if let Some(fb) = m.feed_back.as_mut() {
            fill_joints(&mut fb.joints, &q_deg);
            fill_pose(&mut fb.cartesian, &fb_pose);
            fb.time = Some(pb::EgmClock { sec: wall_ns / 1_000_000_000, usec: (wall_ns % 1_000_000_000) / 1000 });
        }
        if let Some(p) = m.planned.as_mut() {
            fill_joints(&mut p.joints, &r_deg);
            fill_pose(&mut p.cartesian, &planned_pose);
        }
        let mci = match self.state {
            SessionState::Stopped => pb::egm_mci_state::MciStateType::MciStopped,
            _ => pb::egm_mci_state::MciStateType::MciRunning,
        };
        m.mci_state = Some(pb::EgmMciState { state: mci as i32 });
        // Converged: every axis within 0.1 degree of the reference taken.
        let r_in = egm::axes::abb_deg_from_dh(&self.servo.reference().into());
        m.mci_convergence_met = Some((0..6).all(|i| (r_in[i] - q_deg[i]).abs() < 0.1));
        if let Some(f) = m.measured_force.as_mut() {
            f.force.clear();
            f.force.extend_from_slice(&force);
            f.force.extend_from_slice(&torque);
        }
        self.out.clear();
        if prost::Message::encode(&*m, &mut self.out).is_ok() {
            // A full socket buffer or an unreachable sensor loses this datagram, as UDP would.
            let _ = self.sock.send_to(&self.out, self.params.sensor);
        }
    }

    /// Wait up to `timeout` for a datagram (in slices that end on a stop signal).
    fn wait_readable(&self, timeout: Duration) -> bool {
        let end = std::time::Instant::now() + timeout;
        loop {
            let now = std::time::Instant::now();
            if now >= end || self.signals.stop_requested() {
                return false;
            }
            let slice = (end - now).min(Duration::from_millis(1));
            let mut pfd = libc::pollfd { fd: self.sock.as_raw_fd(), events: libc::POLLIN, revents: 0 };
            // SAFETY: one valid pollfd for the duration of the call.
            let n = unsafe { libc::poll(&mut pfd, 1, slice.as_millis().max(1) as libc::c_int) };
            if n > 0 {
                return true;
            }
        }
    }

    /// Take one datagram, if there is one: accepted, refused, or nothing waiting.
    fn take_one(&mut self, buf: &mut [u8; 2048]) -> Option<Result<session::Accepted, Refusal>> {
        let n = match self.sock.recv_from(buf) {
            Ok((n, _from)) => n,
            Err(_) => return None,
        };
        Some(self.sensor_buf.decode(&buf[..n]).and_then(|m| self.rules.check(m)))
    }
}

/// Counters of one run beyond [`LoopStats`].
#[derive(Debug, Default, Clone, Copy)]
pub struct EgmStats {
    pub accepted: u64,
    pub refused: u64,
    pub cycles: u64,
    pub session_ended_tick: Option<u64>,
}

/// What one run of the EGM loop carries from tick to tick besides the session.
struct Run {
    stats: LoopStats,
    es: EgmStats,
    hand_on: EventHandOn,
    pacer: Pacer,
    buf: [u8; 2048],
    origin_ns: u64,
    /// Monotonic time of the last valid sensor message (0: the comm timeout has passed).
    last_valid_ns: u64,
    /// The last sensor message was refused (a streak is one event).
    refusing: bool,
    /// Monotonic time and tick of the first valid sensor message.
    first_answer: Option<(u64, u64)>,
    /// Monotonic time the last `EgmRobot` went out.
    last_sent_ns: u64,
    /// The `/egm` row of the current cycle.
    cycle: EgmRecord,
}

/// The replies one tick took.
#[derive(Default)]
struct Replies {
    taken: u32,
    accepted: u32,
    /// The tick took a reply (valid or not): its latency is measured.
    answered: bool,
}

impl EgmLoop<'_> {
    /// Run until `n_ticks` ticks are integrated or a stop signal arrives.
    pub fn run(&mut self) -> (LoopStats, EgmStats) {
        let p = EgmParams { sensor: self.params.sensor, ..self.params };
        let origin_ns = clock::now_mono_ns();
        let mut run = Run {
            stats: LoopStats::empty(),
            es: EgmStats::default(),
            hand_on: EventHandOn::new(p.period_ns),
            pacer: Pacer::new(origin_ns, p.period_ns),
            buf: [0u8; 2048],
            origin_ns,
            last_valid_ns: origin_ns,
            refusing: false,
            first_answer: None,
            last_sent_ns: origin_ns,
            cycle: EgmRecord { servo_lag_s: self.servo.params().lag_s(), ..EgmRecord::default() },
        };
        let mut tick: u64 = self.plant.tick();
        while tick < p.n_ticks {
            if self.signals.stop_requested() {
                run.stats.stopped_by_signal = true;
                break;
            }
            if p.mode == Mode::Realtime {
                run.pacer.pace(tick, &mut run.stats, self.recorder.as_deref_mut());
            }
            let wake_ns = clock::now_mono_ns();
            let publish_wall_ns = clock::now_wall_ns();
            let cycle_tick = tick.is_multiple_of(p.cycle_ticks);
            // 1. The EGM exchange of this cycle.
            if !self.exchange(&p, tick, cycle_tick, &mut run) {
                run.stats.stopped_by_signal = true;
                break;
            }
            // Lockstep has no deadline: wait for the writer rather than drop this tick's records.
            if p.mode == Mode::Lockstep {
                crate::tick_events::make_room_for_tick(self.recorder.as_deref_mut());
            }
            // 2. Take the replies: lockstep one per cycle, real time all that arrived.
            let replies = self.take_replies(&p, tick, wake_ns, cycle_tick, &mut run);
            // Reply latency: from this cycle's EgmRobot to the reply taken (real time: at the tick
            // the reply was found, so to within a tick).
            let latency_ns = if replies.answered { clock::now_mono_ns() - run.last_sent_ns } else { 0 };
            if replies.answered {
                run.stats.round_trip.record(latency_ns);
            }
            self.record_cycle(&p, tick, cycle_tick, &replies, latency_ns, &mut run);
            // 3. Session timeout: no valid sensor message for comm_timeout (wall clock).
            if self.state == SessionState::Running && clock::now_mono_ns().saturating_sub(run.last_valid_ns) > p.comm_timeout_ns {
                let mut s = StackText::new();
                let _ = write!(
                    s,
                    "tick {tick}: EGM session ended: no valid sensor message for {} s (egm.comm_timeout_s); the robot holds",
                    p.comm_timeout_ns as f64 * 1e-9
                );
                self.end_session(tick, s.as_str(), &mut run.stats, &mut run.es);
            }
            // 4.-6. The servo's tick through the plant's core, its events, its record.
            let timing = TimingRecord {
                publish_wall_ns,
                torque_receive_wall_ns: if replies.answered { clock::now_wall_ns() } else { 0 },
                round_trip_ns: latency_ns,
                period_ns: p.period_ns,
                missed: false,
                plant_compute_ns: 0,
                controller_compute_ns: 0,
                // The stage stamps are the torque path's (`rig timing`); EGM cycles are in /egm.
                stages: None,
            };
            self.servo_tick(wake_ns, timing, &mut run);
            tick += 1;
            run.pacer.next();
        }
        self.finish(&p, tick, run)
    }

    /// Step 1 of a tick: on a cycle tick, send `EgmRobot`; in lockstep wait for the sensor's
    /// reply (waiting: resend every [`LOCKSTEP_RESEND`]; running: up to the comm timeout).
    /// False: a stop signal came.
    fn exchange(&mut self, p: &EgmParams, tick: u64, cycle_tick: bool, run: &mut Run) -> bool {
        if !cycle_tick || self.state == SessionState::Stopped {
            return true;
        }
        run.es.cycles += 1;
        self.send_robot(tick);
        run.last_sent_ns = clock::now_mono_ns();
        if p.mode == Mode::Lockstep {
            if self.state == SessionState::Waiting {
                while !self.signals.stop_requested() && !self.wait_readable(LOCKSTEP_RESEND) {
                    if self.signals.stop_requested() {
                        break;
                    }
                    self.robot_seqno = self.robot_seqno.wrapping_sub(1);
                    self.send_robot(tick);
                }
            } else if !self.wait_readable(Duration::from_nanos(p.comm_timeout_ns)) && !self.signals.stop_requested() {
                // Nothing in comm_timeout: the session ends in step 3.
                run.last_valid_ns = 0;
            }
            if self.signals.stop_requested() {
                return false;
            }
        }
        true
    }

    /// Step 2: take the sensor's replies (lockstep: the one of this cycle; real time: all that
    /// arrived), check each, set the servo's reference from the valid ones.
    fn take_replies(&mut self, p: &EgmParams, tick: u64, wake_ns: u64, cycle_tick: bool, run: &mut Run) -> Replies {
        let take = if p.mode == Mode::Lockstep { usize::from(cycle_tick && self.state != SessionState::Stopped) } else { usize::MAX };
        let mut r = Replies::default();
        while (r.taken as usize) < take && self.state != SessionState::Stopped {
            let Some(result) = self.take_one(&mut run.buf) else { break };
            r.taken += 1;
            r.answered = true;
            match result {
                Ok(a) => {
                    run.es.accepted += 1;
                    r.accepted += 1;
                    run.cycle.sensor_seqno = a.seqno;
                    run.cycle.joints_ref_deg = a.joints_deg;
                    run.cycle.speed_ref_deg_s = a.speed_deg_s;
                    run.refusing = false;
                    run.last_valid_ns = clock::now_mono_ns();
                    self.servo.set_reference(a.q_ref, a.qd_ref);
                    if self.state == SessionState::Waiting {
                        self.state = SessionState::Running;
                        run.first_answer = Some((wake_ns, tick));
                        let mut s = StackText::new();
                        let _ = write!(s, "tick {tick}: EGM session started: the sensor at {} answered (seqno {})", p.sensor, a.seqno);
                        tracing::info!("{}", s.as_str());
                        self.event(tick, EventKind::EgmSession, s.as_str());
                    }
                }
                Err(refusal) => {
                    run.es.refused += 1;
                    run.stats.first_refusal_tick.get_or_insert(tick);
                    if !run.refusing {
                        let mut s = StackText::new();
                        let _ = write!(s, "tick {tick}: EGM sensor message refused: {refusal}");
                        tracing::warn!("{}", s.as_str());
                        self.event(tick, EventKind::EgmRefused, s.as_str());
                    }
                    run.refusing = true;
                }
            }
        }
        r
    }

    /// `/egm`: one row per cycle, written at its end (lockstep: the reply came at its start).
    fn record_cycle(&mut self, p: &EgmParams, tick: u64, cycle_tick: bool, replies: &Replies, latency_ns: u64, run: &mut Run) {
        let cycle = &mut run.cycle;
        if cycle_tick {
            cycle.tick = tick;
            cycle.sim_time_s = tick as f64 * p.period_ns as f64 * 1e-9;
            cycle.robot_seqno = self.robot_seqno;
            (cycle.replies, cycle.accepted, cycle.reply_latency_ns) = (0, 0, 0);
        }
        cycle.replies += replies.taken;
        cycle.accepted += replies.accepted;
        if replies.answered {
            cycle.reply_latency_ns = latency_ns;
        }
        let cycle_end = if p.mode == Mode::Lockstep { cycle_tick } else { (tick + 1).is_multiple_of(p.cycle_ticks) };
        if cycle_end && (self.state != SessionState::Stopped || cycle.replies > 0) {
            cycle.session_state = self.state as u8;
            cycle.servo_ref_rad = self.servo.servo_reference().into();
            if let Some(r) = self.recorder.as_deref_mut() {
                r.record_egm(cycle);
            }
        }
    }

    /// Steps 4-6: the servo's torque over this tick, from the joints the state reports,
    /// integrated by the plant's tick core; the tick's events (a reflex ends the session: the
    /// robot's motion supervision stops it); the tick's record.
    fn servo_tick(&mut self, wake_ns: u64, mut timing: TimingRecord, run: &mut Run) {
        let (mut state, wrench) = self.plant.outputs();
        state.plant_status = match self.state {
            SessionState::Waiting => PlantStatus::WaitingForController,
            SessionState::Running => PlantStatus::Running,
            SessionState::Stopped => PlantStatus::SafeStop,
        } as u32;
        let tau = self.servo.tick(&Vec6::from(state.q), &Vec6::from(state.qd));
        let tau = Vec6::from_fn(|i, _| tau[i].clamp(-Robot::TORQUE_LIMIT_NM[i], Robot::TORQUE_LIMIT_NM[i]));
        let pre_ns = clock::now_mono_ns() - wake_ns;
        let t0 = clock::now_mono_ns();
        let outcome = self.plant.advance_servo(&tau);
        for r in outcome.events.iter() {
            match r.event {
                PlantEvent::Reflex(x) if self.state != SessionState::Stopped => {
                    run.stats.reflexes += 1;
                    run.stats.first_reflex_tick.get_or_insert(r.tick);
                    let mut s = StackText::new();
                    let _ = write!(s, "tick {}: {x}: EGM session ended, the robot holds", r.tick);
                    tracing::error!("{}", s.as_str());
                    self.event(r.tick, EventKind::Reflex, s.as_str());
                    self.end_session(r.tick, "", &mut run.stats, &mut run.es);
                }
                _ => run.hand_on.one(r, self.recorder.as_deref_mut()),
            }
        }
        let plant_ns = pre_ns + (clock::now_mono_ns() - t0);
        run.stats.plant_compute.record(plant_ns);
        timing.plant_compute_ns = plant_ns;
        if let Some(r) = self.recorder.as_deref_mut() {
            r.record_tick(&crate::tick::tick_record(state, wrench, &outcome, None, timing));
        }
    }

    /// The run's end: it ends the session too (a last `EgmRobot` says `MCI_STOPPED`, so a sensor
    /// can end at once); the totals and the stop event.
    fn finish(&mut self, p: &EgmParams, tick: u64, run: Run) -> (LoopStats, EgmStats) {
        let Run { mut stats, es, origin_ns, first_answer, .. } = run;
        if self.state != SessionState::Stopped {
            self.state = SessionState::Stopped;
            self.send_robot(tick);
        }
        stats.ticks = tick;
        stats.refusals = es.refused;
        stats.wall_s = (clock::now_mono_ns() - origin_ns) as f64 * 1e-9;
        stats.sim_s = self.plant.physics().time_s();
        if let Some((t0, k0)) = first_answer {
            stats.active_wall_s = (clock::now_mono_ns() - t0) as f64 * 1e-9;
            stats.active_sim_s = (tick - k0) as f64 * p.period_ns as f64 * 1e-9;
        }
        let mut s = StackText::new();
        let _ = write!(
            s,
            "plant stopped after {tick} ticks ({}); EGM: {} references accepted, {} refused",
            if stats.stopped_by_signal { "signal" } else { "duration reached" },
            es.accepted,
            es.refused
        );
        self.event(tick, EventKind::Stop, s.as_str());
        (stats, es)
    }

    /// End the session: hold, tell the sensor once (`MCI_STOPPED`), record why.
    fn end_session(&mut self, tick: u64, why: &str, stats: &mut LoopStats, es: &mut EgmStats) {
        if self.state == SessionState::Stopped {
            return;
        }
        self.state = SessionState::Stopped;
        self.servo.hold();
        stats.safe_stops += 1;
        stats.first_safe_stop_tick.get_or_insert(tick);
        es.session_ended_tick = Some(tick);
        if !why.is_empty() {
            tracing::error!("{why}");
            self.event(tick, EventKind::EgmSession, why);
        }
        self.send_robot(tick);
    }
}
