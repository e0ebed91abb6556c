//! Helpers for the end-to-end tests in `tests/tests/`: locate the built binaries, give every test
//! its own rig name and temporary directory, write small scenarios, and start daemons under a
//! guard that kills them if a test fails.
//!
//! The binaries must be built first: `cargo build --release --workspace --bins`.

use rig_process::child::{self, SpawnOptions};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Directory holding the workspace binaries: the test executable lives in
/// `target/<profile>/deps/`, the binaries one level up.
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let deps = exe.parent().expect("deps dir");
    deps.parent().expect("profile dir").to_path_buf()
}

/// Path of a workspace binary; panics with the build command if it is missing or older than one
/// of its sources (`rig` also checks the daemons it starts), so a test never runs stale code.
pub fn bin(name: &str) -> PathBuf {
    let p = bin_dir().join(name);
    assert!(p.is_file(), "{} is missing: run `cargo build --release --workspace --bins` first", p.display());
    let started = if name == "rig" { &["rig", "plant-sim", "controller"][..] } else { &[name][..] };
    for b in started {
        if let Some(newer) = source_newer_than_binary(b) {
            panic!(
                "{} is older than its source {}: run `cargo build --release --workspace --bins` first",
                bin_dir().join(b).display(),
                newer.display()
            );
        }
    }
    p
}

/// A source file of binary `name` modified after the binary was built, from the dep-info file
/// cargo writes beside it (`target/release/NAME.d`: `NAME: src1 src2 ...`, spaces escaped).
pub fn source_newer_than_binary(name: &str) -> Option<PathBuf> {
    source_newer_than(&bin_dir().join(name), &bin_dir().join(format!("{name}.d")))
}

fn source_newer_than(exe: &Path, dep_info: &Path) -> Option<PathBuf> {
    let built = std::fs::metadata(exe).and_then(|m| m.modified()).ok()?;
    let dep_info = std::fs::read_to_string(dep_info).ok()?;
    let line = dep_info.lines().next()?;
    let sources = line.split_once(": ")?.1.replace("\\ ", "\u{0}");
    sources
        .split_whitespace()
        .map(|s| PathBuf::from(s.replace('\u{0}', " ")))
        .find(|src| std::fs::metadata(src).and_then(|m| m.modified()).is_ok_and(|t| t > built))
}

/// A rig name unique to this test and process.
pub fn unique_rig(tag: &str) -> String {
    let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos();
    format!("e2e-{tag}-{}-{}", std::process::id(), n % 1_000_000_000)
}

