//! The host-floor probe (`plant-sim --host-probe`, which `rig timing` passes): one thread per CPU
//! the plant may run on, pinned there, SCHED_FIFO above the loop when permitted, sleeping to
//! absolute deadlines every [`DEFAULT_PERIOD_NS`] (CLOCK_MONOTONIC, TIMER_ABSTIME; a quarter of the
//! loop's period) and doing nothing else, as cyclictest does. It sees a stall only from the first of
//! its deadlines the stall covers, so the period bounds how early a stall may have begun unseen:
//! 250 µs, against 1 ms, turns the stall that made the controller miss half its budget from a
//! quarter seen into at most 250 µs unseen. Its wake-up latency is what the host alone costs on that CPU; its stalls (a wake-up
//! later than [`HOST_STALL_NS`]) are time-stamped. It lives in the plant's process because the
//! plant is the clock master: its deadlines sit half a period after the plant's (the probe never
//! wakes when the loop does), and its latest wake-up goes into each tick's `/timing` record
//! through one atomic ([`Latest`]), so `rig report` can attribute misses from the recording alone.
//!
//! Per wake-up there is no allocation, no lock and no I/O: a histogram increment, an atomic
//! `fetch_max`, and for a stall a write into a preallocated ring.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use crate::histogram::Histogram;
pub use recordings::HOST_STALL_NS;
use rig_process::{clock, rt};

/// SCHED_FIFO priority of the probe threads: above the plant's loop (80) and the controller
/// (80), so that what it measures is the host, not the rig; it runs for a few µs per period.
pub const PROBE_PRIORITY: i32 = 90;

/// The probe's default period: four wake-ups per 1 ms tick (`plant-sim --host-probe-period-us`).
pub const DEFAULT_PERIOD_NS: u64 = 250_000;

/// Stalls kept per CPU (the most recent; the count is exact).
pub const STALL_RING: usize = 1024;

/// The latest probe wake-up since the plant last asked, ns.
#[derive(Debug, Default)]
pub struct Latest {
    late_ns: AtomicU64,
    /// The deadline (CLOCK_MONOTONIC ns) of that latest wake-up: the stall ran from there.
    at_ns: AtomicU64,
    /// The plant's first deadline (CLOCK_MONOTONIC ns), 0 until its loop starts.
    grid_ns: AtomicU64,
    /// The probe's period, ns: a stall began at most this long before the deadline it was seen at.
    period_ns: AtomicU64,
}

impl Latest {
    /// Taken once per tick by the plant (then 0 again): how late, and the deadline it was late
    /// for (a wake-up racing with the take may pair with the previous deadline: one stall late).
    #[inline]
    pub fn take(&self) -> (u64, u64) {
        let late = self.late_ns.swap(0, Ordering::Relaxed);
        (late, self.at_ns.load(Ordering::Relaxed))
    }
    /// The probe's period, ns (recorded with every tick, for the attribution).
    #[inline]
    pub fn period_ns(&self) -> u64 {
        self.period_ns.load(Ordering::Relaxed)
    }
    /// The plant's loop tells where its grid is.
    pub fn set_grid(&self, first_deadline_ns: u64) {
        self.grid_ns.store(first_deadline_ns, Ordering::Relaxed);
    }
}

/// What one CPU's probe measured.
#[derive(Debug, Clone)]
pub struct CpuReport {
    pub cpu: usize,
    /// Its period, ns.
    pub period_ns: u64,
    pub pinned: bool,
    pub sched_fifo: bool,
    pub latency: Histogram,
    /// Stalls seen (exact count) and the most recent [`STALL_RING`] of them as (deadline ns after
    /// the plant's first deadline, lateness ns), oldest first.
    pub stalls: u64,
    pub recent_stalls: Vec<(u64, u64)>,
}

/// The running probe.
pub struct Probe {
    pub latest: Arc<Latest>,
    stop: Arc<AtomicBool>,
    threads: Vec<std::thread::JoinHandle<CpuReport>>,
}

/// The CPUs the calling thread may run on.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: cpu_set_t is plain data; sched_getaffinity fills it, CPU_ISSET reads within it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return Vec::new();
        }
        (0..libc::CPU_SETSIZE as usize).filter(|&c| libc::CPU_ISSET(c, &set)).collect()
    }
}

impl Probe {
    /// One probe thread on each of `cpus`, period `period_ns`.
    pub fn start(cpus: &[usize], period_ns: u64) -> std::io::Result<Probe> {
        let latest = Arc::new(Latest::default());
        latest.period_ns.store(period_ns, Ordering::Relaxed);
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::with_capacity(cpus.len());
        for &cpu in cpus {
            let (latest, stop) = (latest.clone(), stop.clone());
            threads.push(std::thread::Builder::new().name(format!("host-probe-{cpu}")).spawn(move || run(cpu, period_ns, &latest, &stop))?);
        }
        Ok(Probe { latest, stop, threads })
    }

    /// Stop every thread (each within a period) and collect what it measured.
    pub fn finish(self) -> Vec<CpuReport> {
        self.stop.store(true, Ordering::Relaxed);
        self.threads.into_iter().filter_map(|t| t.join().ok()).collect()
    }
}

