//! `hold-controller --rig NAME --scenario FILE [--contract-version N] [--offset-nm X] [--free-joint1]
//! [--waypoints DQ;DQ;... [--move-s S] [--dwell-s S]]
//! [--answer-after-us MIN:MAX [--seed N]] [--sleep-before-open-s S] [--open-rig OTHER] [--iceoryx2-defaults]
//! [--startup-timeout-s S]`
//!
//! `--free-joint1` and `--waypoints` serve the realistic cell's checks (issue 23): joint 1 left to
//! the offset torque alone (a joint under a known torque against its friction), and the hold
//! moved smoothly through other poses (the tool's load on the sensor in other orientations).
//!
//! `--answer-after-us` answers late, as a slow controller would (the take-over test, issue 22).
//! The last three make it a controller that never connects, as a user's port gone wrong would
//! (rig's connect timeout, issue 27): it sleeps before opening anything, opens another rig's
//! name, or creates its node with iceoryx2's default configuration instead of the rig's.
//!
//! A second, deliberately simple controller binary: joint-space computed torque
//! `τ = M(q)(Kp e − Kd q̇) + C(q, q̇) q̇ + g(q)` (via RNEA) holding the joint position of the first
//! state it sees; every joint then behaves as a critically damped 10 Hz unit mass. It exists to show (and test) that any
//! program speaking the contract can drive the plant, and that a *different* controller binary can
//! take over a running plant. It links only `messages` and `robot` (for g(q)), not the plant loop.

use std::time::{Duration, Instant};

use clap::Parser;
use messages::{ControllerDiagnostics, ControllerStatus, JointTorque, PlantStatus, CONTRACT_VERSION};
use rig_process::ports::{ControllerPorts, Wake};
use robot::Vec6;

#[derive(Debug, Parser)]
struct Args {
    #[arg(long)]
    rig: String,
    #[arg(long)]
    scenario: std::path::PathBuf,
    /// Pretend to speak another contract version (testing the plant's refusal): the torques carry
    /// this version, and the plant's states are NOT checked against it, so the plant gets to refuse.
    #[arg(long, default_value_t = CONTRACT_VERSION)]
    contract_version: u32,
    /// How long the plant may be silent before it is taken for dead, ms (long lockstep runs on
    /// a loaded host stall for more than the default).
    #[arg(long, default_value_t = 100)]
    silence_ms: u64,
    /// How long to wait for the plant's first state, s, before exiting with an error (a guard
    /// against a controller left waiting for ever when a test's plant never starts; long enough
    /// for a strip model built from an empty cache).
    #[arg(long, default_value_t = 600.0)]
    startup_timeout_s: f64,
    /// Constant torque added to joint 1, N m (to make this controller's output recognisable).
    #[arg(long, default_value_t = 0.0)]
    offset_nm: f64,
    /// Joint 1 is not held: its command is `--offset-nm` alone (the other joints are held).
    #[arg(long)]
    free_joint1: bool,
    /// Poses to visit after the first, as joint offsets from the first state's q, rad: six
    /// comma-separated values per pose, poses separated by `;`. The hold stays at the first q for
    /// `--dwell-s`, then moves to each pose in turn over `--move-s` (a cycloidal blend, fed forward)
    /// and stays there `--dwell-s`.
    #[arg(long)]
    waypoints: Option<String>,
    #[arg(long, default_value_t = 2.0)]
    move_s: f64,
    #[arg(long, default_value_t = 1.0)]
    dwell_s: f64,
    /// From this tick on, send NaN on joint 1 (testing the plant's refusal).
    #[arg(long)]
    nan_from_tick: Option<u64>,
    /// Answer each state only MIN..MAX µs (uniform, seeded by `--seed`) after it was received, as a
    /// slow controller (e.g. one in Python) would: testing that the plant waits its budget.
    #[arg(long, value_parser = parse_range_us)]
    answer_after_us: Option<(u64, u64)>,
    /// Seed of the `--answer-after-us` delays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Sleep this long before opening the rig (a slow start), s.
    #[arg(long, default_value_t = 0.0)]
    sleep_before_open_s: f64,
    /// Open this rig name instead of --rig's.
    #[arg(long)]
    open_rig: Option<String>,
    /// Create the node with iceoryx2's default configuration, not the rig's, and wait for states
    /// that never come there.
    #[arg(long)]
    iceoryx2_defaults: bool,
}