/// A fresh temporary directory for one test (left behind for inspection on failure).
pub fn temp_dir(rig: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rig-tests-{rig}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The `[loop]` line a real-time test scenario gets unless its `extra` sets the limit itself: a
/// shared 2-core CI host stalls for 20-50 ms now and then (46 ms seen in a 2 s run), and at the
/// default 20 misses in a row such a stall ends the run in a safe stop (exit 4). Tests about the
/// miss safety set `max_consecutive_misses` themselves; the others test something else.
pub const HOST_STALLS_TOLERATED: &str = "max_consecutive_misses = 1000\n";

/// Write a scenario for loop tests: no strip (no model build), the given mode, plus `extra` TOML
/// lines appended inside the given sections (e.g. "[loop]\nlockstep_watchdog_s = 0.2\n"). In
/// real time the `[loop]` section also gets [`HOST_STALLS_TOLERATED`] unless `extra` names
/// `max_consecutive_misses`.
pub fn write_scenario(dir: &Path, mode: &str, extra: &str) -> PathBuf {
    let tolerance = if mode == "realtime" && !extra.contains("max_consecutive_misses") { HOST_STALLS_TOLERATED } else { "" };
    let text = format!("description = \"e2e loop test\"\n[strip]\nenabled = false\n[loop]\nmode = \"{mode}\"\n{tolerance}{extra}");
    let p = dir.join("scenario.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// A child process that is killed (SIGKILL) and reaped when dropped, unless it already exited.
pub struct Daemon {
    pub name: String,
    pub child: Option<Child>,
    pub stdout_path: PathBuf,
    pub stderr_path: PathBuf,
}

impl Daemon {
    /// Start `bin` with `args`; stdout and stderr go to files in `dir` named after `name`.
    pub fn start(name: &str, bin: &Path, args: &[&str], dir: &Path) -> Daemon {
        let stdout_path = dir.join(format!("{name}.stdout"));
        let stderr_path = dir.join(format!("{name}.stderr"));
        // No PDEATHSIG: it follows the spawning thread, and a test's thread may end before the
        // daemons it hands on; the Drop below ends them.
        let child = child::configure(&mut Command::new(bin), SpawnOptions::default())
            .args(args)
            .stdout(std::fs::File::create(&stdout_path).unwrap())
            .stderr(std::fs::File::create(&stderr_path).unwrap())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {}: {e}", bin.display()));
        Daemon { name: name.into(), child: Some(child), stdout_path, stderr_path }
    }

    pub fn pid(&self) -> i32 {
        self.child.as_ref().map_or(0, |c| c.id() as i32)
    }

    /// Send a signal (e.g. `libc::SIGKILL`).
    pub fn signal(&self, sig: i32) {
        if let Some(c) = &self.child {
            child::signal(c.id(), sig);
        }
    }

    /// Wait up to `timeout` for the process to exit.
    pub fn wait_timeout(&mut self, timeout: Duration) -> Option<ExitStatus> {
        child::wait_deadline(self.child.as_mut()?, timeout).unwrap()
    }

    /// Wait for the exit or panic (after killing it) with the process's stderr.
    pub fn expect_exit(&mut self, timeout: Duration) -> ExitStatus {
        match self.wait_timeout(timeout) {
            Some(s) => s,
            None => {
                self.signal(libc::SIGKILL);
                panic!("{} did not exit within {timeout:?}; stderr:\n{}", self.name, self.stderr());
            }
        }
    }

    pub fn stdout(&self) -> String {
        read(&self.stdout_path)
    }
    pub fn stderr(&self) -> String {
        read(&self.stderr_path)
    }
}

fn read(p: &Path) -> String {
    let mut s = String::new();
    if let Ok(mut f) = std::fs::File::open(p) {
        let _ = f.read_to_string(&mut s);
    }
    s
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            child::kill(&mut c);
        }
    }
}

/// Start `plant-sim` on `rig` with `scenario`, recording to `dir/run.mcap`.
pub fn start_plant(rig: &str, scenario: &Path, dir: &Path, duration_s: f64, extra: &[&str]) -> Daemon {
    let out = dir.join("run.mcap");
    let dur = duration_s.to_string();
    let mut args = vec!["--rig", rig, "--scenario", scenario.to_str().unwrap(), "--duration", &dur, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    Daemon::start("plant", &bin("plant-sim"), &args, dir)
}

/// Start a controller binary (`controller` or `hold-controller`) on `rig`.
pub fn start_controller(name: &str, bin_name: &str, rig: &str, scenario: &Path, dir: &Path, extra: &[&str]) -> Daemon {
    let mut args = vec!["--rig", rig, "--scenario", scenario.to_str().unwrap()];
    args.extend_from_slice(extra);
    Daemon::start(name, &bin(bin_name), &args, dir)
}

/// The plant's one-line JSON summary from its stdout, read as a [`recordings::PlantSummary`]
/// (every field there) and handed back as JSON to index by field name.
pub fn plant_summary(d: &Daemon) -> serde_json::Value {
    let out = d.stdout();
    let line = out
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok().filter(|v| v.is_object()))
        .unwrap_or_else(|| panic!("no JSON summary on the plant's stdout:\n{out}\nstderr:\n{}", d.stderr()));
    let typed = recordings::PlantSummary::from_value(line.clone()).unwrap_or_else(|e| panic!("{e}:\n{line}"));
    assert_eq!(typed.to_value(), line, "the summary line holds what the type holds, no more");
    line
}

/// Wait until `needle` appears in a daemon's log (stderr), e.g. the plant's "connected" line.
pub fn wait_for_log(d: &Daemon, needle: &str, timeout: Duration) {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if d.stderr().contains(needle) {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("{:?} not in {}'s log within {timeout:?}:\n{}", needle, d.name, d.stderr());
}

/// One test's rig: its name, temporary directory and loop scenario (no strip).
pub struct TestRig {
    pub rig: String,
    pub dir: PathBuf,
    pub scenario: PathBuf,
}

impl TestRig {
    pub fn new(tag: &str, mode: &str) -> TestRig {
        let rig = unique_rig(tag);
        let dir = temp_dir(&rig);
        let scenario = write_scenario(&dir, mode, "");
        TestRig { rig, dir, scenario }
    }

    pub fn plant(&self, duration_s: f64) -> Daemon {
        start_plant(&self.rig, &self.scenario, &self.dir, duration_s, &[])
    }

    pub fn controller(&self, name: &str, bin_name: &str, extra: &[&str]) -> Daemon {
        start_controller(name, bin_name, &self.rig, &self.scenario, &self.dir, extra)
    }

    /// Start the plant and the `controller` binary and wait until the plant reports it connected.
    pub fn running(&self, duration_s: f64) -> (Daemon, Daemon) {
        let plant = self.plant(duration_s);
        let ctrl = self.controller("controller", "controller", &[]);
        wait_for_log(&plant, "connected", Duration::from_secs(10));
        (plant, ctrl)
    }

    pub fn recording(&self) -> PathBuf {
        self.dir.join("run.mcap")
    }
}

/// One Python controller test at a time per test binary: each runs a lockstep plant and a Python
/// controller, and two such pairs on the 2-CPU host would slow each other down.
static PYTHON_SERIAL: Mutex<()> = Mutex::new(());

/// True when `python3` imports `modules` (e.g. `"iceoryx2, numpy"`); otherwise the test fails,
/// naming the `pip install` line: the third-party client is what the test is about, and
/// `.ci/deps` (part of README's test command) installs it.
pub fn python_has(test: &str, modules: &str, pip: &str) -> bool {
    let ok = Command::new("python3").args(["-c", &format!("import {modules}")]).output().is_ok_and(|o| o.status.success());
    assert!(ok, "{test}: python3 lacks {modules}: run `bash .ci/deps` (or pip install {pip})");
    ok
}

/// The scenario of a [`python_rig`]: more `[loop]` lines for the loop scenario without a strip
/// (a `&str` converts to this; `""`: none), or a whole scenario's text (e.g. a shipped scenario's
/// with its mode set to lockstep).
pub enum RigScenario<'a> {
    LoopExtra(&'a str),
    Text(&'a str),
}

impl<'a> From<&'a str> for RigScenario<'a> {
    fn from(loop_extra: &'a str) -> Self {
        RigScenario::LoopExtra(loop_extra)
    }
}

/// A lockstep rig running `duration_s` with the Python controller `script` (an executable file
/// with a shebang, started as `script --rig NAME --scenario FILE` like `rig run` starts any
/// controller), holding the Python serial lock; the test fails when python3 lacks `modules`
/// ([`python_has`]). `scenario`: e.g. `"peer_stall_timeout_s = 0.3\n"` ([`RigScenario`]).
pub fn python_rig<'a>(
    test: &str,
    tag: &str,
    duration_s: f64,
    script: &Path,
    modules: &str,
    pip: &str,
    scenario: impl Into<RigScenario<'a>>,
) -> Option<(MutexGuard<'static, ()>, TestRig, Daemon, Daemon)> {
    let g = PYTHON_SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    if !python_has(test, modules, pip) {
        return None;
    }
    let mut t = TestRig::new(tag, "lockstep");
    match scenario.into() {
        RigScenario::LoopExtra("") => {}
        RigScenario::LoopExtra(extra) => t.scenario = write_scenario(&t.dir, "lockstep", extra),
        RigScenario::Text(text) => std::fs::write(&t.scenario, text).unwrap(),
    }
    let plant = t.plant(duration_s);
    let args = ["--rig", t.rig.as_str(), "--scenario", t.scenario.to_str().unwrap()];
    let py = Daemon::start("python-controller", script, &args, &t.dir);
    Some((g, t, plant, py))
}

/// "No torque jump": around a takeover the applied torque changes per tick by at most 2 % of each
/// joint's torque limit, i.e. crossing the whole torque range would take at least 50 ticks. (The
/// restarted controller's first command differs from the safe-stop torque by up to ~1000 N m on
/// joint 2 here, as it pulls the sagged arm back to its start pose; applied at once, that is the
/// jump this rules out.)
pub fn assert_no_jump(rec: &recording_tools::read::Recording, takeover: u64) {
    let rows: Vec<_> = rec.joint_torque.iter().filter(|t| t.tick + 5 >= takeover && t.tick <= takeover + 100).collect();
    assert!(rows.len() > 50, "takeover at tick {takeover} too close to the end");
    for w in rows.windows(2) {
        for j in 0..6 {
            let d = (w[1].torque.tau[j] - w[0].torque.tau[j]).abs();
            assert!(d < 0.02 * robot::Robot::TORQUE_LIMIT_NM[j], "joint {} jumps {d} N m at tick {}", j + 1, w[1].tick);
        }
    }
}

/// The pid of the child of `parent` whose command name (`/proc/PID/comm`) is `comm`, e.g. the
/// `controller` that `rig run` started.
pub fn child_pid(parent: i32, comm: &str) -> Option<i32> {
    let tasks = std::fs::read_dir(format!("/proc/{parent}/task")).ok()?;
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("children")).ok())
        .flat_map(|c| c.split_whitespace().filter_map(|p| p.parse::<i32>().ok()).collect::<Vec<_>>())
        .find(|pid| std::fs::read_to_string(format!("/proc/{pid}/comm")).is_ok_and(|c| c.trim() == comm))
}

