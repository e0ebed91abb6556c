//! Operating-system knobs of a real-time loop thread (Linux), written once for the plant and the
//! controller: timer slack, SCHED_FIFO, mlockall, CPU affinity, nice, the idle-poll latency
//! request. The clocks and absolute sleeps are [`crate::clock`]'s.

/// What the real-time set-up achieved (logged once at start).
#[derive(Debug, Clone, Copy, Default)]
pub struct RtSetup {
    pub timer_slack_1ns: bool,
    pub sched_fifo: bool,
    /// Why SCHED_FIFO was refused: the error number `pthread_setschedparam` returned (0 when
    /// granted or not requested).
    pub sched_fifo_errno: i32,
    pub mlockall: bool,
}

/// Prepare the calling thread: timer slack 1 ns (so absolute sleeps wake on time instead of up to
/// 50 µs late), SCHED_FIFO at `priority` (None = keep the normal policy) and, with
/// `lock_memory`, locked memory when the process may (CAP_SYS_NICE / rtprio limits, CAP_IPC_LOCK /
/// memlock limits). Failures are reported, not fatal.
pub fn setup_thread(priority: Option<i32>, lock_memory: bool) -> RtSetup {
    let mut r = RtSetup::default();
    // SAFETY: plain syscalls on the calling thread/process with valid arguments.
    unsafe {
        r.timer_slack_1ns = libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) == 0;
        if let Some(priority) = priority {
            let param = libc::sched_param { sched_priority: priority };
            r.sched_fifo_errno = libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param);
            r.sched_fifo = r.sched_fifo_errno == 0;
        }
        r.mlockall = lock_memory && libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0;
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

/// The kernel's cpuidle driver (`/sys/devices/system/cpu/cpuidle/current_driver`), None when it
/// has none. Only a cpuidle governor reads the PM QoS CPU latency request: without a driver an
/// idle CPU runs the architecture's default idle (`hlt`) whatever the request says (the
/// development VM: driver `none`, and `perf` finds the idle vCPU in `pv_native_safe_halt` while
/// the request is held).
pub fn cpuidle_driver() -> Option<String> {
    let d = std::fs::read_to_string("/sys/devices/system/cpu/cpuidle/current_driver").ok()?;
    let d = d.trim();
    (!d.is_empty() && d != "none").then(|| d.to_string())
}

/// Hold the kernel's PM QoS CPU latency request at 0 µs for the rest of the process, as cyclictest
/// does: idle CPUs then poll instead of halting, so a wake-up (the controller's notification, the
/// tick timer) costs a few µs instead of a vCPU exit and an inter-processor interrupt (tens of µs
/// on a VM), where the kernel has a cpuidle driver ([`cpuidle_driver`]). The request lasts while
/// the file stays open; the kernel drops it when we exit.
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
