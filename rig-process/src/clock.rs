//! The rig's clocks, read once here for every process: CLOCK_MONOTONIC for stage stamps and
//! deadlines (the contract's stage stamps, `messages::ControllerDiagnostics`, are on it: one
//! clock on one host), CLOCK_REALTIME for recorded timestamps. vDSO calls, no syscall (about
//! 20-30 ns).

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
        // Interrupted by a signal: sleep on to the same deadline (a stop is seen at the next tick).
        if rc != libc::EINTR {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_advances_and_sleep_reaches_its_deadline() {
        let t0 = now_mono_ns();
        sleep_until_mono_ns(t0 + 1_000_000);
        assert!(now_mono_ns() >= t0 + 1_000_000);
        // after 2020-01-01 (1.577e18 ns since the epoch)
        assert!(now_wall_ns() > 1_577_836_800_000_000_000);
    }
}
