//! `fault-controller --rig NAME --scenario FILE [FAULTS]`
//!
//! A controller that misbehaves on purpose, for the safety tests (issue 11, DESIGN section 10).
//! The base is `hold-controller`'s joint-space computed-torque hold
//! `τ = M(q)(Kp e − Kd q̇) + C(q, q̇) q̇ + g(q)` (RNEA) of the first state it sees; on top:
//!
//! - `--add-torque J:NM[@TICK]` (repeatable): add NM N m on joint J (1-6) from plant tick TICK
//!   on (default 0), e.g. `6:45@200`, a valid torque that spins the light wrist up.
//! - `--drive-joint J:RAD`: the hold target of joint J moves to RAD (e.g. beyond its range) at
//!   `--drive-speed` rad/s (default 10 % of the axis speed, so the joint stays well below it and
//!   the TCP below the reduced speed), and the PD part of joint J's torque is saturated at
//!   `--drive-torque` N m (default 50 % of its torque limit): how hard it presses into a stop.
//! - `--stranger`: not a controller at all: a rogue publisher that, once it has seen
//!   `--stranger-after` states (default 100), answers every state with g(q) plus
//!   `--stranger-nm` (default 40) N m on joint 1, and no PD.
//! - `--sleep-us X --every N [--sleep-from TICK]`: sleep X µs before answering every Nth tick
//!   (ticks with `tick % N == 0`, from TICK on): a slow controller. Its diagnostics carry the
//!   stage stamps, the sleep counted as compute (`rig timing` attributes those misses to it).
//! - `--rt-priority P`: run SCHED_FIFO at P (default 0: the normal scheduler).
//!
//! It never acknowledges a reflex: it always sends `controller_status` = 0 (active), so a reflex
//! holds to the end of the run. It exits 0 on the plant's `shutting_down`, and with an error when
//! the plant's node is dead or the plant is silent for `loop.peer_stall_timeout_s`.
//! It links only `messages`, `robot` and `scenarios`.

use std::time::{Duration, Instant};

use clap::Parser;
use messages::{ControllerDiagnostics, ControllerStatus, JointTorque, PlantStatus, CONTRACT_VERSION};
use rig_process::liveness::{PeerWatch, Watched};
use rig_process::ports::{ControllerPorts, Wake};
use robot::params::{TORQUE_LIMIT_NM, VELOCITY_LIMIT_RADPS};
use robot::Vec6;

#[derive(Debug, Parser)]
struct Args {
    #[arg(long)]
    rig: String,
    #[arg(long)]
    scenario: std::path::PathBuf,
    /// `J:NM[@TICK]`: add NM N m on joint J (1-6) from tick TICK on (repeatable).
    #[arg(long = "add-torque", value_parser = parse_add_torque)]
    add_torque: Vec<AddTorque>,
    /// `J:RAD`: move joint J's hold target to RAD (rad, DH convention).
    #[arg(long = "drive-joint", value_parser = parse_drive_joint)]
    drive_joint: Option<(usize, f64)>,
    /// Speed of the driven joint's target, rad/s (default: 10 % of its axis speed).
    #[arg(long)]
    drive_speed: Option<f64>,
    /// Saturation of the driven joint's PD torque, N m (default: 50 % of its torque limit).
    #[arg(long)]
    drive_torque: Option<f64>,
    /// Be a rogue publisher instead of a controller.
    #[arg(long)]
    stranger: bool,
    /// The stranger starts publishing after this many states.
    #[arg(long, default_value_t = 100)]
    stranger_after: u64,
    /// The stranger's torque on joint 1 on top of g(q), N m.
    #[arg(long, default_value_t = 40.0)]
    stranger_nm: f64,
    /// Sleep this long before answering (see --every), µs.
    #[arg(long, default_value_t = 0)]
    sleep_us: u64,
    /// Sleep before every Nth tick's answer.
    #[arg(long, default_value_t = 1)]
    every: u64,
    /// Sleep only from this tick on.
    #[arg(long, default_value_t = 0)]
    sleep_from: u64,
    /// Run SCHED_FIFO at this priority (0 = the normal scheduler), as the rig's controller does.
    #[arg(long, default_value_t = 0)]
    rt_priority: i32,
}

#[derive(Debug, Clone, Copy)]
struct AddTorque {
    joint: usize,
    nm: f64,
    from_tick: u64,
}

fn joint_index(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(j) if (1..=6).contains(&j) => Ok(j - 1),
        _ => Err(format!("joint {s:?}: expected 1..6")),
    }
}

fn parse_add_torque(s: &str) -> Result<AddTorque, String> {
    let (j, rest) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected J:NM[@TICK]"))?;
    let (nm, tick) = match rest.split_once('@') {
        Some((nm, t)) => (nm, t.trim().parse::<u64>().map_err(|e| format!("{s:?}: tick: {e}"))?),
        None => (rest, 0),
    };
    let nm = nm.trim().parse::<f64>().map_err(|e| format!("{s:?}: torque: {e}"))?;
    Ok(AddTorque { joint: joint_index(j)?, nm, from_tick: tick })
}

fn parse_drive_joint(s: &str) -> Result<(usize, f64), String> {
    let (j, rad) = s.split_once(':').ok_or_else(|| format!("{s:?}: expected J:RAD"))?;
    let rad = rad.trim().parse::<f64>().map_err(|e| format!("{s:?}: position: {e}"))?;
    Ok((joint_index(j)?, rad))
}

/// Closed-loop natural frequency (rad/s) and damping ratio of every held joint (as hold-controller).
const OMEGA: f64 = 2.0 * std::f64::consts::PI * 10.0;
const ZETA: f64 = 1.0;