/// A peer that skips the rig's iceoryx2 configuration: its node and the state service live in
/// iceoryx2's default namespace, where no plant publishes; it waits there for good.
fn defaults_only(rig: &str) -> anyhow::Result<()> {
    use iceoryx2::prelude::*;
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let name: ServiceName = format!("rig/{rig}/joint_state").as_str().try_into()?;
    let service = node.service_builder(&name).publish_subscribe::<messages::JointState>().open_or_create()?;
    let sub = service.subscriber_builder().create()?;
    loop {
        if sub.receive()?.is_some() {
            anyhow::bail!("a joint state arrived in iceoryx2's default namespace");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `MIN:MAX` in µs, MIN <= MAX.
fn parse_range_us(s: &str) -> Result<(u64, u64), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("{s:?} is not MIN:MAX (µs)"))?;
    let lo: u64 = a.trim().parse().map_err(|e| format!("{a:?}: {e}"))?;
    let hi: u64 = b.trim().parse().map_err(|e| format!("{b:?}: {e}"))?;
    if lo > hi {
        return Err(format!("MIN {lo} is above MAX {hi}"));
    }
    Ok((lo, hi))
}

/// `a,b,c,d,e,f;a,b,...`: six offsets (rad) per pose.
fn parse_waypoints(s: &str) -> Result<Vec<Vec6>, String> {
    s.split(';')
        .map(|pose| {
            let v: Vec<f64> =
                pose.split(',').map(|x| x.trim().parse::<f64>().map_err(|e| format!("{x:?}: {e}"))).collect::<Result<_, _>>()?;
            if v.len() != 6 {
                return Err(format!("{pose:?}: six joint offsets per pose"));
            }
            Ok(Vec6::from_column_slice(&v))
        })
        .collect()
}

/// The hold's reference offset from the first q, its velocity and acceleration at `t_s` after the
/// first state: dwell, then per waypoint a cycloidal blend over `move_s` and a dwell.
fn reference(waypoints: &[Vec6], move_s: f64, dwell_s: f64, t_s: f64) -> (Vec6, Vec6, Vec6) {
    let mut from = Vec6::zeros();
    let mut t = t_s - dwell_s;
    for to in waypoints {
        if t < 0.0 {
            break;
        }
        if t < move_s {
            // cycloidal: s = τ − sin(2πτ)/(2π), τ = t/move_s; acceleration continuous, zero at both ends
            let w = std::f64::consts::TAU / move_s;
            let d = to - from;
            let (sin, cos) = (w * t).sin_cos();
            return (from + d * (t / move_s - sin / std::f64::consts::TAU), d * ((1.0 - cos) / move_s), d * (w * sin / move_s));
        }
        from = *to;
        t -= move_s + dwell_s;
    }
    (from, Vec6::zeros(), Vec6::zeros())
}

/// A uniform draw in `lo..=hi` from a xorshift64* state (never zero).
fn draw(state: &mut u64, (lo, hi): (u64, u64)) -> u64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    let x = state.wrapping_mul(0x2545_F491_4F6C_DD1D);
    lo + x % (hi - lo + 1)
}

/// Sleep until `t` (CLOCK_MONOTONIC, which `Instant` is on Linux) with an absolute
/// `clock_nanosleep`; the timer slack is lowered at start so a 200 µs delay is not 250.
fn sleep_until(t: Instant) {
    let now = Instant::now();
    if t <= now {
        return;
    }
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid out pointer.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    let target = (ts.tv_sec as u128) * 1_000_000_000 + ts.tv_nsec as u128 + (t - now).as_nanos();
    let ts = libc::timespec { tv_sec: (target / 1_000_000_000) as libc::time_t, tv_nsec: (target % 1_000_000_000) as libc::c_long };
    // SAFETY: a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
    while unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) } == libc::EINTR {}
}

/// Closed-loop natural frequency (rad/s) and damping ratio of every joint: ω T = 0.06 at 1 kHz.
const OMEGA: f64 = 2.0 * std::f64::consts::PI * 10.0;
const ZETA: f64 = 1.0;

