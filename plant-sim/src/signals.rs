//! The plant's signals as a handle the loops are given ([`Signals`]), not globals they read:
//! SIGINT/SIGTERM ask for a stop, and `rig` reports the controller's end with SIGUSR1
//! (sigqueue). A signal handler can only reach a static, so the process' flags are one; a
//! handle made by [`Signals::detached`] has flags of its own that no signal sets (in-process
//! runs inside another program, tests).

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// The flags a handle reads.
#[derive(Debug)]
pub struct Flags {
    stop: AtomicBool,
    /// The last controller-end report: [`encode_controller_end`]'s value, 0 = none.
    controller_end: AtomicI32,
}

impl Flags {
    const fn new() -> Flags {
        Flags { stop: AtomicBool::new(false), controller_end: AtomicI32::new(0) }
    }
}

/// The process' flags: the only ones a signal handler sets.
static PROCESS: Flags = Flags::new();

/// What the loops ask about stopping, passed to them.
#[derive(Debug, Clone, Copy)]
pub struct Signals {
    flags: &'static Flags,
}

impl Signals {
    /// The process' signals: SIGINT and SIGTERM ask for a stop, SIGUSR1 carries the controller's
    /// end from `rig`. Installing twice is harmless.
    pub fn install() -> Signals {
        install_stop_handlers();
        install_controller_end_handler();
        Signals { flags: &PROCESS }
    }

    /// The process' SIGINT/SIGTERM only (a launcher: SIGUSR1 is the plant's).
    pub fn install_stop_only() -> Signals {
        install_stop_handlers();
        Signals { flags: &PROCESS }
    }

    /// Flags of its own that no signal sets: stopped only by [`Signals::request_stop`].
    pub fn detached() -> Signals {
        Signals { flags: Box::leak(Box::new(Flags::new())) }
    }

    /// True once a stop was asked for.
    #[inline]
    pub fn stop_requested(&self) -> bool {
        self.flags.stop.load(Ordering::Relaxed)
    }

    /// Ask for a stop from inside the process (tests, fatal conditions).
    pub fn request_stop(&self) {
        self.flags.stop.store(true, Ordering::Relaxed);
    }

    /// True while a controller-end report waits to be taken (a wait should end early for it).
    #[inline]
    pub fn controller_end_pending(&self) -> bool {
        self.flags.controller_end.load(Ordering::Relaxed) != 0
    }

    /// Taken once: the controller-end report `rig` sent, if any.
    pub fn take_controller_end(&self) -> Option<ControllerEnd> {
        decode_controller_end(self.flags.controller_end.swap(0, Ordering::Relaxed))
    }

    /// Report the controller's end as `rig`'s SIGUSR1 would (tests).
    pub fn report_controller_end(&self, end: ControllerEnd) {
        self.flags.controller_end.store(encode_controller_end(end), Ordering::Relaxed);
    }
}

extern "C" fn on_signal(_: libc::c_int) {
    PROCESS.stop.store(true, Ordering::Relaxed);
}

/// Route SIGINT and SIGTERM to the process' stop flag.
fn install_stop_handlers() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        sa.sa_flags = 0;
        libc::sigaction(libc::SIGINT, &sa, std::ptr::null_mut());
        libc::sigaction(libc::SIGTERM, &sa, std::ptr::null_mut());
    }
}

extern "C" fn on_controller_ended(_sig: libc::c_int, info: *mut libc::siginfo_t, _ctx: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo_t to an SA_SIGINFO handler; reading it and storing
    // to an atomic is async-signal-safe.
    let v = unsafe { (*info).si_value().sival_ptr as usize as i32 };
    PROCESS.controller_end.store(if v == 0 { i32::MIN } else { v }, Ordering::Relaxed);
}

/// Route SIGUSR1, through which `rig` tells the plant that the controller process ended (it sends
/// `sigqueue(plant, SIGUSR1, code)` with [`encode_controller_end`]'s code), to the process' flag.
fn install_controller_end_handler() {
    // SAFETY: as in install_stop_handlers; the handler only reads siginfo and stores an atomic.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_controller_ended as extern "C" fn(libc::c_int, *mut libc::siginfo_t, *mut libc::c_void) as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        sa.sa_flags = libc::SA_SIGINFO;
        libc::sigaction(libc::SIGUSR1, &sa, std::ptr::null_mut());
    }
}

