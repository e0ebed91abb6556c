//! Cost of one plant tick: `loop.substeps` steps of the robot integrator (midpoint and RK4), robot
//! only and with the strip contact (default scenario), plus the once-per-tick strip record. The
//! lockstep speed target (20x real time) leaves ~50 µs per tick for plant + controller + IPC.

use criterion::{criterion_group, criterion_main, Criterion};
use plant_sim::physics::Physics;
use std::path::Path;

fn step_tick(c: &mut Criterion) {
    let mut s = scenarios::Scenario::default();
    s.strip.enabled = false;
    let mut p = Physics::new(&s, Path::new("/nonexistent")).unwrap();
    c.bench_function("physics.step_tick (robot only, default substeps)", |b| {
        b.iter(|| {
            let tau = p.gravity_torque();
            p.step_tick(std::hint::black_box(&tau));
        })
    });
    let mut s_rk4 = s.clone();
    s_rk4.loop_.integrator = scenarios::Integrator::Rk4;
    let mut p_rk4 = Physics::new(&s_rk4, Path::new("/nonexistent")).unwrap();
    c.bench_function("physics.step_tick (robot only, default substeps, rk4)", |b| {
        b.iter(|| {
            let tau = p_rk4.gravity_torque();
            p_rk4.step_tick(std::hint::black_box(&tau));
        })
    });
    let robot = p.robot().clone();
    let (q, qd) = (p.q(), p.qd());
    let tau = p.gravity_torque();
    c.bench_function("robot.forward_dynamics", |b| b.iter(|| robot.forward_dynamics(std::hint::black_box(&q), &qd, &tau)));

    let s = scenarios::Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml")).unwrap();
    let mut p = Physics::new(&s, &strip::cache::cache_dir()).unwrap();
    c.bench_function("physics.step_tick (default scenario, with strip)", |b| {
        b.iter(|| {
            let tau = p.gravity_torque();
            p.step_tick(std::hint::black_box(&tau));
        })
    });
    let mut r = recordings::StripRecord::default();
    c.bench_function("physics.fill_strip_record (default scenario)", |b| b.iter(|| p.fill_strip_record(std::hint::black_box(&mut r))));
}

criterion_group!(benches, step_tick);
criterion_main!(benches);
