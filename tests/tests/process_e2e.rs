//! End-to-end tests of issue 12's process and shared-memory items, with the real `plant-sim`,
//! `controller` and `rig` processes: one plant per rig name, daemons that end with a killed
//! launcher, one sentence for unusable shared memory, and a second user who can neither stop a
//! rig from starting nor open its services. Build first: `cargo build --release --workspace --bins`.
//!
//! The shared-memory and second-user tests need root and `unshare` (a private mount namespace
//! with its own tmpfs on /dev/shm); without them they print `SKIPPED:` and pass.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use harness::*;
use recording_tools::read::Recording;
use recordings::EventKind;
use rig_process::host::{EXIT_RIG_TAKEN, EXIT_SHARED_MEMORY};

static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

const LONG: Duration = Duration::from_secs(60);

/// The sentence a refused plant prints: one line, naming the rig and the running plant's PID.
fn assert_refused(second: &mut Daemon, rig: &str, first_pid: i32) {
    let st = second.expect_exit(Duration::from_secs(20));
    assert_eq!(st.code(), Some(EXIT_RIG_TAKEN), "second plant: {st}\n{}", second.stderr());
    let err = second.stderr();
    let line = err.lines().find(|l| l.contains("error")).unwrap_or_else(|| panic!("no error line:\n{err}"));
    assert!(line.contains(&format!("rig {rig:?} is already running")) && line.contains(&format!("PID {first_pid}")), "{line}");
    assert_eq!(err.matches(rig).count(), 1, "one sentence:\n{err}");
}

/// The undisturbed rig: plant and controller exit 0, the recording is complete with every tick,
/// one controller and no safe stop.
fn assert_undisturbed(t: &TestRig, plant: &mut Daemon, ctrl: &mut Daemon, ticks: usize) {
    assert!(plant.expect_exit(LONG).success(), "first plant: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "first controller: {}", ctrl.stderr());
    let s = plant_summary(plant);
    assert_eq!(s["safe_stops"], 0, "{s}");
    let rec = Recording::open_complete(t.recording()).expect("complete recording of the first rig");
    assert_eq!(rec.joint_state.len(), ticks);
    rec.check_continuity().expect("every tick recorded once");
    assert_eq!(rec.events_of(EventKind::SafeStop).count(), 0, "{:?}", rec.events);
    assert_eq!(rec.events_of(EventKind::ControllerChange).count(), 1, "{:?}", rec.events);
    for d in [&*plant, &*ctrl] {
        assert!(!d.stderr().contains("No config file"), "iceoryx2 ran without the rig's configuration:\n{}", d.stderr());
    }
}

#[test]
fn a_second_plant_with_a_live_rigs_name_refuses_naming_the_rig_and_pid_and_the_rig_runs_on() {
    let _g = serial();
    let t = TestRig::new("same", "realtime");
    let (mut plant, mut ctrl) = t.running(2.0);
    let dir2 = t.dir.join("second");
    std::fs::create_dir_all(&dir2).unwrap();
    let mut second = start_plant(&t.rig, &t.scenario, &dir2, 1.0, &[]);
    assert_refused(&mut second, &t.rig, plant.pid());
    assert!(!dir2.join("run.mcap").exists(), "the refused plant must not record");
    assert_undisturbed(&t, &mut plant, &mut ctrl, 2000);
}

#[test]
fn of_two_plants_started_at_once_on_one_name_exactly_one_runs() {
    let _g = serial();
    let t = TestRig::new("race", "lockstep");
    let dirs: Vec<PathBuf> = ["a", "b"].iter().map(|n| t.dir.join(n)).collect();
    for d in &dirs {
        std::fs::create_dir_all(d).unwrap();
    }
    let mut a = start_plant(&t.rig, &t.scenario, &dirs[0], 0.5, &[]);
    let mut b = start_plant(&t.rig, &t.scenario, &dirs[1], 0.5, &[]);
    let mut ctrl = t.controller("controller", "controller", &[]);
    let (sa, sb) = (a.expect_exit(LONG), b.expect_exit(LONG));
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller: {}", ctrl.stderr());
    let (winner, loser, wd) = match (sa.code(), sb.code()) {
        (Some(0), Some(c)) if c == EXIT_RIG_TAKEN => (&a, &b, &dirs[0]),
        (Some(c), Some(0)) if c == EXIT_RIG_TAKEN => (&b, &a, &dirs[1]),
        _ => panic!("expected one run and one refusal, got {sa} and {sb}:\n{}\n{}", a.stderr(), b.stderr()),
    };
    assert!(loser.stderr().contains(&format!("rig {:?} is already running", t.rig)), "{}", loser.stderr());
    let rec = Recording::open_complete(wd.join("run.mcap")).expect("the winner's recording");
    assert_eq!(rec.joint_state.len(), 500, "{}", winner.stderr());
}

/// Processes whose parent is `pid` (from /proc).
fn children(pid: i32) -> Vec<i32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(p) = e.file_name().to_str().and_then(|s| s.parse::<i32>().ok()) else { continue };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{p}/stat")) else { continue };
        let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else { continue };
        if rest.split_whitespace().nth(1).and_then(|s| s.parse::<i32>().ok()) == Some(pid) {
            out.push(p);
        }
    }
    out
}