fn run(cpu: usize, period_ns: u64, latest: &Latest, stop: &AtomicBool) -> CpuReport {
    let pinned = rt::pin_thread_to_cpu(cpu);
    let sched_fifo = rt::setup_thread(Some(PROBE_PRIORITY), true).sched_fifo;
    let mut latency = Histogram::for_latency();
    let mut ring = vec![(0u64, 0u64); STALL_RING];
    let mut stalls = 0u64;
    // Wait for the plant's grid (its loop starts after the probe), polling each period.
    let grid = loop {
        let g = latest.grid_ns.load(Ordering::Relaxed);
        if g != 0 || stop.load(Ordering::Relaxed) {
            break g;
        }
        clock::sleep_until_mono_ns(clock::now_mono_ns() + period_ns);
    };
    // Half a probe period after the plant's deadlines (whose period is a multiple of the probe's),
    // so the probe never wakes when the loop does; the first one still ahead.
    let phase = grid + period_ns / 2;
    let now = clock::now_mono_ns();
    let mut next = phase + now.saturating_sub(phase).div_ceil(period_ns) * period_ns;
    while grid != 0 && !stop.load(Ordering::Relaxed) {
        clock::sleep_until_mono_ns(next);
        let woke = clock::now_mono_ns();
        let late = woke.saturating_sub(next);
        latency.record(late);
        if latest.late_ns.fetch_max(late, Ordering::Relaxed) < late {
            latest.at_ns.store(next, Ordering::Relaxed);
        }
        if late >= HOST_STALL_NS {
            ring[(stalls % STALL_RING as u64) as usize] = (next - grid, late);
            stalls += 1;
        }
        next += period_ns;
        if woke >= next {
            // A stall longer than a period: on to the next deadline ahead (no burst of wake-ups).
            next += (woke - next) / period_ns * period_ns + period_ns;
        }
    }
    let n = stalls.min(STALL_RING as u64) as usize;
    let start = if stalls > STALL_RING as u64 { (stalls % STALL_RING as u64) as usize } else { 0 };
    let recent_stalls = (0..n).map(|i| ring[(start + i) % STALL_RING]).collect();
    CpuReport { cpu, period_ns, pinned, sched_fifo, latency, stalls, recent_stalls }
}

impl CpuReport {
    /// The summary's form, its latency binned at `edges_us`.
    pub fn report(&self, edges_us: &[f64]) -> recordings::plant_summary::CpuProbe {
        recordings::plant_summary::CpuProbe {
            cpu: self.cpu,
            period_us: self.period_ns as f64 * 1e-3,
            pinned: self.pinned,
            sched_fifo: self.sched_fifo,
            latency: self.latency.distribution(edges_us),
            stalls: self.stalls,
            // [ms after the plant's first deadline, µs late]
            recent_stalls: self.recent_stalls.iter().map(|&(t, l)| (t as f64 * 1e-6, l as f64 * 1e-3)).collect(),
        }
    }
}

/// The `/events` entry a run with the probe ends with: how many stalls each CPU's probe saw
/// and the worst wake-up, so the recording itself says how much the host took (the summary
/// JSON and `rig timing` print the distributions).
pub fn summary_text(cpus: &[CpuReport]) -> String {
    let total: u64 = cpus.iter().map(|c| c.stalls).sum();
    let each: Vec<String> = cpus.iter().map(|c| format!("CPU {} {}", c.cpu, c.stalls)).collect();
    let longest = cpus.iter().max_by_key(|c| c.latency.max_ns());
    let longest =
        longest.map_or(String::new(), |c| format!("; the worst wake-up {:.3} ms late (CPU {})", c.latency.max_ns() as f64 * 1e-6, c.cpu));
    format!("host probe: {total} stalls (wake-ups {} µs or more late): {}{longest}", HOST_STALL_NS / 1000, each.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_names_each_cpus_stalls_and_the_worst_wake_up() {
        let report = |cpu, stalls, late: &[u64]| {
            let mut latency = Histogram::for_latency();
            late.iter().for_each(|&l| latency.record(l));
            CpuReport { cpu, period_ns: 250_000, pinned: true, sched_fifo: true, latency, stalls, recent_stalls: Vec::new() }
        };
        let text = summary_text(&[report(0, 3, &[5_000, 120_000, 2_500_000]), report(1, 1, &[7_000, 150_000])]);
        assert!(text.starts_with("host probe: 4 stalls (wake-ups 100 µs or more late): CPU 0 3, CPU 1 1; the worst wake-up 2."), "{text}");
        assert!(text.ends_with(" ms late (CPU 0)"), "{text}");
    }

    #[test]
    fn the_probe_wakes_on_its_grid_and_reports_every_wake_up() {
        // Real threads, real sleeps: correctness (counts, a stall recorded with its time), not timing.
        let cpus = allowed_cpus();
        assert!(!cpus.is_empty());
        let started = clock::now_mono_ns();
        let p = Probe::start(&cpus[..1], 1_000_000).unwrap();
        assert_eq!(p.latest.period_ns(), 1_000_000);
        let t0 = clock::now_mono_ns();
        p.latest.set_grid(t0);
        std::thread::sleep(std::time::Duration::from_millis(60));
        let (seen, at) = p.latest.take();
        assert!(seen == 0 || at > t0, "the stall's deadline {at} is on the probe's grid after {t0}");
        let r = p.finish();
        let lived_ns = clock::now_mono_ns() - started;
        assert_eq!(r.len(), 1);
        assert_eq!((r[0].cpu, r[0].period_ns), (cpus[0], 1_000_000));
        // One wake-up per 1 ms deadline of the probe's life at most (stalls skip deadlines), and
        // at least one: its life is the 60 ms sleep and however long this host stretched it.
        let n = r[0].latency.count();
        assert!(n > 0 && n <= lived_ns / 1_000_000 + 1, "{n} wake-ups in {lived_ns} ns");
        assert!(seen <= r[0].latency.max_ns());
        assert_eq!(r[0].recent_stalls.len() as u64, r[0].stalls.min(STALL_RING as u64));
        assert!(r[0].recent_stalls.iter().all(|&(_, late)| late >= HOST_STALL_NS));
    }
}
