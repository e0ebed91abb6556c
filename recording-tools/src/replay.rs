//! Replay: act as the plant of a fresh rig and republish a recording's joint states and wrenches,
//! at the recorded rate (or X times faster), or in lockstep with a controller driven open-loop
//! from the recording; then compare that controller's torques with the recorded ones.
//!
//! What is compared: the recorded `/joint_torque` is the torque the plant APPLIED. It equals the
//! recorded controller's answer except on held ticks (late/missing/refused answers) and while the
//! plant blends a (re)connected controller in (`loop.takeover_blend_s` of the scenario); those
//! ticks are counted and left out. Everything else must match a deterministic controller exactly
//! in lockstep.

use crate::read::{open_for, Recording};
use anyhow::{bail, Context};
use messages::{PlantStatus, DOF};
use rig_process::child::{self, SpawnOptions};
use rig_process::ports::{PlantPorts, Wake};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// `rig replay FILE [--speed X] [--controller PATH]`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// The recording (.mcap).
    pub file: PathBuf,
    /// Republish at X times the recorded rate. Default: lockstep (wait for each torque, as fast as
    /// the controller answers) when --controller is given, else the recorded rate (1).
    #[arg(long)]
    pub speed: Option<f64>,
    /// Controller executable to drive open-loop from the recording and compare with the recorded
    /// torques (it is started as `PATH --rig NAME --scenario FILE`; `--controller` alone or
    /// `--controller auto` takes the `controller` next to this executable). Without it, replay only republishes; a controller
    /// you start yourself on the printed rig name is compared too.
    #[arg(long, num_args = 0..=1, default_missing_value = "auto")]
    pub controller: Option<PathBuf>,
    /// Scenario file for the controller (default: the scenario stored in the recording).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Rig name to publish on (default: a fresh `replay-<pid>`).
    #[arg(long)]
    pub rig: Option<String>,
    /// Longest wait for one torque in lockstep, s.
    #[arg(long, default_value_t = 2.0)]
    pub watchdog: f64,
    /// Also write the comparison as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Replay a cut (killed run) or corrupt file up to its first bad chunk instead of refusing it.
    #[arg(long, visible_alias = "allow-damaged")]
    pub allow_truncated: bool,
}

/// How the replayed controller's torques differ from the recorded ones.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TorqueComparison {
    pub ticks_compared: usize,
    /// Recorded torque was held from an earlier tick (no fresh recorded answer to compare).
    pub ticks_held: usize,
    /// The recording's plant was blending a (re)connected controller in.
    pub ticks_blending: usize,
    /// The replayed controller gave no torque for the tick in time.
    pub ticks_unanswered: usize,
    /// Per joint max |tau_replay - tau_recorded|, N m.
    pub max_abs_nm: [f64; DOF],
    /// Per joint RMS of tau_replay - tau_recorded, N m.
    pub rms_nm: [f64; DOF],
    /// Every compared tick bit-identical.
    pub identical: bool,
    pub first_difference_tick: Option<u64>,
}

