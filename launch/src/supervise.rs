//! Start `plant-sim` and a controller as two processes on one rig, supervise them, stop them
//! cleanly. tokio lives here only (child processes, signals, timeouts), never in the 1 kHz loops.

use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::time::Duration;

use anyhow::Context;
use rig_process::child::{describe_stopped, ended, SpawnOptions};
use tokio::io::AsyncReadExt;
use tokio::process::{Child, Command};
use tokio::signal::unix::{signal, SignalKind};

/// Which controller a run starts (`--controller`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Controller {
    /// This executable, started with `--rig NAME --scenario FILE`.
    Program(PathBuf),
    /// `--controller none` (EGM scenarios): start no controller, the plant waits for an external
    /// EGM client at the scenario's sensor address.
    ExternalEgm,
}

impl Controller {
    /// `--controller`'s value: `none` is the external EGM client, anything else a program.
    pub fn from_flag(s: &str) -> Result<Controller, std::convert::Infallible> {
        Ok(if s == "none" { Controller::ExternalEgm } else { Controller::Program(PathBuf::from(s)) })
    }
}

impl std::fmt::Display for Controller {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Controller::Program(p) => write!(f, "{}", p.display()),
            Controller::ExternalEgm => f.write_str("none (an external EGM client)"),
        }
    }
}

/// What to start.
#[derive(Debug, Clone)]
pub struct RigLaunch {
    pub rig: String,
    pub scenario: PathBuf,
    /// Overrides the scenario's `loop.mode`.
    pub mode: Option<scenarios::Mode>,
    pub duration_s: Option<f64>,
    pub recording: PathBuf,
    pub plant_bin: PathBuf,
    pub controller: Controller,
    pub cache_dir: PathBuf,
    /// Lockstep: start the controller pinned to this CPU, the one `plant-sim` pins its loop to.
    pub controller_cpu: Option<usize>,
    /// Daemons log warnings and errors only (unless RUST_LOG says otherwise): for `rig sweep`.
    pub quiet: bool,
    /// The plant serves its recording live (`--live ADDR --live-rate HZ`).
    pub live: Option<recordings::LiveConfig>,
    /// The plant runs the host-floor probe (`plant-sim --host-probe`): for `rig timing`.
    pub host_probe: bool,
    /// Its period, µs (None: plant-sim's default).
    pub host_probe_period_us: Option<u64>,
    /// The scenario's `loop.connect_timeout_s`: how long the controller process may take to
    /// answer its first state before it is named and the run ends (exit 3).
    pub connect_timeout: Duration,
}

/// How a supervised run ended.
#[derive(Debug)]
pub enum Ending {
    /// The plant reached its duration and both exited 0.
    Completed,
    /// The user pressed Ctrl-C (rig got SIGINT); both were stopped cleanly.
    Interrupted,
    /// rig got SIGTERM; both were stopped cleanly.
    Terminated,
    /// The plant failed (non-zero exit or killed); the controller was stopped.
    PlantFailed(String),
    /// The controller exited while the plant still ran; the plant was told (safe stop), then
    /// stopped cleanly.
    ControllerFailed(String),
    /// The controller process was alive but answered no state within the connect timeout: the
    /// sentence (which program, what was seen, the likely fix) was said at once; both stopped.
    NeverConnected(String),
}

impl Ending {
    /// Process exit code of `rig run` for this ending, before the plant's summary is read
    /// (a completed run is 0 or 4: `Outcome::exit_code`, in `summary` with the incidents it counts).
    pub fn exit_code(&self) -> i32 {
        match self {
            Ending::Completed => 0,
            Ending::PlantFailed(_) => 2,
            Ending::ControllerFailed(_) | Ending::NeverConnected(_) => 3,
            Ending::Interrupted => 130,
            Ending::Terminated => 143,
        }
    }
}

/// Result of a supervised run: the ending, and the plant's summary if it printed one that reads.
#[derive(Debug)]
pub struct Outcome {
    pub ending: Ending,
    pub plant_summary: Option<recordings::PlantSummary>,
}

