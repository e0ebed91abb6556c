//! ns per call of the model's hot paths (compare: native Pinocchio on this machine, same 6-DOF
//! model, about 800 ns RNEA, 400 ns CRBA, 1500 ns ABA).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use robot::{Robot, Tool, Vec6};

fn bench(c: &mut Criterion) {
    let robot = Robot::irb2400_with_tool(Tool::default());
    let q = Vec6::new(0.1, -1.2, 0.4, 0.2, 0.9, -0.3);
    let qd = Vec6::new(0.5, -0.3, 0.4, 1.0, -1.5, 2.0);
    let qdd = Vec6::new(1.0, 2.0, -1.0, 3.0, 0.5, -2.0);
    let tau = robot.rnea(&q, &qd, &qdd);
    c.bench_function("rnea", |b| b.iter(|| robot.rnea(black_box(&q), black_box(&qd), black_box(&qdd))));
    c.bench_function("crba", |b| b.iter(|| robot.mass_matrix(black_box(&q))));
    c.bench_function("forward_dynamics", |b| b.iter(|| robot.forward_dynamics(black_box(&q), black_box(&qd), black_box(&tau))));
    c.bench_function("jacobian_tcp", |b| b.iter(|| robot.jacobian_tcp(black_box(&q))));
    c.bench_function("jdot_qdot_tcp", |b| b.iter(|| robot.jdot_qdot_tcp(black_box(&q), black_box(&qd))));
    c.bench_function("gravity_torque", |b| b.iter(|| robot.gravity_torque(black_box(&q))));
    c.bench_function("mass_matrix_and_bias", |b| b.iter(|| robot.mass_matrix_and_bias(black_box(&q), black_box(&qd))));
    c.bench_function("frames", |b| b.iter(|| robot.frames(black_box(&q))));
}

criterion_group!(benches, bench);
criterion_main!(benches);