/// How a controller process ended, as `rig` reports it to the plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerEnd {
    Exit(i32),
    Signal(i32),
    Unknown,
    /// The process (`pid`) is alive but answered no state within the connect timeout; `rig`
    /// stops it. `seen`: what `rig` saw of it (`rig_process::connect::NotConnected::code`).
    NeverConnected {
        pid: u32,
        seen: u8,
    },
}

impl std::fmt::Display for ControllerEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ControllerEnd::Exit(c) => write!(f, "exit status {c}"),
            ControllerEnd::Signal(s) => write!(f, "killed by signal {s}"),
            ControllerEnd::Unknown => f.write_str("unknown status"),
            ControllerEnd::NeverConnected { pid, seen } => write!(
                f,
                "never connected: process {pid} answered no state within loop.connect_timeout_s ({}); rig stops it",
                rig_process::connect::NotConnected::what(*seen)
            ),
        }
    }
}

/// Tag of a never-connected report in the sigqueue value: above every exit status code.
const NEVER_CONNECTED: i32 = 1 << 29;

/// The sigqueue value for `end` (never 0). A never-connected report packs what was seen (3
/// bits) and the pid (up to 2^22, Linux's pid_max limit) under [`NEVER_CONNECTED`].
pub fn encode_controller_end(end: ControllerEnd) -> i32 {
    match end {
        ControllerEnd::Exit(c) => 1 + c.clamp(0, 255),
        ControllerEnd::Signal(s) => -s.clamp(1, 64),
        ControllerEnd::Unknown => i32::MIN,
        ControllerEnd::NeverConnected { pid, seen } => NEVER_CONNECTED | (i32::from(seen & 7) << 22) | (pid & 0x3f_ffff) as i32,
    }
}

/// The report of a sigqueue value ([`encode_controller_end`]); 0 is none.
pub fn decode_controller_end(v: i32) -> Option<ControllerEnd> {
    match v {
        0 => None,
        i32::MIN => Some(ControllerEnd::Unknown),
        // Positive only: a signal's negative value has the tag bit set too.
        v if v > 0 && v & NEVER_CONNECTED != 0 => {
            Some(ControllerEnd::NeverConnected { pid: (v & 0x3f_ffff) as u32, seen: ((v >> 22) & 7) as u8 })
        }
        v if v > 0 => Some(ControllerEnd::Exit(v - 1)),
        v => Some(ControllerEnd::Signal(-v)),
    }
}

#[cfg(test)]
mod controller_end_tests {
    use super::*;

    /// Every report survives the sigqueue value, a signal's negative value included (its tag bit
    /// is set too, which once read a SIGKILL as "never connected").
    #[test]
    fn controller_end_reports_round_trip() {
        for end in [
            ControllerEnd::Exit(0),
            ControllerEnd::Exit(255),
            ControllerEnd::Signal(9),
            ControllerEnd::Signal(15),
            ControllerEnd::Unknown,
            ControllerEnd::NeverConnected { pid: 4_194_303, seen: 4 },
            ControllerEnd::NeverConnected { pid: 1, seen: 0 },
        ] {
            let v = encode_controller_end(end);
            assert_ne!(v, 0);
            assert_eq!(decode_controller_end(v), Some(end), "{v:#x}");
        }
        assert_eq!(decode_controller_end(0), None);
    }
}

#[cfg(test)]
mod handle_tests {
    use super::*;

    #[test]
    fn a_detached_handle_has_flags_of_its_own() {
        let (a, b) = (Signals::detached(), Signals::detached());
        a.request_stop();
        assert!(a.stop_requested() && !b.stop_requested());
        b.report_controller_end(ControllerEnd::Exit(3));
        assert!(b.controller_end_pending() && !a.controller_end_pending());
        assert_eq!(b.take_controller_end(), Some(ControllerEnd::Exit(3)));
        assert!(!b.controller_end_pending(), "taken once");
        assert_eq!(b.take_controller_end(), None);
    }
}