/// How long the plant gets between rig's report that the controller ended (SIGUSR1) and its
/// SIGTERM: it enters the safe stop and records the event within a tick or two.
const CONTROLLER_END_GRACE: Duration = Duration::from_millis(100);

/// True when process `pid` catches `sig` (`SigCgt` in /proc/PID/status).
fn catches_signal(pid: u32, sig: i32) -> bool {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|m| u64::from_str_radix(m.trim(), 16).ok())
        .is_some_and(|mask| mask & (1u64 << (sig - 1)) != 0)
}

/// Tell the plant that the controller process ended (`sigqueue(SIGUSR1)` with
/// `plant_sim::signals::encode_controller_end` as the value, which `plant_sim::signals` reads from
/// `si_value.sival_ptr`): it enters the safe stop and records "controller process ended (...)".
/// Not before the plant has installed its handler (a SIGUSR1 would kill it): a plant still starting
/// up has no loop to safe-stop. Returns whether the plant was told.
fn report_controller_end(plant: &Child, status: ExitStatus) -> bool {
    use plant_sim::signals::ControllerEnd;
    use std::os::unix::process::ExitStatusExt;
    let end = match (status.code(), status.signal()) {
        (Some(c), _) => ControllerEnd::Exit(c),
        (None, Some(s)) => ControllerEnd::Signal(s),
        _ => ControllerEnd::Unknown,
    };
    send_controller_end(plant, end)
}

/// Queue `end` to the plant (SIGUSR1 with [`plant_sim::signals::encode_controller_end`]'s value), once
/// its handler is installed. Also how rig reports a controller that never connected.
fn send_controller_end(plant: &Child, end: plant_sim::signals::ControllerEnd) -> bool {
    let Some(pid) = plant.id() else { return false };
    if !catches_signal(pid, libc::SIGUSR1) {
        return false;
    }
    let value = libc::sigval { sival_ptr: plant_sim::signals::encode_controller_end(end) as isize as usize as *mut libc::c_void };
    // SAFETY: queueing a signal to our own child, which is not reaped yet (its pid is ours).
    if unsafe { libc::sigqueue(pid as i32, libc::SIGUSR1, value) } != 0 {
        tracing::warn!("could not tell plant-sim that the controller ended: {}", std::io::Error::last_os_error());
        return false;
    }
    true
}

/// Unique rig name for this process: `r<pid>-<nanoseconds>`.
pub fn unique_rig_name() -> String {
    let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    format!("r{}-{}", std::process::id(), n % 1_000_000_000_000)
}

/// A binary next to the running `rig` executable (cargo puts all workspace bins there).
pub fn sibling_binary(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("locating the rig executable")?;
    let dir = exe.parent().context("rig executable has no parent directory")?;
    let p = dir.join(name);
    anyhow::ensure!(
        p.is_file(),
        "{} not found next to {} (build it with `cargo build --release --workspace --bins`)",
        p.display(),
        exe.display()
    );
    Ok(p)
}

/// [`rig_process::child::stop`] awaiting tokio's `wait`: SIGTERM, wait up to `grace`, then SIGKILL.
/// Returns the exit status.
async fn stop(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    if let Ok(Some(s)) = child.try_wait() {
        return Some(s);
    }
    if let Some(pid) = child.id() {
        rig_process::child::signal(pid, libc::SIGTERM);
    }
    match tokio::time::timeout(grace, child.wait()).await {
        Ok(Ok(s)) => Some(s),
        _ => {
            let _ = child.kill().await;
            child.wait().await.ok()
        }
    }
}

/// [`rig_process::child::await_or_stop`] awaiting tokio's `wait`: wait for a child to exit by itself
/// for `grace`, then stop it.
async fn await_or_stop(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    match tokio::time::timeout(grace, child.wait()).await {
        Ok(Ok(s)) => Some(s),
        _ => stop(child, rig_process::child::GRACE).await,
    }
}

