//! Cost of one controller tick (`controller::daemon::step`: references, kinematics, inverse
//! dynamics, diagnostics) at the scenario's start pose, in free motion and in force control.
use controller::daemon::step;
use controller::gains::Gains;
use controller::law::ControlLaw;
use controller::reference::{ReferenceGenerator, ReferenceParams};
use controller::step::controller_robot;
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use messages::{JointState, Wrench, WrenchFrame, CONTRACT_VERSION};
use robot::Vec6;
use scenarios::geometry::{self, tool_down_rotation, TaskFrame};
use scenarios::Scenario;

fn bench(c: &mut Criterion) {
    let s = Scenario::default();
    let robot = controller_robot(&s);
    let task = TaskFrame::from_scenario(&s);
    let p = ReferenceParams::from_scenario(&s);
    let q = robot.ik_tcp(&geometry::start_tcp_pose(&s), &robot::ik_seed_tool_down()).unwrap();
    let qd = Vec6::new(0.01, -0.02, 0.01, 0.0, 0.02, 0.0);
    let mut law = ControlLaw::new(robot, task, Gains::from_scenario(&s, f64::NAN), tool_down_rotation());
    let mut reference = ReferenceGenerator::new(p);
    let state = |tick: u64| JointState {
        contract_version: CONTRACT_VERSION,
        plant_status: 1,
        tick,
        sim_time_s: tick as f64 * 1e-3,
        q: q.into(),
        qd: qd.into(),
        tau_applied: [0.0; 6],
        period_s: 1e-3,
        flags: 0,
        consecutive_misses: 0,
        total_misses: 0,
    };
    let free =
        Wrench { contract_version: CONTRACT_VERSION, frame: WrenchFrame::SensorAtTcp as u32, tick: 0, force: [0.0; 3], torque: [0.0; 3] };
    let mut tick = 0;
    c.bench_function("controller_step_free_motion", |bn| {
        bn.iter(|| {
            tick += 1;
            black_box(step(&mut law, &mut reference, &state(1), &free, &q, &qd, CONTRACT_VERSION))
        })
    });
    // Drive the reference into force control (contact detected), then time the contact tick.
    let pressing = Wrench { force: [0.0, 0.0, -10.0], ..free };
    for k in 0..400 {
        step(&mut law, &mut reference, &state(k), &pressing, &q, &qd, CONTRACT_VERSION);
    }
    c.bench_function("controller_step_force_control", |bn| {
        bn.iter(|| black_box(step(&mut law, &mut reference, &state(400), &pressing, &q, &qd, CONTRACT_VERSION)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