/// Wall-clock time now, ns since the Unix epoch (the recordings' `publish_wall_ns` clock).
pub fn wall_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// The first tick the plant published at or after the wall-clock time `ns` (from `/timing`).
pub fn tick_at_wall_ns(rec: &recording_tools::read::Recording, ns: u64) -> Option<u64> {
    rec.timing.iter().find(|t| t.timing.publish_wall_ns >= ns).map(|t| t.tick)
}

/// A 64-bit FNV-1a digest of every tick's physics in a recording: each joint state (tick, time,
/// q, q-dot, applied torque), wrench, applied torque row (answered tick, held, tau) and strip
/// record (wheel z, contact and bottom forces, peak pressure, top displacement, centre-line
/// pressures), as bits.
/// Two recordings with the same digest agree bit for bit on all of them; wall clocks are left
/// out, so a lockstep run's digest is the same on every machine and every day.
pub fn physics_digest(rec: &recording_tools::read::Recording) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut put = |x: u64| {
        for b in x.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for s in &rec.joint_state {
        put(s.tick);
        put(s.sim_time_s.to_bits());
        s.q.iter().chain(&s.qd).chain(&s.tau_applied).for_each(|v| put(v.to_bits()));
    }
    for w in &rec.wrench {
        put(w.tick);
        w.force.iter().chain(&w.torque).for_each(|v| put(v.to_bits()));
    }
    for t in &rec.joint_torque {
        put(t.tick);
        put(t.torque.tick);
        put(u64::from(t.held));
        t.torque.tau.iter().for_each(|v| put(v.to_bits()));
    }
    for s in &rec.strip {
        put(s.tick);
        [s.wheel_z_m, s.contact_force_n, s.bottom_force_n, s.max_bottom_pressure_pa, s.top_displacement_m]
            .iter()
            .for_each(|v| put(v.to_bits()));
        s.centreline_pressure_pa.iter().for_each(|v| put(u64::from(v.to_bits())));
    }
    format!(
        "{h:016x} ({} states, {} wrenches, {} torques, {} strip records)",
        rec.joint_state.len(),
        rec.wrench.len(),
        rec.joint_torque.len(),
        rec.strip.len()
    )
}

