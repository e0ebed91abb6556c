//! Operating-system knobs of a real-time loop thread (Linux): timer slack, SCHED_FIFO, mlockall,
//! absolute sleeps on CLOCK_MONOTONIC, clocks, and a signal flag for SIGINT/SIGTERM.

use std::sync::atomic::{AtomicBool, Ordering};

/// What the real-time set-up achieved (logged once at start).
#[derive(Debug, Clone, Copy, Default)]
pub struct RtSetup {
    pub timer_slack_1ns: bool,
    pub sched_fifo: bool,
    pub mlockall: bool,
}

/// Prepare the calling thread: timer slack 1 ns (so absolute sleeps wake on time instead of up to
/// 50 µs late), SCHED_FIFO at `priority` (None = keep the normal policy) and locked memory when
/// the process may (CAP_SYS_NICE / rtprio limits, CAP_IPC_LOCK / memlock limits). Failures are
/// reported, not fatal.
pub fn setup_thread(priority: Option<i32>) -> RtSetup {
    let mut r = RtSetup::default();
    // SAFETY: plain syscalls on the calling thread/process with valid arguments.
    unsafe {
        r.timer_slack_1ns = libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) == 0;
        if let Some(priority) = priority {
            let param = libc::sched_param { sched_priority: priority };
            r.sched_fifo = libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) == 0;
        }
        r.mlockall = libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0;
    }
    r
}

/// The CPU a lockstep rig runs on: the last one. Plant and controller on one CPU hand over
/// without an inter-processor wake-up (on a 2-vCPU VM: 15 µs instead of 60-75 µs per round
/// trip); `rig` starts the controller pinned to the same CPU.
pub fn lockstep_cpu() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get()) - 1
}

/// Pin the calling thread to one CPU. Returns false if the kernel refused.
pub fn pin_thread_to_cpu(cpu: usize) -> bool {
    // SAFETY: a zeroed cpu_set_t is an empty set; CPU_SET writes within it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

/// Take one CPU out of the calling thread's affinity, so the threads it spawns from now on
/// (affinity is inherited at spawn) stay off it: a lockstep run keeps the recorder's writer off
/// the CPU its loop and controller are pinned to. Returns false if no other CPU is left or the
/// kernel refused. Note: [`lockstep_cpu`] counts the CPUs of the calling thread's affinity, so
/// call it before this.
pub fn keep_thread_off_cpu(cpu: usize) -> bool {
    // SAFETY: cpu_set_t is plain data; sched_getaffinity fills it, CPU_* stay within it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        let size = std::mem::size_of::<libc::cpu_set_t>();
        if libc::sched_getaffinity(0, size, &mut set) != 0 {
            return false;
        }
        libc::CPU_CLR(cpu, &mut set);
        libc::CPU_COUNT(&set) > 0 && libc::sched_setaffinity(0, size, &set) == 0
    }
}

/// Set the calling thread's nice value (Linux: per thread). Returns false if refused (lowering it
/// below 0 needs CAP_SYS_NICE or an RLIMIT_NICE allowance).
pub fn set_thread_nice(nice: i32) -> bool {
    // SAFETY: plain syscalls on the calling thread.
    unsafe {
        let tid = libc::gettid() as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, nice) == 0
    }
}

/// Hold the kernel's PM QoS CPU latency request at 0 µs for the rest of the process, as cyclictest
/// does: idle CPUs then poll instead of halting, so a wake-up (the controller's notification, the
/// tick timer) costs a few µs instead of a vCPU exit and an inter-processor interrupt (tens of µs
/// on a VM). The request lasts while the file stays open; the kernel drops it when we exit.
pub fn hold_idle_poll() -> std::io::Result<()> {
    use std::io::Write;
    static HELD: std::sync::OnceLock<std::fs::File> = std::sync::OnceLock::new();
    if HELD.get().is_some() {
        return Ok(());
    }
    let mut f = std::fs::OpenOptions::new().write(true).open("/dev/cpu_dma_latency")?;
    f.write_all(&0i32.to_ne_bytes())?;
    let _ = HELD.set(f);
    Ok(())
}

/// CLOCK_MONOTONIC now, ns.
#[inline]
pub fn now_mono_ns() -> u64 {
    clock_ns(libc::CLOCK_MONOTONIC)
}

/// CLOCK_REALTIME now, ns since the Unix epoch (recorded timestamps).
#[inline]
pub fn now_wall_ns() -> u64 {
    clock_ns(libc::CLOCK_REALTIME)
}

#[inline]
fn clock_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: valid pointer to a timespec.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleep until CLOCK_MONOTONIC reaches `t_ns` (absolute, so errors do not accumulate).
#[inline]
pub fn sleep_until_mono_ns(t_ns: u64) {
    let ts = libc::timespec { tv_sec: (t_ns / 1_000_000_000) as libc::time_t, tv_nsec: (t_ns % 1_000_000_000) as libc::c_long };
    loop {
        // SAFETY: valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc != libc::EINTR {
            return;
        }
        if STOP.load(Ordering::Relaxed) {
            return;
        }
    }
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// Route SIGINT and SIGTERM to a flag the loop polls once per tick ([`stop_requested`]).
pub fn install_stop_signals() {
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

/// Value of the last SIGUSR1 (sigqueue) from the launcher: the controller process ended.
/// Encoded as `1 + exit status` or `-(signal)`, 0 = no report. See [`controller_ended`].
static CONTROLLER_ENDED: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

extern "C" fn on_controller_ended(_sig: libc::c_int, info: *mut libc::siginfo_t, _ctx: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo_t to an SA_SIGINFO handler; reading it and storing
    // to an atomic is async-signal-safe.
    let v = unsafe { (*info).si_value().sival_ptr as usize as i32 };
    CONTROLLER_ENDED.store(if v == 0 { i32::MIN } else { v }, Ordering::Relaxed);
}

/// Install the SIGUSR1 handler through which `rig` tells the plant that the controller process
/// ended (it sends `sigqueue(plant, SIGUSR1, code)` with [`encode_controller_end`]'s code).
pub fn install_controller_end_signal() {
    // SAFETY: as in install_stop_signals; the handler only reads siginfo and stores an atomic.
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
    /// stops it. `seen`: what `rig` saw of it (`messages::connect::NotConnected::code`).
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
                messages::connect::NotConnected::what(*seen)
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

/// True while a controller-end report waits to be taken (a wait should end early for it).
#[inline]
pub fn controller_end_pending() -> bool {
    CONTROLLER_ENDED.load(Ordering::Relaxed) != 0
}

/// Taken once: the controller-end report `rig` sent, if any.
pub fn take_controller_end() -> Option<ControllerEnd> {
    decode_controller_end(CONTROLLER_ENDED.swap(0, Ordering::Relaxed))
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

/// True once SIGINT or SIGTERM arrived.
#[inline]
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Request a stop from inside the process (tests, fatal conditions).
pub fn request_stop() {
    STOP.store(true, Ordering::Relaxed);
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