/// Compares `answers[i]` (the replayed controller's torque for tick row i) with the recording.
/// `blend_ticks`: fresh ticks the plant blends over after a (re)connection.
///
/// Where the plant recorded the controller's own answer (`tau_commanded`) that is the reference on
/// every tick. Otherwise the applied torque is, on the ticks where it equals the answer: not held,
/// and not within the blend-in after the gate left WaitingForController / SafeStop or saw a new
/// controller id (the status the gate decided from is the one published for that tick).
pub fn compare_torques(rec: &Recording, answers: &[Option<[f64; DOF]>], blend_ticks: u32) -> TorqueComparison {
    let mut c = TorqueComparison {
        ticks_compared: 0,
        ticks_held: 0,
        ticks_blending: 0,
        ticks_unanswered: 0,
        max_abs_nm: [0.0; DOF],
        rms_nm: [0.0; DOF],
        identical: true,
        first_difference_tick: None,
    };
    let waiting = PlantStatus::WaitingForController as u32;
    let safe = PlantStatus::SafeStop as u32;
    let mut last_id = None;
    let mut blend_left = 0;
    let mut sq = [0.0; DOF];
    for (i, row) in rec.joint_torque.iter().enumerate() {
        let answer = answers.get(i).copied().flatten();
        if row.held {
            match row.commanded {
                Some(cmd) => accumulate(&mut c, &mut sq, row.tick, answer, &cmd),
                None => c.ticks_held += 1,
            }
            continue;
        }
        let status = rec.joint_state.get(i).map_or(0, |s| s.plant_status);
        if status == waiting || status == safe || last_id != Some(row.torque.controller_id) {
            blend_left = blend_ticks;
        }
        last_id = Some(row.torque.controller_id);
        let blending = blend_left > 0;
        blend_left = blend_left.saturating_sub(1);
        match row.commanded {
            Some(cmd) => accumulate(&mut c, &mut sq, row.tick, answer, &cmd),
            None if blending => c.ticks_blending += 1,
            None => accumulate(&mut c, &mut sq, row.tick, answer, &row.torque.tau),
        }
    }
    if c.ticks_compared > 0 {
        for (rms, s) in c.rms_nm.iter_mut().zip(sq) {
            *rms = (s / c.ticks_compared as f64).sqrt();
        }
    } else {
        c.identical = false;
    }
    c
}

fn accumulate(c: &mut TorqueComparison, sq: &mut [f64; DOF], tick: u64, answer: Option<[f64; DOF]>, recorded: &[f64; DOF]) {
    let Some(tau) = answer else {
        c.ticks_unanswered += 1;
        return;
    };
    c.ticks_compared += 1;
    for (j, (a, b)) in tau.iter().zip(recorded).enumerate() {
        if a.to_bits() != b.to_bits() {
            c.identical = false;
            c.first_difference_tick.get_or_insert(tick);
        }
        c.max_abs_nm[j] = c.max_abs_nm[j].max((a - b).abs());
        sq[j] += (a - b) * (a - b);
    }
}

/// What a replay did.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayOutcome {
    pub file: String,
    pub rig: String,
    pub lockstep: bool,
    pub speed: f64,
    pub ticks_published: usize,
    pub wall_s: f64,
    /// Present when any controller answered.
    pub comparison: Option<TorqueComparison>,
}

/// The spawned controller, killed if replay ends early ([`rig_process::child::Guard`]).
struct ChildGuard {
    proc: child::Guard,
}

impl ChildGuard {
    fn check_alive(&mut self) -> anyhow::Result<()> {
        if let Some(c) = self.proc.0.as_mut() {
            if let Some(status) = c.try_wait()? {
                self.proc.0 = None;
                bail!("the controller {} during the replay; see its log above", child::ended(status));
            }
        }
        Ok(())
    }

    /// Waits up to `grace` for a clean exit, then stops it (SIGTERM, then SIGKILL).
    fn finish(&mut self, grace: Duration) {
        if let Some(mut c) = self.proc.0.take() {
            if let Ok(Some(_)) = child::wait_deadline(&mut c, grace) {
                return;
            }
            tracing::warn!("the controller did not exit after the replay's shutdown state; stopping it");
            child::stop(&mut c, child::GRACE);
        }
    }
}

/// The `controller` executable next to the running one (`target/release/controller` beside `rig`).
pub fn default_controller() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("locating the running executable")?;
    let dir = exe.parent().context("the running executable has no folder")?;
    for cand in [dir.join("controller"), dir.parent().map_or(dir.join("controller"), |p| p.join("controller"))] {
        if cand.is_file() {
            return Ok(cand);
        }
    }
    bail!("no `controller` executable next to {}; pass --controller PATH", exe.display())
}