/// How `rig`'s output reaches this test in [`kill_launcher`].
#[derive(Clone, Copy, PartialEq)]
enum Output {
    /// Files: read afterwards for panics.
    Files,
    /// Pipes whose read ends close with the launcher: every write of a daemon to stdout or
    /// stderr after that fails with EPIPE.
    ClosedPipes,
}

/// Start `rig ARGS`, wait until its `daemons` children run (and `recording` exists), SIGKILL the
/// launcher. This test is their subreaper, so it reaps them and sees how they ended: gone within
/// 1 s, the plant with exit status 0 (it finalised the recording on the SIGTERM of
/// PR_SET_PDEATHSIG and printed its summary into the dead pipe without panicking: a panic is
/// status 101), a controller with 0 or SIGTERM.
fn kill_launcher(tag: &str, args: &[&str], dir: &Path, daemons: usize, recording: Option<&Path>, output: Output) {
    // SAFETY: plain prctl on this process; orphans of rig become this process's children.
    assert_eq!(unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1 as libc::c_ulong, 0, 0, 0) }, 0);
    let err_path = dir.join(format!("{tag}.stderr"));
    let mut cmd = Command::new(bin("rig"));
    cmd.args(args).stdin(std::process::Stdio::null());
    match output {
        Output::Files => {
            cmd.stdout(std::fs::File::create(dir.join(format!("{tag}.stdout"))).unwrap());
            cmd.stderr(std::fs::File::create(&err_path).unwrap());
        }
        Output::ClosedPipes => {
            cmd.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
        }
    }
    let mut rig = cmd.spawn().unwrap();
    let rig_pid = rig.id() as i32;
    let t0 = Instant::now();
    let kids = loop {
        let k = children(rig_pid);
        if k.len() == daemons && recording.is_none_or(|r| r.exists()) {
            break k;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "{tag}: daemons did not start ({k:?})");
        std::thread::sleep(Duration::from_millis(20));
    };
    let names: Vec<String> =
        kids.iter().map(|k| std::fs::read_to_string(format!("/proc/{k}/comm")).unwrap_or_default().trim().to_string()).collect();
    std::thread::sleep(Duration::from_millis(700));
    let _ = rig.kill();
    let killed = Instant::now();
    let _ = rig.wait();
    // The launcher's pipes die with it (this test holds no other end open).
    drop(rig.stdout.take());
    drop(rig.stderr.take());
    let mut statuses: Vec<Option<i32>> = vec![None; kids.len()];
    while statuses.iter().any(Option::is_none) && killed.elapsed() < Duration::from_secs(5) {
        for (i, &k) in kids.iter().enumerate() {
            if statuses[i].is_none() {
                let mut st = 0;
                // SAFETY: waiting for an orphan this process reaps as subreaper.
                if unsafe { libc::waitpid(k, &mut st, libc::WNOHANG) } == k {
                    statuses[i] = Some(st);
                }
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let took = killed.elapsed();
    for (i, &k) in kids.iter().enumerate() {
        if statuses[i].is_none() {
            // Orphans of a failing run must not outlive the test.
            // SAFETY: signalling and reaping a process this test started (through rig).
            unsafe {
                libc::kill(k, libc::SIGKILL);
                libc::waitpid(k, std::ptr::null_mut(), 0);
            }
        }
    }
    assert!(took < Duration::from_secs(1), "{tag}: daemons {names:?} {kids:?} still there {took:?} after SIGKILL of rig");
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    assert!(!err.contains("panicked"), "{tag}: a daemon panicked:\n{err}");
    for (name, st) in names.iter().zip(&statuses) {
        let st = st.unwrap();
        let (exited, code, sig) = (libc::WIFEXITED(st), libc::WEXITSTATUS(st), libc::WTERMSIG(st));
        if name == "plant-sim" {
            assert!(exited && code == 0, "{tag}: plant-sim ended with raw status {st:#x} (exit {code}, signal {sig}); 101 = panic\n{err}");
        } else {
            assert!((exited && code == 0) || (!exited && sig == libc::SIGTERM), "{tag}: {name} ended with raw status {st:#x}\n{err}");
        }
    }
    match recording {
        Some(r) => {
            let rec = Recording::open_complete(r).unwrap_or_else(|e| panic!("{tag}: recording not finalised: {e:#}\n{err}"));
            assert!(!rec.joint_state.is_empty());
            // (Lockstep runs flat out: under load the recorder's queue may drop events, so only the
            // paced runs are held to the note.)
            let why = rec.events_of(EventKind::Fault).find(|e| e.text.contains("the launcher (PID"));
            assert!(why.is_some() || tag == "rig-sweep", "{tag}: the recording does not say the launcher died: {:?}", rec.events);
            println!(
                "{tag}: {names:?} gone {took:?} after SIGKILL of the launcher; recording finalised with {} ticks",
                rec.joint_state.len()
            );
        }
        None => println!("{tag}: {names:?} gone {took:?} after SIGKILL of the launcher"),
    }
}

#[test]
fn sigkill_of_rig_run_ends_both_daemons_within_a_second_and_the_recording_is_finalised() {
    let _g = serial();
    let rig = unique_rig("kill-run");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    let out = dir.join("out");
    kill_launcher(
        "rig-run",
        &["run", scenario.to_str().unwrap(), "--duration", "300", "--out", out.to_str().unwrap()],
        &dir,
        2,
        Some(&out.join("run.mcap")),
        Output::Files,
    );
}

#[test]
fn sigkill_of_rig_run_with_its_output_in_pipes_leaves_no_daemon_panicking_on_them() {
    let _g = serial();
    let rig = unique_rig("kill-pipes");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    let out = dir.join("out");
    let args = ["run", scenario.to_str().unwrap(), "--duration", "300", "--out", out.to_str().unwrap()];
    kill_launcher("rig-run-pipes", &args, &dir, 2, Some(&out.join("run.mcap")), Output::ClosedPipes);
}

#[test]
fn sigkill_of_rig_timing_ends_both_daemons_within_a_second() {
    let _g = serial();
    let rig = unique_rig("kill-timing");
    let dir = temp_dir(&rig);
    let out = dir.join("out");
    kill_launcher(
        "rig-timing",
        &["timing", "--seconds", "300", "--out", out.to_str().unwrap()],
        &dir,
        2,
        Some(&out.join("run.mcap")),
        Output::Files,
    );
}

#[test]
fn sigkill_of_rig_sweep_ends_both_daemons_within_a_second() {
    let _g = serial();
    let rig = unique_rig("kill-sweep");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "lockstep", "");
    let out = dir.join("out");
    // A controller of the user's: the cases run with both daemons (without one, in process).
    let controller = bin("controller");
    kill_launcher(
        "rig-sweep",
        &[
            "sweep",
            scenario.to_str().unwrap(),
            "--set",
            "loop.max_consecutive_misses=20,21",
            "--duration",
            "3000",
            "--controller",
            controller.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &dir,
        2,
        Some(&out.join("case-00").join("run.mcap")),
        Output::Files,
    );
}

#[test]
fn sigkill_of_rig_replay_ends_its_controller_within_a_second() {
    let _g = serial();
    let t = TestRig::new("kill-replay", "lockstep");
    let mut plant = t.plant(0.5);
    let mut ctrl = t.controller("controller", "controller", &[]);
    assert!(plant.expect_exit(LONG).success(), "plant: {}", plant.stderr());
    ctrl.expect_exit(Duration::from_secs(10));
    // 500 ticks at 1/20 of the recorded rate: 10 s of replay.
    let rec = t.recording();
    kill_launcher("rig-replay", &["replay", rec.to_str().unwrap(), "--controller", "--speed", "0.05"], &t.dir, 1, None, Output::Files);
}

#[test]
fn a_sigbus_in_the_plant_is_one_sentence_and_exit_71_and_rig_names_the_plant() {
    // What a tmpfs that fills up after the check delivers on the first touch of a mapped page;
    // sent here by hand, as no test can time a full tmpfs to the middle of a run.
    let _g = serial();
    let rig = unique_rig("sigbus");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    let out = dir.join("out");
    let mut run =
        Daemon::start("rig", &bin("rig"), &["run", scenario.to_str().unwrap(), "--duration", "30", "--out", out.to_str().unwrap()], &dir);
    let t0 = Instant::now();
    let plant = loop {
        let k = children(run.pid());
        let plant = k.iter().copied().find(|p| std::fs::read_to_string(format!("/proc/{p}/comm")).is_ok_and(|c| c.trim() == "plant-sim"));
        if let (Some(p), true) = (plant, k.len() == 2 && run.stderr().contains("connected")) {
            break p;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "daemons did not start:\n{}", run.stderr());
        std::thread::sleep(Duration::from_millis(20));
    };
    // SAFETY: signalling a process this test started (through rig).
    unsafe { libc::kill(plant, libc::SIGBUS) };
    let st = run.expect_exit(Duration::from_secs(20));
    let err = run.stderr();
    assert_eq!(st.code(), Some(2), "rig names the plant:\n{err}");
    assert!(err.contains("plant-sim: error: shared memory in /dev/shm failed under the rig (SIGBUS"), "{err}");
    let verdict = err.lines().find(|l| l.contains("FAILED")).unwrap();
    assert!(verdict.contains("PLANT FAILED: plant-sim ended with exit status 71"), "{verdict}");
    assert!(!verdict.contains("signal 7") && !verdict.contains("cleanly"), "{verdict}");
    println!("{verdict}");
}

/// True when this process may make private mount namespaces (root with `unshare`); otherwise
/// prints `SKIPPED:` with why.
fn namespaces_available(test: &str) -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        println!("SKIPPED: {test}: needs root for a private mount namespace with its own /dev/shm");
        return false;
    }
    match Command::new("unshare").args(["--mount", "true"]).output() {
        Ok(o) if o.status.success() => true,
        Ok(o) => {
            println!("SKIPPED: {test}: `unshare --mount` refused: {}", String::from_utf8_lossy(&o.stderr).trim());
            false
        }
        Err(e) => {
            println!("SKIPPED: {test}: no `unshare` ({e})");
            false
        }
    }
}

