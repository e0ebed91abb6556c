//! Recorder costs (issue 5 benchmarks):
//! 1. `record_tick` on the loop thread, at 1 kHz with the writer running: p50/p99/p99.9/max.
//! 2. Writer thread CPU share at 1 kHz (from /proc/self/task/<tid>/schedstat, ns resolution).
//! 3. File size per minute with every channel.
//! 4. criterion: the writer's encoding of one tick (all channels) and the writer's throughput.
//!
//! Run: `cargo bench -p recordings --bench recorder` (about 30 s).

use criterion::{black_box, Criterion};
use recordings::synthetic::SyntheticRun;
use recordings::{Recorder, RecorderConfig};
use std::time::{Duration, Instant};

/// CPU time (ns) of the thread named `name` in this process.
fn thread_cpu_ns(name: &str) -> Option<u64> {
    for t in std::fs::read_dir("/proc/self/task").ok()? {
        let dir = t.ok()?.path();
        let comm = std::fs::read_to_string(dir.join("comm")).ok()?;
        if comm.trim() == name {
            let s = std::fs::read_to_string(dir.join("schedstat")).ok()?;
            return s.split_whitespace().next()?.parse().ok();
        }
    }
    None
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    sorted[((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1] as f64
}

/// `seconds` of 1 kHz ticks pushed on a paced loop while the writer runs.
fn paced_run(n_centreline: usize, seconds: f64) {
    let run = SyntheticRun { ticks: (seconds * 1000.0) as u64, n_centreline, roll_ticks: (seconds * 600.0) as u64, ..Default::default() };
    let dir = std::env::temp_dir().join(format!("recordings-bench-{}", std::process::id()));
    let path = dir.join(format!("bench-{n_centreline}.mcap"));
    let mut cfg = RecorderConfig::new(&path, run.metadata());
    if let Ok(q) = std::env::var("QUEUE") {
        cfg.queue_capacity = q.parse().unwrap();
    }
    let mut rec = Recorder::start(cfg).unwrap();
    std::thread::sleep(Duration::from_millis(50));
    let cpu0 = thread_cpu_ns("recorder");
    let mut cost_ns = Vec::with_capacity(run.ticks as usize);
    let t0 = Instant::now();
    for k in 0..run.ticks as usize {
        let due = t0 + Duration::from_micros(1000 * k as u64);
        while Instant::now() < due {
            if let Some(d) = due.checked_duration_since(Instant::now()) {
                if d > Duration::from_micros(100) {
                    std::thread::sleep(d - Duration::from_micros(60));
                }
            }
        }
        // Built on the loop thread just before the push, as the plant does (not timed).
        let r = run.tick(k as u64);
        let a = Instant::now();
        let ok = rec.record_tick(black_box(&r));
        cost_ns.push(a.elapsed().as_nanos() as u64);
        assert!(ok, "dropped tick {k}");
    }
    let wall = t0.elapsed();
    let cpu1 = thread_cpu_ns("recorder");
    let summary = rec.finish().unwrap();
    cost_ns.sort_unstable();
    let mb_per_min = summary.bytes as f64 / 1e6 / (run.ticks as f64 * run.period_s / 60.0);
    println!(
        "record_tick @1 kHz, {n_centreline} centre-line nodes, {} ticks: p50 {:.0} ns, p99 {:.0} ns, p99.9 {:.0} ns, max {:.0} ns",
        cost_ns.len(),
        percentile(&cost_ns, 0.5),
        percentile(&cost_ns, 0.99),
        percentile(&cost_ns, 0.999),
        *cost_ns.last().unwrap() as f64
    );
    match (cpu0, cpu1) {
        (Some(a), Some(b)) => println!(
            "writer CPU share @1 kHz: {:.2} % of one core ({:.1} ms CPU over {:.2} s)",
            (b - a) as f64 / wall.as_nanos() as f64 * 100.0,
            (b - a) as f64 * 1e-6,
            wall.as_secs_f64()
        ),
        _ => println!("writer CPU share: /proc/self/task/*/schedstat not available"),
    }
    println!(
        "file size: {} bytes for {:.1} s = {:.2} MB/min (dropped {}, finalised {})",
        summary.bytes,
        run.ticks as f64 * run.period_s,
        mb_per_min,
        summary.dropped_ticks,
        summary.finalised
    );
    let _ = std::fs::remove_file(&path);
}

fn criterion_benches(c: &mut Criterion) {
    let run = SyntheticRun::default();
    let full = run.tick(1234);
    let r = recordings::schema::TickHead::of(&full);
    let p: Vec<f32> = full.strip.centreline().iter().map(|&p| p as f32).collect();
    let z: Vec<f32> = run.centreline_z_m().iter().map(|&z| z as f32).collect();
    let mut buf = Vec::with_capacity(4096);
    c.bench_function("encode one tick, all channels (writer thread)", |b| {
        b.iter(|| {
            let r = black_box(&r);
            recordings::schema::encode_joint_state(&mut buf, r);
            recordings::schema::encode_joint_torque(&mut buf, r);
            recordings::schema::encode_wrench(&mut buf, r);
            recordings::schema::encode_strip(&mut buf, r, &p, &z);
            recordings::schema::encode_controller(&mut buf, r);
            recordings::schema::encode_timing(&mut buf, r, 0);
            black_box(buf.len())
        })
    });
    // record_tick back to back, waiting for queue space: this measures the WRITER's throughput
    // (encode + zstd + write per tick), i.e. how much faster than 1 kHz it can keep up.
    let dir = std::env::temp_dir().join(format!("recordings-bench-c-{}", std::process::id()));
    let mut cfg = RecorderConfig::new(dir.join("c.mcap"), run.metadata());
    cfg.queue_capacity = 1 << 16;
    let mut rec = Recorder::start(cfg).unwrap();
    c.bench_function("writer throughput: one tick end to end (record_tick back to back)", |b| {
        b.iter(|| {
            while rec.queue_free() == 0 {
                std::thread::yield_now();
            }
            rec.record_tick(black_box(&full))
        })
    });
    let s = rec.finish().unwrap();
    println!("(criterion record_tick run: {} ticks written, {} dropped)", s.ticks_written, s.dropped_ticks);
}

fn main() {
    println!("TickRecord: {} bytes", std::mem::size_of::<recordings::TickRecord>());
    paced_run(81, 10.0);
    if std::env::var("ONLY_81").is_ok() {
        return;
    }
    paced_run(256, 5.0);
    let mut c = Criterion::default().configure_from_args().measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    criterion_benches(&mut c);
    c.final_summary();
}