/// Scenario file for the controller: the given one, or the recording's `scenario_toml` metadata
/// written to a temporary file.
fn scenario_file(rec: &Recording, given: Option<&Path>, tmp_dir: &Path) -> anyhow::Result<PathBuf> {
    if let Some(p) = given {
        return Ok(p.to_path_buf());
    }
    let run = rec.run_metadata().with_context(|| format!("{}: pass --scenario FILE", rec.path.display()))?;
    let text = run
        .scenario
        .map(|s| s.toml)
        .with_context(|| format!("{} stores no scenario (metadata rig/scenario_toml); pass --scenario FILE", rec.path.display()))?;
    std::fs::create_dir_all(tmp_dir).with_context(|| format!("creating {}", tmp_dir.display()))?;
    let p = tmp_dir.join("scenario.toml");
    std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
    Ok(p)
}

fn blend_ticks(scenario: &Path, period_s: f64) -> anyhow::Result<u32> {
    let s = scenarios::Scenario::load(scenario).with_context(|| format!("reading the scenario {}", scenario.display()))?;
    let period = if period_s > 0.0 { period_s } else { s.loop_.period_s };
    Ok((s.loop_.takeover_blend_s / period).round() as u32)
}

pub fn run(args: &ReplayArgs) -> anyhow::Result<ReplayOutcome> {
    let rec = open_for(&args.file, args.allow_truncated)?;
    if rec.joint_state.is_empty() {
        bail!("{} holds no ticks to replay", args.file.display());
    }
    if let Some(v) = rec.rig_metadata("contract_version") {
        if v != messages::CONTRACT_VERSION.to_string() {
            bail!(
                "{} was recorded with contract version {v}; this replay speaks version {}",
                args.file.display(),
                messages::CONTRACT_VERSION
            );
        }
    }
    let n = rec.joint_state.len().min(rec.wrench.len());
    let lockstep = args.speed.is_none() && args.controller.is_some();
    let speed = args.speed.unwrap_or(1.0);
    if !(speed > 0.0 && speed.is_finite()) {
        bail!("--speed must be a positive number, got {speed}");
    }
    let rig = args.rig.clone().unwrap_or_else(|| format!("replay-{}", std::process::id()));
    messages::services::validate_rig_name(&rig)?;
    let tmp_dir = std::env::temp_dir().join(format!("rig-replay-{}", std::process::id()));

    // The replay is the rig's plant: not on a rig whose plant runs (nor may one start meanwhile).
    let _claim = rig_process::host::claim_plant(&rig, rig_process::host::prepare()?)?;
    let ports = PlantPorts::open(&rig, "replay").with_context(|| format!("opening the services of rig {rig:?}"))?;
    let mut blend = 0;
    let mut guard = ChildGuard { proc: child::Guard(None) };
    if let Some(path) = &args.controller {
        let exe = if path.as_os_str() == "auto" { default_controller()? } else { path.clone() };
        let scen = scenario_file(&rec, args.scenario.as_deref(), &tmp_dir)?;
        blend = blend_ticks(&scen, rec.period_s())?;
        let mut cmd = Command::new(&exe);
        cmd.arg("--rig").arg(&rig).arg("--scenario").arg(&scen);
        // The controller ends with the replay, even a replay killed by SIGKILL (spawned from the
        // main thread, which PDEATHSIG follows).
        child::configure(&mut cmd, SpawnOptions { own_process_group: false, die_with_parent: true });
        let c = cmd.spawn().with_context(|| format!("starting the controller {}", exe.display()))?;
        guard.proc.0 = Some(c);
        tracing::info!(rig = %rig, controller = %exe.display(), "replay: controller started");
    } else if let Some(s) = args.scenario.as_deref() {
        blend = blend_ticks(s, rec.period_s())?;
    } else if let Some(src) = rec.run_metadata().ok().and_then(|m| m.scenario) {
        if let Ok(s) = scenarios::Scenario::from_toml_str(&src.toml, Path::new("<recording>")) {
            blend = (s.loop_.takeover_blend_s / rec.period_s().max(1e-9)).round() as u32;
        }
    }
    println!(
        "replay      {} -> rig {rig}, {n} ticks, {}",
        args.file.display(),
        if lockstep { "lockstep".to_string() } else { format!("{speed} x recorded rate") }
    );

    let mut answers: Vec<Option<[f64; DOF]>> = vec![None; n];
    let t_first = rec.joint_state[0].sim_time_s;
    let mut started = Instant::now();
    let watchdog = Duration::from_secs_f64(args.watchdog.max(0.001));
    for i in 0..n {
        let mut state = rec.joint_state[i];
        state.contract_version = messages::CONTRACT_VERSION;
        let mut wrench = rec.wrench[i];
        wrench.contract_version = messages::CONTRACT_VERSION;
        let tick = state.tick;
        if i == 0 && guard.proc.0.is_some() {
            // The started controller joins late and gets no history: republish the first tick
            // every 5 ms until it answers (as the plant does), then start the clock.
            answers[0] = Some(handshake(&ports, &state, &wrench, &mut guard, &rig)?);
            started = Instant::now();
            continue;
        }
        if lockstep {
            ports.publish(&state, &wrench)?;
            let give_up = Instant::now() + watchdog;
            loop {
                ports.wait_torque(give_up);
                if let Some(t) = ports.receive_torque_for(tick) {
                    answers[i] = Some(t.tau);
                    break;
                }
                guard.check_alive()?;
                if Instant::now() >= give_up {
                    tracing::warn!(tick, "no torque within the watchdog; continuing");
                    break;
                }
            }
        } else {
            let due = started + Duration::from_secs_f64(((state.sim_time_s - t_first) / speed).max(0.0));
            if let Some(d) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
            ports.publish(&state, &wrench)?;
            // Collect this tick's answer until the next tick is due.
            let next = started + Duration::from_secs_f64(((state.sim_time_s + state.period_s - t_first) / speed).max(0.0));
            while Instant::now() < next {
                ports.wait_torque(next);
                if let Some(t) = ports.receive_torque_for(tick) {
                    answers[i] = Some(t.tau);
                    break;
                }
            }
            if i % 256 == 0 {
                guard.check_alive()?;
            }
        }
    }
    let wall_s = started.elapsed().as_secs_f64();
    // Goodbye: a shutting-down state tells the controller to exit.
    let mut last = rec.joint_state[n - 1];
    last.contract_version = messages::CONTRACT_VERSION;
    last.tick += 1;
    last.sim_time_s += last.period_s;
    last.plant_status = PlantStatus::ShuttingDown as u32;
    let mut w = rec.wrench[n - 1];
    w.contract_version = messages::CONTRACT_VERSION;
    w.tick = last.tick;
    let _ = ports.publish(&last, &w);
    guard.finish(Duration::from_secs(2));
    let _ = std::fs::remove_dir_all(&tmp_dir);

    let comparison = answers.iter().any(Option::is_some).then(|| compare_torques(&rec, &answers, blend));
    let outcome = ReplayOutcome {
        file: args.file.display().to_string(),
        rig,
        lockstep,
        speed: if lockstep { 0.0 } else { speed },
        ticks_published: n,
        wall_s,
        comparison,
    };
    print!("{}", format_outcome(&outcome));
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(&outcome)? + "\n").with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(outcome)
}