/// Run `script` with bash in a private mount namespace; returns (exit code, stdout, stderr).
fn in_namespace(script: &str) -> (Option<i32>, String, String) {
    let o = Command::new("unshare").args(["--mount", "--propagation", "private", "bash", "-c", script]).output().expect("unshare");
    (o.status.code(), String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// A state directory for one test, short enough for iceoryx2's socket paths
/// (`rig_process::host::MAX_STATE_DIR_LEN`).
fn short_state_dir(tag: &str) -> String {
    let d = format!("/tmp/rs-{tag}-{}", std::process::id());
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Lines `KEY=value` a namespace script printed.
fn field<'a>(out: &'a str, key: &str) -> &'a str {
    out.lines().find_map(|l| l.strip_prefix(&format!("{key}="))).unwrap_or_else(|| panic!("no {key}= in:\n{out}"))
}

/// Plant alone, controller alone and `rig run`, each in `/dev/shm` as `mount_cmds` leave it.
/// Each daemon must end with exit status 71 (no signal) and the one sentence containing `needle`;
/// rig must name the daemon that failed, with 71, and call nothing clean that was not.
fn shm_fault(tag: &str, mount_cmds: &str, needle: &str) {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    let (plant, ctrl, rigbin) = (bin("plant-sim"), bin("controller"), bin("rig"));
    let (s, d) = (scenario.display(), dir.display());
    let script = format!(
        r#"set -u
export RIG_ICEORYX2_DIR={state}
{mount_cmds}
{plant} --rig {rig} --scenario {s} --duration 1 --out {d}/p.mcap >{d}/plant.out 2>{d}/plant.err; echo plant=$?
{ctrl} --rig {rig} --scenario {s} >{d}/ctrl.out 2>{d}/ctrl.err; echo controller=$?
{rigbin} run {s} --duration 1 --out {d}/run >{d}/rig.out 2>{d}/rig.err; echo rig=$?
"#,
        plant = plant.display(),
        ctrl = ctrl.display(),
        rigbin = rigbin.display(),
        state = short_state_dir(tag),
    );
    let (code, out, err) = in_namespace(&script);
    assert_eq!(code, Some(0), "namespace script failed:\n{out}\n{err}");
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    for (who, file) in [("plant", "plant.err"), ("controller", "ctrl.err")] {
        let text = read(file);
        assert_eq!(
            field(&out, who),
            EXIT_SHARED_MEMORY.to_string(),
            "{who} exit status (71 = shared memory; 135 would be SIGBUS):\n{text}"
        );
        let lines: Vec<&str> = text.lines().filter(|l| l.contains(needle)).collect();
        assert_eq!(lines.len(), 1, "{who}: one sentence with {needle:?}:\n{text}");
        assert!(lines[0].contains("--shm-size"), "{who}: the sentence carries the fix: {}", lines[0]);
        assert!(!text.contains("UnableToGenerateUniqueNodeId") && !text.contains("panicked"), "{who}:\n{text}");
        println!("{tag}: {who}: exit 71: {}", lines[0]);
    }
    let rig_err = read("rig.err");
    let rig_code: i32 = field(&out, "rig").parse().unwrap();
    let verdict = rig_err.lines().find(|l| l.contains("FAILED")).unwrap_or_else(|| panic!("rig named nobody:\n{rig_err}"));
    match rig_code {
        2 => assert!(verdict.contains("PLANT FAILED: plant-sim ended with exit status 71"), "{verdict}"),
        3 => assert!(verdict.contains("CONTROLLER FAILED: controller quit early: it ended with exit status 71"), "{verdict}"),
        c => panic!("rig exit {c}, expected 2 (plant) or 3 (controller):\n{rig_err}"),
    }
    assert!(!verdict.contains("signal 7") && !verdict.contains("cleanly (killed"), "{verdict}");

    assert!(rig_err.contains(needle), "the daemon's sentence reaches the user:\n{rig_err}");
    println!("{tag}: rig exit {rig_code}: {verdict}");
}

#[test]
fn a_40_kib_dev_shm_is_one_sentence_and_exit_71_not_sigbus() {
    let _g = serial();
    if !namespaces_available("a_40_kib_dev_shm") {
        return;
    }
    shm_fault(
        "shm40k",
        "mount -t tmpfs -o size=40k,mode=1777 tmpfs /dev/shm",
        "KiB free, too little for a rig (it holds 76 KiB while it runs",
    );
}

#[test]
fn a_read_only_dev_shm_is_one_sentence_and_exit_71() {
    let _g = serial();
    if !namespaces_available("a_read_only_dev_shm") {
        return;
    }
    shm_fault(
        "shmro",
        "mount -t tmpfs -o size=16m,mode=1777 tmpfs /dev/shm && mount -o remount,ro /dev/shm",
        "/dev/shm is mounted read-only",
    );
}

#[test]
fn a_second_user_can_neither_stop_a_rig_from_starting_nor_open_its_services() {
    let _g = serial();
    if !namespaces_available("a_second_user") {
        return;
    }
    if !Command::new("setpriv").arg("--version").output().is_ok_and(|o| o.status.success()) {
        println!("SKIPPED: a_second_user: no `setpriv` to act as user nobody");
        return;
    }
    let rig = unique_rig("user2");
    let dir = temp_dir(&rig);
    let scenario = write_scenario(&dir, "realtime", "");
    // The other user reads the scenario and writes its notes here.
    std::fs::set_permissions(&dir, std::os::unix::fs::PermissionsExt::from_mode(0o777)).unwrap();
    std::fs::set_permissions(&scenario, std::os::unix::fs::PermissionsExt::from_mode(0o644)).unwrap();
    let (plant, ctrl) = (bin("plant-sim"), bin("controller"));
    let (s, d) = (scenario.display(), dir.display());
    // Fresh /dev/shm and /run, as after a boot: the other user moves first, before the rig's
    // first start, then again while the rig runs. The rig uses the default state directory
    // (/run/rig-iceoryx2 for root).
    let script = format!(
        r#"set -u
mount -t tmpfs -o mode=1777 tmpfs /dev/shm
mount -t tmpfs -o mode=755 tmpfs /run
unset RIG_ICEORYX2_DIR
as_other() {{ setpriv --reuid=65534 --regid=65534 --clear-groups "$@"; }}
# before the first start: squat what it can (iceoryx2's default global management segment, the
# default root path, the rig's state directory) and fill /dev/shm with junk of its own
as_other sh -c 'echo junk > /dev/shm/iox2_9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt; mkdir -p /tmp/iceoryx2/nodes 2>/dev/null; mkdir /run/rig-iceoryx2 2>/dev/null && echo squat_state_dir=yes || echo squat_state_dir=no'
{plant} --rig {rig} --scenario {s} --duration 2.5 --out {d}/run.mcap >{d}/plant.out 2>{d}/plant.err &
P=$!
{ctrl} --rig {rig} --scenario {s} >{d}/ctrl.out 2>{d}/ctrl.err &
C=$!
sleep 1
# while it runs: every rig file in /dev/shm, overwritten or read
as_other sh -c 'n=0; for f in /dev/shm/rig0_*; do [ -e "$f" ] || continue; n=$((n+1)); (: > "$f") 2>/dev/null && echo "wrote $f"; cat "$f" >/dev/null 2>&1 && echo "read $f"; done; echo rig_files_seen=$n' > {d}/other.txt
as_other sh -c 'ls /run/rig-iceoryx2 >/dev/null 2>&1 && echo state_dir_listed=yes || echo state_dir_listed=no' >> {d}/other.txt
ls -l /dev/shm > {d}/shm.txt
ls -ld /run/rig-iceoryx2 /run/rig-iceoryx2/* >> {d}/shm.txt
# open the rig's services: with the rig's state directory (not readable to it), and with its own
timeout 5 setpriv --reuid=65534 --regid=65534 --clear-groups env RIG_ICEORYX2_DIR=/run/rig-iceoryx2 {ctrl} --rig {rig} --scenario {s} >/dev/null 2>{d}/other_ctrl1.err; echo other_ctrl_rig_dir=$?
timeout 1 setpriv --reuid=65534 --regid=65534 --clear-groups env RIG_ICEORYX2_DIR={other_state} {ctrl} --rig {rig} --scenario {s} >/dev/null 2>{d}/other_ctrl2.err; echo other_ctrl_own_dir=$?
wait $P; echo plant=$?
wait $C; echo controller=$?
# and the next rig starts too, after the other user's attempts
{plant} --rig {rig}-2 --scenario {s} --mode lockstep --duration 0.3 --out {d}/run2.mcap >{d}/plant2.out 2>{d}/plant2.err &
P=$!
{ctrl} --rig {rig}-2 --scenario {s} >/dev/null 2>{d}/ctrl2.err; echo controller2=$?
wait $P; echo plant2=$?
"#,
        plant = plant.display(),
        ctrl = ctrl.display(),
        other_state = short_state_dir("u2"),
    );
    let (code, out, err) = in_namespace(&script);
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    assert_eq!(code, Some(0), "namespace script failed:\n{out}\n{err}");
    assert_eq!(field(&out, "squat_state_dir"), "no", "the other user must not be able to create the rig's state directory");
    assert_eq!(field(&out, "plant"), "0", "the rig did not start or run:\n{}", read("plant.err"));
    assert_eq!(field(&out, "controller"), "0", "{}", read("ctrl.err"));
    assert_eq!(field(&out, "plant2"), "0", "the next rig did not start:\n{}", read("plant2.err"));
    assert_eq!(field(&out, "controller2"), "0", "{}", read("ctrl2.err"));
    let other = read("other.txt");
    assert!(!other.contains("wrote ") && !other.contains("read "), "the other user reached the rig's files:\n{other}\n{}", read("shm.txt"));
    let seen: usize = field(&other, "rig_files_seen").parse().unwrap();
    assert!(seen >= 17, "the rig's {seen} files in /dev/shm were not all there to attack:\n{}", read("shm.txt"));
    assert_eq!(field(&other, "state_dir_listed"), "no", "{other}");
    // every rig file owner-only, the global management segment included
    let shm = read("shm.txt");
    for l in shm.lines().filter(|l| l.contains(" rig0_")) {
        assert!(l.starts_with("-rw-------") || l.starts_with("-r--------"), "not owner-only: {l}");
    }
    assert!(shm.lines().any(|l| l.contains("global_mgmt") && l.contains(" rig0_") && l.starts_with("-rw-------")), "{shm}");
    // with the rig's state directory the other user's controller is refused at once (exit 71)
    assert_eq!(field(&out, "other_ctrl_rig_dir"), EXIT_SHARED_MEMORY.to_string(), "{}", read("other_ctrl1.err"));
    // with its own configuration it never reaches the rig (killed by timeout: 124)
    assert_eq!(field(&out, "other_ctrl_own_dir"), "124", "{}", read("other_ctrl2.err"));
    // the rig heard only its own controller
    let rec = Recording::open_complete(dir.join("run.mcap")).expect("complete recording");
    assert_eq!(rec.joint_state.len(), 2500);
    assert_eq!(rec.events_of(EventKind::ControllerChange).count(), 1, "{:?}", rec.events);
    assert_eq!(rec.events_of(EventKind::SafeStop).count(), 0, "{:?}", rec.events);
    println!("second user: squatted the defaults, saw {seen} rig files and opened none; the rig ran 2500 ticks with one controller");
    println!("other user with the rig's state dir: {}", read("other_ctrl1.err").lines().last().unwrap_or(""));
}