fn spawn(cmd: &mut Command, what: &str, bin: &Path) -> anyhow::Result<Child> {
    // Own process group: a terminal Ctrl-C reaches rig only, which then stops the plant first so
    // the controller sees the plant's goodbye instead of dying at the same instant.
    // SIGTERM to the child when rig dies, even by SIGKILL (the plant then finalises its
    // recording). PDEATHSIG follows the spawning thread: rig's runtime is current-thread, so this
    // is the main thread, which lives as long as rig.
    rig_process::child::configure(cmd.as_std_mut(), SpawnOptions { own_process_group: true, die_with_parent: true });
    cmd.kill_on_drop(true);
    cmd.spawn().with_context(|| format!("starting the {what} {}", bin.display()))
}

/// The summary's numbers of the recording ([`recording_tools::cli::summary_numbers`]), read back
/// while the plant tears down ([`supervise_reading_back`]).
pub type ReadBack = anyhow::Result<recording_tools::report::ReportNumbers>;

/// Start both daemons and supervise them until the run ends.
pub async fn supervise(l: &RigLaunch) -> anyhow::Result<Outcome> {
    Ok(supervise_reading_back(l, false).await?.0)
}

/// [`supervise`], and with `read_back` the recording's summary numbers, read as soon as the
/// plant's stdout ends: `plant-sim` closes it right after its summary line, once the recording is
/// finished, and only then lets go of its iceoryx2 ports, its liveness watch and its claim on the
/// rig (10-40 ms on an ext4 state directory, where each file removed frees blocks), so the read
/// overlaps that teardown. None: not asked, or the plant printed no summary naming a recording.
pub async fn supervise_reading_back(l: &RigLaunch, read_back: bool) -> anyhow::Result<(Outcome, Option<ReadBack>)> {
    let mut plant_cmd = Command::new(&l.plant_bin);
    plant_cmd
        .arg("--rig")
        .arg(&l.rig)
        .arg("--scenario")
        .arg(&l.scenario)
        .arg("--out")
        .arg(&l.recording)
        .arg("--cache-dir")
        .arg(&l.cache_dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let quiet = l.quiet && std::env::var_os("RUST_LOG").is_none();
    if quiet {
        plant_cmd.env("RUST_LOG", "warn");
    }
    if let Some(m) = l.mode {
        plant_cmd.arg("--mode").arg(m.name());
    }
    if let Some(d) = l.duration_s {
        plant_cmd.arg("--duration").arg(d.to_string());
    }
    if let Some(live) = &l.live {
        plant_cmd.arg("--live").arg(live.addr.to_string()).arg("--live-rate").arg(live.rate_hz.to_string());
    }
    if l.host_probe {
        plant_cmd.arg("--host-probe");
        if let Some(us) = l.host_probe_period_us {
            plant_cmd.arg("--host-probe-period-us").arg(us.to_string());
        }
    }
    let mut plant = spawn(&mut plant_cmd, "plant", &l.plant_bin)?;
    let mut plant_out = plant.stdout.take().context("plant stdout")?;
    // Lockstep: the recording is read while the plant writes it, so that the summary waits for
    // its last chunk only (`Follower`); its guard abandons the read on any way out of here.
    let (follower, _follow_guard) = match (read_back, l.controller_cpu) {
        (true, Some(cpu)) => {
            let f = Follower::start(&l.recording, &l.rig, cpu);
            let guard = f.as_ref().map(|f| FollowGuard(f.progress.clone()));
            (f, guard)
        }
        _ => (None, None),
    };
    let recording = l.recording.clone();
    let reader = tokio::spawn(async move {
        let mut s = String::new();
        let _ = plant_out.read_to_string(&mut s).await;
        // The summary line is complete and the recording finished: read it back now, beside the
        // plant's teardown (a plant that fails after this still has its summary printed, with
        // these numbers, as before).
        let path = read_back.then(|| last_summary(&s).and_then(Result::ok)?.recording).flatten();
        let early = match (path, follower) {
            (Some(p), Some(f)) if Path::new(&p) == recording => Some(f.finished()),
            (path, follower) => {
                drop(follower.map(|f| FollowGuard(f.progress)));
                path.map(|p| tokio::task::spawn_blocking(move || recording_tools::cli::summary_numbers(Path::new(&p))))
            }
        };
        (s, early)
    });

    let controller_bin = match &l.controller {
        Controller::Program(p) => p,
        Controller::ExternalEgm => return finish(plant_alone(&mut plant).await?, reader, false, false).await,
    };
    // Watch for the controller's first answer from before it starts (its earliest torque counts).
    let controller_pid = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
    let connect_watch = match rig_process::connect::ConnectWatch::spawn(&l.rig, controller_pid.clone(), l.connect_timeout) {
        Ok(w) => Some(w),
        Err(e) => {
            // The daemons report an unusable host themselves (exit 71); rig only loses this check.
            tracing::debug!("no connect watch: {}", rig_process::ports::WithCauses(&e));
            None
        }
    };
    let mut ctrl_cmd = Command::new(controller_bin);
    ctrl_cmd.arg("--rig").arg(&l.rig).arg("--scenario").arg(&l.scenario).stdout(Stdio::inherit()).stderr(Stdio::inherit());
    if quiet {
        ctrl_cmd.env("RUST_LOG", "warn");
    }
    if let Some(cpu) = l.controller_cpu {
        // SAFETY: between fork and exec only sched_setaffinity (async-signal-safe) runs.
        unsafe {
            ctrl_cmd.pre_exec(move || {
                rig_process::rt::pin_thread_to_cpu(cpu);
                Ok(())
            });
        }
    }
    let mut controller = match spawn(&mut ctrl_cmd, "controller", controller_bin) {
        Ok(c) => c,
        Err(e) => {
            let _ = stop(&mut plant, Duration::from_secs(5)).await;
            return Err(e);
        }
    };

    controller_pid.store(controller.id().unwrap_or(0), std::sync::atomic::Ordering::Release);
    let watch_stop = connect_watch.as_ref().map(rig_process::connect::ConnectWatch::stop_flag);
    // Resolves only if the controller never connected (else it stays pending).
    let never_connected = async move {
        match connect_watch {
            Some(w) => match tokio::task::spawn_blocking(move || w.verdict()).await {
                Ok(Some(seen)) => seen,
                _ => std::future::pending().await,
            },
            None => std::future::pending().await,
        }
    };
    tokio::pin!(never_connected);

    let mut sigint = signal(SignalKind::interrupt())?;
    let mut sigterm = signal(SignalKind::terminate())?;
    let mut controller_exited_first = false;
    let mut plant_told = false;
    let ending = tokio::select! {
        biased;
        s = plant.wait() => {
            let s = s?;
            // The plant said goodbye (ShuttingDown) or died; the controller must exit by itself
            // within 100 ms of silence, so 2 s is generous.
            let c = await_or_stop(&mut controller, Duration::from_secs(2)).await;
            if s.success() {
                match c {
                    Some(c) if c.success() => Ending::Completed,
                    Some(c) => Ending::ControllerFailed(format!("controller {} after the plant finished", ended(c))),
                    None => Ending::ControllerFailed("controller could not be reaped".into()),
                }
            } else {
                Ending::PlantFailed(format!("plant-sim {}; controller {}", ended(s), describe_stopped(c)))
            }
        }
        c = controller.wait() => {
            let c = c?;
            // Both gone already (e.g. both refused a full /dev/shm): the plant is named first, it
            // starts first and owns the rig.
            if let Ok(Some(p)) = plant.try_wait() {
                if !p.success() && !c.success() {
                    return finish(Ending::PlantFailed(format!("plant-sim {}; controller {}", ended(p), ended(c))), reader, false, false).await;
                }
            }
            // A controller exits 0 only after the plant's goodbye, when the plant is finishing
            // too; any other exit leaves a running plant without a controller. Either way: tell
            // the plant (safe stop, an /events entry; harmless once its loop is over), give it
            // 100 ms, stop it (it finalises its recording). Whether the plant had reached its end
            // is read from its summary below.
            let told = report_controller_end(&plant, c);
            plant_told = told;
            let p = match tokio::time::timeout(CONTROLLER_END_GRACE, plant.wait()).await {
                Ok(Ok(s)) => Some(s),
                _ => stop(&mut plant, Duration::from_secs(10)).await,
            };
            if c.success() && p.is_some_and(|p| p.success()) {
                controller_exited_first = true;
                Ending::Completed
            } else if c.success() {
                Ending::PlantFailed(format!("plant-sim {} after the controller finished", describe_stopped(p)))
            } else {
                Ending::ControllerFailed(format!(
                    "controller quit early: it {}; plant-sim {}{}",
                    ended(c),
                    if told { "told (SIGUSR1), then " } else { "" },
                    describe_stopped(p)
                ))
            }
        }
        seen = &mut never_connected => {
            let pid = controller.id().unwrap_or(0);
            let sentence = format!(
                "the controller {} (pid {pid}) is running but answered no state within {:.1} s (loop.connect_timeout_s): {}",
                controller_bin.display(),
                l.connect_timeout.as_secs_f64(),
                seen.explain(&l.rig)
            );
            // Said at once; then the plant records it (/events) and both are stopped.
            eprintln!("rig: CONTROLLER NEVER CONNECTED: {sentence}");
            send_controller_end(&plant, plant_sim::signals::ControllerEnd::NeverConnected { pid, seen: seen.code() });
            let _ = tokio::time::timeout(CONTROLLER_END_GRACE, plant.wait()).await;
            let (_, _) = tokio::join!(stop(&mut plant, Duration::from_secs(10)), stop(&mut controller, Duration::from_secs(1)));
            Ending::NeverConnected(sentence)
        }
        _ = sigint.recv() => {
            stop(&mut plant, Duration::from_secs(10)).await;
            await_or_stop(&mut controller, Duration::from_secs(2)).await;
            Ending::Interrupted
        }
        _ = sigterm.recv() => {
            stop(&mut plant, Duration::from_secs(10)).await;
            await_or_stop(&mut controller, Duration::from_secs(2)).await;
            Ending::Terminated
        }
    };
    // However the run ended, the connect watch ends with it (its blocking task would hold up
    // the runtime's shutdown, and rig's exit, for good).
    if let Some(s) = watch_stop {
        s.store(true, std::sync::atomic::Ordering::Release);
    }
    finish(ending, reader, controller_exited_first, plant_told).await
}

/// `--controller none`: only the plant to supervise (an EGM client outside the rig answers it).
async fn plant_alone(plant: &mut Child) -> anyhow::Result<Ending> {
    let mut sigint = signal(SignalKind::interrupt())?;
    let mut sigterm = signal(SignalKind::terminate())?;
    Ok(tokio::select! {
        s = plant.wait() => {
            let s = s?;
            if s.success() { Ending::Completed } else { Ending::PlantFailed(format!("plant-sim {}", ended(s))) }
        }
        _ = sigint.recv() => {
            stop(plant, Duration::from_secs(10)).await;
            Ending::Interrupted
        }
        _ = sigterm.recv() => {
            stop(plant, Duration::from_secs(10)).await;
            Ending::Terminated
        }
    })
}

/// The plant's summary from its stdout (its last line that is a JSON object). One that does not
/// read (a field missing) is a failed plant, named in the ending when the run reached its end
/// (else said on stderr): rig does not guess the missing numbers.
pub fn read_summary(ending: Ending, stdout: &str) -> (Ending, Option<recordings::PlantSummary>) {
    match last_summary(stdout) {
        None => (ending, None),
        Some(Ok(s)) => (ending, Some(s)),
        Some(Err(e)) => match ending {
            Ending::Completed => (Ending::PlantFailed(e.to_string()), None),
            other => {
                eprintln!("rig: {e}");
                (other, None)
            }
        },
    }
}

/// The plant's summary: its stdout's last line that is a JSON object, read (None: no such line).
fn last_summary(stdout: &str) -> Option<Result<recordings::PlantSummary, recordings::plant_summary::SummaryError>> {
    let line = stdout.lines().rev().find_map(|line| serde_json::from_str::<serde_json::Value>(line).ok().filter(|v| v.is_object()));
    line.map(recordings::PlantSummary::from_value)
}

/// What the task reading the plant's stdout hands back: the text, and the read-back it started.
type Reader = tokio::task::JoinHandle<(String, Option<tokio::task::JoinHandle<ReadBack>>)>;

/// The summary's read of a lockstep recording while the plant writes it, on its own thread off
/// the lockstep CPU (the loop's): `rig run scenarios/sunroof.toml --mode lockstep` spent 0.15 s
/// after its last tick reading 24 MB back before (2026-12-07).
struct Follower {
    progress: std::sync::Arc<std::sync::atomic::AtomicU8>,
    result: tokio::sync::oneshot::Receiver<Option<ReadBack>>,
    /// The following thread, unparked when the file is finished (it would wait out its poll).
    thread: std::thread::Thread,
}

/// [`recording_tools::read::Writing`] as the follower's shared state.
const WRITING: u8 = 0;
const FINISHED: u8 = 1;
const ABANDONED: u8 = 2;

impl Follower {
    /// None if the thread cannot start (the summary then reads the file after the run).
    fn start(recording: &Path, rig: &str, lockstep_cpu: usize) -> Option<Follower> {
        let progress = std::sync::Arc::new(std::sync::atomic::AtomicU8::new(WRITING));
        let (tx, result) = tokio::sync::oneshot::channel();
        let (path, rig, seen) = (recording.to_path_buf(), rig.to_string(), progress.clone());
        let handle = std::thread::Builder::new()
            .name("follow-recording".into())
            .spawn(move || {
                rig_process::rt::keep_thread_off_cpu(lockstep_cpu);
                let progress = || match seen.load(std::sync::atomic::Ordering::Acquire) {
                    WRITING => recording_tools::read::Writing::Running,
                    FINISHED => recording_tools::read::Writing::Finished,
                    _ => recording_tools::read::Writing::Abandoned,
                };
                let _ = tx.send(recording_tools::cli::summary_numbers_following(&path, &rig, &progress));
            })
            .ok()?;
        Some(Follower { progress, result, thread: handle.thread().clone() })
    }

    /// The recording is finished: the numbers once the rest is read.
    fn finished(self) -> tokio::task::JoinHandle<ReadBack> {
        self.progress.store(FINISHED, std::sync::atomic::Ordering::Release);
        self.thread.unpark();
        tokio::spawn(async move {
            match self.result.await {
                Ok(Some(numbers)) => numbers,
                _ => Err(anyhow::anyhow!("the read of the recording as it was written ended without a result")),
            }
        })
    }
}

/// Abandons a follow that is still waiting for the file to be finished (a finished one completes).
struct FollowGuard(std::sync::Arc<std::sync::atomic::AtomicU8>);

impl Drop for FollowGuard {
    fn drop(&mut self) {
        let _ = self.0.compare_exchange(WRITING, ABANDONED, std::sync::atomic::Ordering::AcqRel, std::sync::atomic::Ordering::Acquire);
    }
}

/// The outcome with the plant's summary line, once its stdout is read to the end, and the
/// read-back started then.
async fn finish(
    ending: Ending,
    reader: Reader,
    controller_exited_first: bool,
    plant_told: bool,
) -> anyhow::Result<(Outcome, Option<ReadBack>)> {
    let (out, early) = tokio::time::timeout(Duration::from_secs(5), reader).await.ok().and_then(|r| r.ok()).unwrap_or_default();
    let read_back = match early {
        Some(h) => Some(h.await.unwrap_or_else(|e| Err(anyhow::anyhow!("the read-back task failed: {e}")))),
        None => None,
    };
    let (ending, plant_summary) = read_summary(ending, &out);
    // A plant that exits 0 after a stop signal did not reach its end: rig stopped it because the
    // controller exited first, or somebody else stopped it.
    let stopped_by_signal = plant_summary.as_ref().map(|v| v.stopped_by_signal);
    let ending = match ending {
        Ending::Completed if stopped_by_signal != Some(false) && controller_exited_first => Ending::ControllerFailed(format!(
            "controller exited 0 before the plant reached its end; plant {}stopped",
            if plant_told { "told (SIGUSR1), then " } else { "" }
        )),
        Ending::Completed if stopped_by_signal == Some(true) => {
            Ending::PlantFailed("plant-sim was stopped by a signal (not from rig) before the end of the run".into())
        }
        e => e,
    };
    Ok((Outcome { ending, plant_summary }, read_back))
}