fn main() {
    let a = Args::parse();
    match run(&a) {
        Ok(n) => eprintln!("fault-controller: plant shut down; published {n} torques"),
        Err(e) => {
            eprintln!("fault-controller: error: {e:#}");
            std::process::exit(1);
        }
    }
}

/// The driven joint's moving target.
struct Drive {
    joint: usize,
    target: f64,
    speed: f64,
    torque: f64,
    /// Current reference, rad.
    r: Option<f64>,
}

fn run(a: &Args) -> anyhow::Result<u64> {
    let s = scenarios::Scenario::load(&a.scenario)?;
    let robot = scenarios::geometry::nominal_robot(&s);
    let period = s.loop_.period_s;
    let stall = Duration::from_secs_f64(s.loop_.peer_stall_timeout_s);
    rig_process::ports::clean_dead_nodes();
    if a.rt_priority > 0 {
        let param = libc::sched_param { sched_priority: a.rt_priority };
        // SAFETY: a plain syscall on the calling thread with a valid parameter.
        let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        if rc != 0 {
            eprintln!(
                "fault-controller: SCHED_FIFO {} refused ({}): default scheduler",
                a.rt_priority,
                std::io::Error::from_raw_os_error(rc)
            );
        }
    }
    let role = if a.stranger { "stranger" } else { "fault-controller" };
    let ports = ControllerPorts::open(&a.rig, role)?;
    let watch = PeerWatch::spawn(&a.rig, &format!("{role}-watch"), Watched::Plant)?;
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    let id = ((std::process::id() as u64) << 32) | nanos as u64;
    let mut drive = a.drive_joint.map(|(joint, target)| Drive {
        joint,
        target,
        speed: a.drive_speed.unwrap_or(0.1 * VELOCITY_LIMIT_RADPS[joint]).abs(),
        torque: a.drive_torque.unwrap_or(0.5 * TORQUE_LIMIT_NM[joint]).abs(),
        r: None,
    });
    let mut hold: Option<Vec6> = None;
    let mut plant: Option<u128> = None;
    let mut last_state = Instant::now();
    let (mut seen, mut published) = (0u64, 0u64);
    loop {
        // Wake on the plant's notification; a timeout only serves the dead-plant checks.
        let _: Wake = ports.wait_state(Instant::now() + Duration::from_millis(10));
        let Some((st, origin)) = ports.receive_state_with_origin() else {
            if let Some(p) = plant {
                anyhow::ensure!(!watch.is_gone(p), "the plant's node on rig {:?} is dead", a.rig);
                anyhow::ensure!(last_state.elapsed() < stall, "plant on rig {:?} is silent for {stall:?}: assuming it is dead", a.rig);
            }
            continue;
        };
        let t0 = Instant::now();
        let woke_mono_ns = rig_process::clock::now_mono_ns();
        last_state = t0;
        if plant != Some(origin) {
            plant = Some(origin);
            watch.follow(origin);
        }
        if st.contract_version != CONTRACT_VERSION {
            anyhow::bail!("{}", messages::check_version(CONTRACT_VERSION, st.contract_version, "joint state").unwrap_err());
        }
        if st.plant_status == PlantStatus::ShuttingDown as u32 {
            return Ok(published);
        }
        seen += 1;
        if a.sleep_us > 0 && st.tick >= a.sleep_from && st.tick % a.every.max(1) == 0 {
            std::thread::sleep(Duration::from_micros(a.sleep_us));
        }
        let q = Vec6::from(st.q);
        let qd = Vec6::from(st.qd);
        let tau = if a.stranger {
            if seen <= a.stranger_after {
                continue;
            }
            let mut tau = robot.gravity_torque(&q);
            tau[0] += a.stranger_nm;
            tau
        } else {
            let mut q_ref = *hold.get_or_insert(q);
            let mut qd_ref = Vec6::zeros();
            if let Some(d) = drive.as_mut() {
                // The driven joint's reference moves towards its target at the drive speed.
                let r = d.r.get_or_insert(q[d.joint]);
                let step = (d.target - *r).clamp(-d.speed * period, d.speed * period);
                *r += step;
                q_ref[d.joint] = *r;
                qd_ref[d.joint] = if *r == d.target { 0.0 } else { step / period };
            }
            let qdd = (q_ref - q) * (OMEGA * OMEGA) + (qd_ref - qd) * (2.0 * ZETA * OMEGA);
            let mut tau = robot.rnea(&q, &qd, &qdd);
            if let Some(d) = drive.as_ref() {
                // Joint J's PD part (M_JJ times its PD acceleration, RNEA being linear in q̈),
                // saturated at the drive torque.
                let mut qdd0 = qdd;
                qdd0[d.joint] = 0.0;
                let base = robot.rnea(&q, &qd, &qdd0)[d.joint];
                tau[d.joint] = base + (tau[d.joint] - base).clamp(-d.torque, d.torque);
            }
            for add in a.add_torque.iter().filter(|x| st.tick >= x.from_tick) {
                tau[add.joint] += add.nm;
            }
            tau
        };
        let t = JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status: ControllerStatus::Active as u32,
            tick: st.tick,
            controller_id: id,
            tau: tau.into(),
        };
        // Stage stamps: a --sleep-us delay counts as compute (it sits between waking and the answer).
        let computed_mono_ns = rig_process::clock::now_mono_ns();
        let d = ControllerDiagnostics {
            tick: st.tick,
            compute_time_ns: t0.elapsed().as_nanos() as u64,
            woke_mono_ns,
            computed_mono_ns,
            published_mono_ns: rig_process::clock::now_mono_ns(),
            ..ControllerDiagnostics::zeroed(CONTRACT_VERSION)
        };
        // A stranger publishes torques only, like a process that knows nothing of the contract's
        // diagnostics.
        ports.publish(&t, (!a.stranger).then_some(&d))?;
        published += 1;
    }
}