/// Publishes the first state every 5 ms until the controller answers it (15 s at most).
fn handshake(
    ports: &PlantPorts,
    state: &messages::JointState,
    wrench: &messages::Wrench,
    guard: &mut ChildGuard,
    rig: &str,
) -> anyhow::Result<[f64; DOF]> {
    let give_up = Instant::now() + Duration::from_secs(15);
    loop {
        ports.publish(state, wrench)?;
        let step = Instant::now() + Duration::from_millis(5);
        while ports.wait_torque(step) == Wake::Notified {
            if let Some(t) = ports.receive_torque_for(state.tick) {
                return Ok(t.tau);
            }
        }
        if let Some(t) = ports.receive_torque_for(state.tick) {
            return Ok(t.tau);
        }
        guard.check_alive()?;
        if Instant::now() >= give_up {
            bail!("the controller answered no state on rig {rig} within 15 s");
        }
    }
}

pub fn format_outcome(o: &ReplayOutcome) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "published   {} ticks in {:.2} s", o.ticks_published, o.wall_s);
    match &o.comparison {
        None => {
            let _ = writeln!(s, "compared    no controller answered on rig {}", o.rig);
        }
        Some(c) => {
            let _ = writeln!(
                s,
                "compared    {} ticks ({} blending in, {} held in the recording, {} unanswered)",
                c.ticks_compared, c.ticks_blending, c.ticks_held, c.ticks_unanswered
            );
            let f = |v: &[f64; DOF]| v.iter().map(|x| format!("{x:.3e}")).collect::<Vec<_>>().join(" ");
            let _ = writeln!(s, "torque diff max |d tau| per joint [N m]: {}", f(&c.max_abs_nm));
            let _ = writeln!(s, "            RMS d tau per joint [N m]:   {}", f(&c.rms_nm));
            let _ = match c.first_difference_tick {
                None if c.identical => writeln!(s, "identical   yes: every compared torque is bit-identical to the recording"),
                None => writeln!(s, "identical   no (nothing compared)"),
                Some(t) => writeln!(s, "identical   no: first difference at tick {t}"),
            };
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use recordings::schema::TorqueRow;

    fn recording(held: &[bool], ids: &[u64], status: &[u32]) -> Recording {
        let mut rec = Recording::default();
        for k in 0..held.len() {
            let mut r = recordings::TickRecord::default();
            r.state.tick = k as u64;
            r.state.plant_status = status[k];
            rec.joint_state.push(r.state);
            let mut t = r.torque;
            t.tick = k as u64;
            t.controller_id = ids[k];
            t.tau = [k as f64; DOF];
            rec.joint_torque.push(TorqueRow { tick: k as u64, torque: t, held: held[k], commanded: None });
        }
        rec
    }

    #[test]
    fn blend_windows_and_held_ticks_are_left_out() {
        let (w, r, s) = (PlantStatus::WaitingForController as u32, PlantStatus::Running as u32, PlantStatus::SafeStop as u32);
        // 0: first answer (blend 2: ticks 0, 1), 2..3 compared, 4 held, 5 new controller (blend 5, 6),
        // 7 compared, 8 after a safe stop (blend 8, 9).
        let held = [false, false, false, false, true, false, false, false, false, false];
        let ids = [1, 1, 1, 1, 1, 2, 2, 2, 2, 2];
        let st = [w, r, r, r, r, r, r, r, s, r];
        let rec = recording(&held, &ids, &st);
        let answers: Vec<_> = (0..10).map(|k| Some([k as f64; DOF])).collect();
        let c = compare_torques(&rec, &answers, 2);
        assert_eq!((c.ticks_compared, c.ticks_held, c.ticks_blending, c.ticks_unanswered), (3, 1, 6, 0));
        assert!(c.identical && c.max_abs_nm == [0.0; DOF]);

        // A difference on a compared tick: max and RMS over the 3 compared ticks.
        let mut answers = answers;
        answers[3] = Some([3.0 + 0.3; DOF]);
        answers[7] = None;
        let c = compare_torques(&rec, &answers, 2);
        assert_eq!((c.ticks_compared, c.ticks_unanswered), (2, 1));
        assert!(!c.identical && c.first_difference_tick == Some(3));
        assert!((c.max_abs_nm[0] - 0.3).abs() < 1e-12);
        assert!((c.rms_nm[5] - (0.3f64 * 0.3 / 2.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_recorded_answer_is_compared_on_every_tick_held_or_blending() {
        let (w, r) = (PlantStatus::WaitingForController as u32, PlantStatus::Running as u32);
        let mut rec = recording(&[false, false, true, false], &[1, 1, 1, 1], &[w, r, r, r]);
        for (k, row) in rec.joint_torque.iter_mut().enumerate() {
            row.commanded = Some([10.0 + k as f64; DOF]); // the answers, unlike the applied tau
        }
        let answers: Vec<_> = (0..4).map(|k| Some([10.0 + k as f64; DOF])).collect();
        let c = compare_torques(&rec, &answers, 2);
        assert_eq!((c.ticks_compared, c.ticks_held, c.ticks_blending), (4, 0, 0));
        assert!(c.identical);
    }
}
