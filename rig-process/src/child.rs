//! Child processes of the rig's launchers, written once: `rig` (crate `rig`, through tokio), `rig
//! replay` (`recording-tools`) and the end-to-end tests' harness (`tests`) spawn, wait for,
//! stop and describe their daemons with these.
//!
//! - [`configure`]: stdin from /dev/null, optionally an own process group and
//!   [`die_with_parent`](crate::host::die_with_parent) (PR_SET_PDEATHSIG: the child gets SIGTERM
//!   when the spawning thread ends, even by SIGKILL);
//! - [`wait_deadline`]: wait for the exit until a deadline;
//! - [`stop`]: SIGTERM, up to a grace period for the exit, then SIGKILL; [`await_or_stop`] first
//!   gives the child a grace period to exit by itself; [`Guard`] kills and reaps on drop;
//! - [`describe`], [`ended`], [`describe_stopped`]: the exit-status text of `rig`'s summary
//!   ("cleanly" only for exit status 0, signals named).
//!
//! Blocking calls (they poll `try_wait` every [`POLL`]); `rig`'s async supervisor awaits tokio's
//! `wait` between the same steps ([`signal`], [`GRACE`]) instead.

use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How often the blocking waits look at the child.
pub const POLL: Duration = Duration::from_millis(2);

/// What [`stop`] gives a child between SIGTERM and SIGKILL when the caller has no reason to wait
/// longer or shorter: the plant finalises its recording within it.
pub const GRACE: Duration = Duration::from_secs(3);

/// How a child is started.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpawnOptions {
    /// Its own process group: a terminal's Ctrl-C reaches the launcher only, which then stops its
    /// children in order.
    pub own_process_group: bool,
    /// SIGTERM to the child when the spawning thread ends (spawn from the main thread).
    pub die_with_parent: bool,
}

/// Stdin from /dev/null plus `opts` on `cmd`.
pub fn configure(cmd: &mut Command, opts: SpawnOptions) -> &mut Command {
    cmd.stdin(Stdio::null());
    if opts.own_process_group {
        cmd.process_group(0);
    }
    if opts.die_with_parent {
        // SAFETY: the hook calls only prctl/getppid between fork and exec.
        unsafe {
            cmd.pre_exec(crate::host::die_with_parent());
        }
    }
    cmd
}

/// Sends `sig` to process `pid` (a child not reaped yet, so the pid is still ours).
pub fn signal(pid: u32, sig: i32) {
    // SAFETY: kill has no memory preconditions; the caller owns the unreaped child `pid`.
    unsafe { libc::kill(pid as i32, sig) };
}

/// Waits until `child` exits or `timeout` passes: its status, or None at the deadline.
pub fn wait_deadline(child: &mut Child, timeout: Duration) -> std::io::Result<Option<ExitStatus>> {
    let until = Instant::now() + timeout;
    loop {
        if let Some(s) = child.try_wait()? {
            return Ok(Some(s));
        }
        if Instant::now() >= until {
            return Ok(None);
        }
        std::thread::sleep(POLL);
    }
}

/// SIGTERM, up to `grace` for the exit, then SIGKILL; the exit status (None: not reaped).
pub fn stop(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    if let Ok(Some(s)) = child.try_wait() {
        return Some(s);
    }
    signal(child.id(), libc::SIGTERM);
    match wait_deadline(child, grace) {
        Ok(Some(s)) => Some(s),
        _ => kill(child),
    }
}

/// Up to `grace` for `child` to exit by itself, then [`stop`] with [`GRACE`].
pub fn await_or_stop(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    match wait_deadline(child, grace) {
        Ok(Some(s)) => Some(s),
        _ => stop(child, GRACE),
    }
}

/// SIGKILL (if it still runs) and reap.
pub fn kill(child: &mut Child) -> Option<ExitStatus> {
    if let Ok(None) = child.try_wait() {
        let _ = child.kill();
    }
    child.wait().ok()
}

/// A child that is killed (SIGKILL) and reaped when dropped, unless it was taken out.
#[derive(Debug, Default)]
pub struct Guard(pub Option<Child>);

impl Drop for Guard {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            kill(&mut c);
        }
    }
}

/// "exit status N" (with what the rig's own statuses mean) or "killed by signal N (NAME)".
pub fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) if c == crate::host::EXIT_SHARED_MEMORY => {
            format!("exit status {c} (shared memory unusable, see its message above)")
        }
        (Some(c), _) if c == crate::host::EXIT_RIG_TAKEN => format!("exit status {c} (the rig name is taken)"),
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(s)) => format!("killed by signal {s} ({})", signal_name(s)),
        _ => "unknown status".into(),
    }
}

/// The signals a daemon of the rig dies of, named (with the cause where it is known).
pub fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGBUS => "SIGBUS: a bus error, e.g. shared memory that /dev/shm could not back",
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGABRT => "SIGABRT: it aborted",
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        _ => "a signal",
    }
}

/// "ended with exit status N (...)" or "was killed by signal N (...)".
pub fn ended(status: ExitStatus) -> String {
    if status.signal().is_some() {
        format!("was {}", describe(status))
    } else {
        format!("ended with {}", describe(status))
    }
}

/// How a child that the launcher stopped ended: "cleanly" only for exit status 0.
pub fn describe_stopped(status: Option<ExitStatus>) -> String {
    match status {
        Some(s) if s.success() => "stopped cleanly".to_string(),
        Some(s) => ended(s),
        None => "could not be reaped".to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_exit_status_0_is_clean_and_signals_are_named() {
        let bus = ended(ExitStatus::from_raw(libc::SIGBUS));
        assert!(bus.starts_with("was killed by signal 7 (SIGBUS") && !bus.contains("clean"), "{bus}");
        assert_eq!(ended(ExitStatus::from_raw(3 << 8)), "ended with exit status 3");
        assert_eq!(describe_stopped(Some(ExitStatus::from_raw(0))), "stopped cleanly");
        assert_eq!(describe_stopped(Some(ExitStatus::from_raw(1 << 8))), "ended with exit status 1");
        assert_eq!(describe_stopped(None), "could not be reaped");
        let shm = describe_stopped(Some(ExitStatus::from_raw(crate::host::EXIT_SHARED_MEMORY << 8)));
        assert_eq!(shm, "ended with exit status 71 (shared memory unusable, see its message above)");
    }

    /// A child that ignores SIGTERM is killed after the grace; one that exits on it is not.
    #[test]
    fn stop_terminates_then_kills() {
        let mut stubborn = configure(Command::new("sh").args(["-c", "trap '' TERM; sleep 10"]), SpawnOptions::default()).spawn().unwrap();
        std::thread::sleep(Duration::from_millis(100)); // the trap is set
        let t0 = Instant::now();
        let s = stop(&mut stubborn, Duration::from_millis(200)).unwrap();
        assert_eq!(s.signal(), Some(libc::SIGKILL), "{s:?}");
        assert!(t0.elapsed() >= Duration::from_millis(200), "{:?}", t0.elapsed());
        let mut polite = configure(Command::new("sleep").arg("10"), SpawnOptions::default()).spawn().unwrap();
        let s = stop(&mut polite, Duration::from_secs(5)).unwrap();
        assert_eq!(s.signal(), Some(libc::SIGTERM), "{s:?}");
        let mut quick = Command::new("true").spawn().unwrap();
        assert!(wait_deadline(&mut quick, Duration::from_secs(5)).unwrap().unwrap().success());
    }
}