/// Each `/strip_scene` of the MCAP file at `path` (the recording `rec` read from it), decoded,
/// with the wheel's z (m) of the strip record logged last before it: what the scene tests walk.
pub fn strip_scenes(path: &Path, rec: &recording_tools::read::Recording) -> Vec<(f64, foxglove::messages::SceneUpdate)> {
    use foxglove::Decode;
    let bytes = std::fs::read(path).unwrap();
    let mut k = 0usize;
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != "/strip_scene" {
            continue;
        }
        while k + 1 < rec.strip.len() && rec.log_time_ns[k] < m.log_time {
            k += 1;
        }
        out.push((rec.strip[k].wheel_z_m, foxglove::messages::SceneUpdate::decode(&m.data[..]).unwrap()));
    }
    out
}

/// An executable script `dir/name` that runs `program` with `args` before the arguments it gets
/// (`rig run --controller` takes a path without arguments: this is how a test gives them).
pub fn exec_wrapper(dir: &Path, name: &str, program: &Path, args: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let args: Vec<String> = args.iter().map(|a| format!("'{a}'")).collect();
    std::fs::write(&path, format!("#!/bin/sh\nexec '{}' {} \"$@\"\n", program.display(), args.join(" "))).unwrap();
    std::fs::set_permissions(&path, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    path
}

/// rig-client's C and C++ examples, built as a user on a fresh machine builds them: the library
/// installed into a new prefix by its one install command (`rig-client/install.sh --prefix P`),
/// then each example configured by the system's cmake from a new, empty build directory against
/// that prefix (`find_package(RigClient)`) and built with the system's cc / g++.
pub struct ClientExamples {
    pub prefix: PathBuf,
    /// examples/c: the minimal C controller.
    pub c_controller: PathBuf,
    /// examples/cpp: the C++ joint-space hold.
    pub cpp_hold: PathBuf,
}

fn run_logged(what: &str, cmd: &mut Command) {
    let o = cmd.output().unwrap_or_else(|e| panic!("{what}: cannot start ({e}); install cmake, g++ and pkg-config: bash .ci/deps"));
    assert!(
        o.status.success(),
        "{what} failed ({}):\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The installed library and the examples built against it (once per test binary).
pub fn client_examples() -> &'static ClientExamples {
    static BUILT: std::sync::OnceLock<ClientExamples> = std::sync::OnceLock::new();
    BUILT.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let dir = temp_dir(&unique_rig("client-examples"));
        let prefix = dir.join("prefix");
        run_logged("rig-client/install.sh", Command::new("bash").arg(root.join("rig-client/install.sh")).arg("--prefix").arg(&prefix));
        let build = |example: &str, target: &str| {
            let b = dir.join(format!("build-{example}"));
            assert!(!b.exists(), "a clean build directory");
            run_logged(
                &format!("cmake configure of examples/{example}"),
                Command::new("cmake")
                    .arg("-S")
                    .arg(root.join("rig-client/examples").join(example))
                    .arg("-B")
                    .arg(&b)
                    .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display()))
                    .arg("-DCMAKE_BUILD_TYPE=Release"),
            );
            run_logged(&format!("cmake build of examples/{example}"), Command::new("cmake").arg("--build").arg(&b));
            b.join(target)
        };
        let c_controller = build("c", "minimal_controller");
        let cpp_hold = build("cpp", "hold_controller");
        ClientExamples { prefix, c_controller, cpp_hold }
    })
}