fn main() {
    let a = Args::parse();
    match run(&a) {
        Ok(()) => {}
        Err(e) => {
            eprintln!("hold-controller: error: {e:#}");
            std::process::exit(1);
        }
    }
}

fn run(a: &Args) -> anyhow::Result<()> {
    let s = scenarios::Scenario::load(&a.scenario)?;
    let robot = scenarios::geometry::nominal_robot(&s);
    std::thread::sleep(Duration::from_secs_f64(a.sleep_before_open_s));
    if a.iceoryx2_defaults {
        return defaults_only(&a.rig);
    }
    rig_process::ports::clean_dead_nodes();
    let ports = ControllerPorts::open(a.open_rig.as_deref().unwrap_or(&a.rig), "hold-controller")?;
    // (a test that needs this controller subscribed before the plant starts waits for this line)
    eprintln!("hold-controller: ports open");
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    let id = ((std::process::id() as u64) << 32) | nanos as u64;
    let mut hold: Option<(Vec6, u64)> = None;
    let mut last_state = Instant::now();
    let mut rng = a.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    if a.answer_after_us.is_some() {
        // SAFETY: prctl with an integer argument changes only this thread's timer slack.
        unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
    }
    let waypoints = a.waypoints.as_deref().map(parse_waypoints).transpose().map_err(anyhow::Error::msg)?;
    let mut answered = false;
    loop {
        // Wake on the plant's notification; a timeout only serves the dead-plant check.
        let _: Wake = ports.wait_state(Instant::now() + Duration::from_millis(20));
        let Some(st) = ports.receive_state() else {
            if hold.is_some() && last_state.elapsed() > Duration::from_millis(a.silence_ms) {
                anyhow::bail!("plant on rig {:?} is silent for {} ms: assuming it is dead", a.rig, a.silence_ms);
            }
            if hold.is_none() && last_state.elapsed().as_secs_f64() > a.startup_timeout_s {
                anyhow::bail!("no joint state on rig {:?} within {} s of opening the ports: no plant came", a.rig, a.startup_timeout_s);
            }
            continue;
        };
        let t0 = Instant::now();
        last_state = t0;
        if a.contract_version == CONTRACT_VERSION && st.contract_version != CONTRACT_VERSION {
            anyhow::bail!("{}", messages::check_version(CONTRACT_VERSION, st.contract_version, "joint state").unwrap_err());
        }
        if st.plant_status == PlantStatus::ShuttingDown as u32 {
            return Ok(());
        }
        let q = Vec6::from(st.q);
        let qd = Vec6::from(st.qd);
        let (q0, tick0) = *hold.get_or_insert((q, st.tick));
        let t_s = (st.tick - tick0) as f64 * s.loop_.period_s;
        let (dq, qd_ref, qdd_ref) =
            waypoints.as_deref().map_or((Vec6::zeros(), Vec6::zeros(), Vec6::zeros()), |w| reference(w, a.move_s, a.dwell_s, t_s));
        let mut qdd = qdd_ref + (q0 + dq - q) * (OMEGA * OMEGA) + (qd_ref - qd) * (2.0 * ZETA * OMEGA);
        if a.free_joint1 {
            qdd[0] = 0.0;
        }
        let mut tau = robot.rnea(&q, &qd, &qdd);
        if a.free_joint1 {
            tau[0] = 0.0;
        }
        tau[0] += a.offset_nm;
        if a.nan_from_tick.is_some_and(|k| st.tick >= k) {
            tau[0] = f64::NAN;
        }
        let t = JointTorque {
            contract_version: a.contract_version,
            controller_status: ControllerStatus::Active as u32,
            tick: st.tick,
            controller_id: id,
            tau: tau.into(),
        };
        let d = ControllerDiagnostics {
            tick: st.tick,
            compute_time_ns: t0.elapsed().as_nanos() as u64,
            ..ControllerDiagnostics::zeroed(a.contract_version)
        };
        if let Some(range) = a.answer_after_us {
            sleep_until(t0 + Duration::from_micros(draw(&mut rng, range)));
        }
        ports.publish(&t, Some(&d))?;
        if !answered {
            // Once, for the tests: which tick this controller answered first.
            answered = true;
            eprintln!("hold-controller: first answer: tick {}", st.tick);
        }
    }
}