/// A UDP port free right now (the sensor binds it next).
pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Wait until someone holds UDP `port` on loopback (the EGM sensor, Python client or
/// `egm-controller`, has bound it).
pub fn wait_bound(port: u16, client: &mut Daemon) {
    let end = Instant::now() + Duration::from_secs(30);
    while std::net::UdpSocket::bind(("127.0.0.1", port)).is_ok() {
        assert!(
            Instant::now() < end && client.wait_timeout(Duration::from_millis(0)).is_none(),
            "the EGM client never bound port {port}: {}",
            client.stderr()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `scenarios/egm.toml` with the sensor on `port`, written into `dir`.
pub fn egm_scenario_on(dir: &Path, port: u16) -> PathBuf {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/egm.toml")).unwrap();
    assert!(text.contains("sensor_address = \"127.0.0.1:6510\""));
    let p = dir.join("egm.toml");
    std::fs::write(&p, text.replace("127.0.0.1:6510", &format!("127.0.0.1:{port}"))).unwrap();
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::SystemTime;

    /// A source modified after the binary (a space in its path included) is named; older sources
    /// are not.
    #[test]
    fn a_source_newer_than_its_binary_is_found_from_the_dep_info() {
        let d = temp_dir(&unique_rig("dep-info"));
        let (exe, old_src, new_src) = (d.join("tool"), d.join("old.rs"), d.join("with space.rs"));
        let at = |p: &Path, secs: u64| {
            let f = std::fs::File::create(p).unwrap();
            f.set_modified(SystemTime::UNIX_EPOCH + Duration::from_secs(secs)).unwrap();
        };
        at(&old_src, 1_000);
        at(&exe, 2_000);
        at(&new_src, 1_500);
        let dep = d.join("tool.d");
        let escaped = new_src.display().to_string().replace(' ', "\\ ");
        std::fs::write(&dep, format!("{}: {} {escaped}\n", exe.display(), old_src.display())).unwrap();
        assert_eq!(source_newer_than(&exe, &dep), None);
        at(&new_src, 3_000);
        assert_eq!(source_newer_than(&exe, &dep), Some(new_src));
    }
}
