//! Cost of the realistic cell (issue 23): the plant's per-tick compute of `scenarios/cell.toml`
//! with its `[sensor]` and `[drives]` sections off against the same with them on (and each alone;
//! the default scenario, at its own substeps, for reference),
//! all with the wheel pressing the strip (the rolling phase's contact path, where a run spends
//! its time). Two measures of a tick:
//! - the whole tick: [`PlantTick::advance`] and [`PlantTick::outputs`], exactly what the daemons
//!   run between receiving a torque and publishing the next state (the gate, the integrator's
//!   substeps, the cell's encoders and sensor, the reflex and end-stop checks, the strip record,
//!   the state and wrench);
//! - its parts that the sections touch: the integrator's substeps (with the cell: the friction in
//!   every stage and the stick springs' slip), then the encoders and the sensor (the tool's load,
//!   the sensor's chain).
//!
//! Criterion-free: interleaved rounds of them all, so that a loaded host slows them alike; prints
//! each one's median ns per tick and the ratio of the medians.
//!
//! `cargo bench -p plant-sim --bench cell_cost` (`-- ROUNDS TICKS`, default 21 rounds of 2000 ticks).

use std::path::Path;
use std::time::Instant;

use messages::{ControllerStatus, JointTorque, CONTRACT_VERSION};
use nalgebra::Vector3;
use plant_sim::drives::Encoders;
use plant_sim::physics::Physics;
use plant_sim::sensor::{SensorChain, ToolLoad};
use plant_sim::PlantTick;
use robot::Vec6;
use scenarios::{Mode, Scenario};

/// Force the wheel presses down with, N (the default run's set-point).
const PRESS_N: f64 = 10.0;
/// Joint damping of the bench's torque per unit of the joint's inertia, 1/s (settles the wheel on
/// the strip; proportional to M_ii so that the light wrist joints stay stable in the integrator).
const DAMPING_PER_S: f64 = 50.0;

/// The scenario `file` with `edit` applied, the wheel starting 10 µm above the strip.
fn scenario(file: &str, edit: impl Fn(&mut Scenario)) -> Scenario {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut s = Scenario::load(&root.join("scenarios").join(file)).unwrap();
    edit(&mut s);
    s.trajectory.approach_height_mm = 0.01;
    s
}

/// The bench's command at the start pose: gravity and the press (constant), and the joint
/// damping that settles the wheel on the strip.
fn command(physics: &Physics) -> (Vec6, Vec6) {
    let robot = physics.robot();
    let q = physics.q();
    let frames = robot.frames(&q);
    let jac = robot.jacobian_point(&frames, &robot.tcp_position(&frames));
    let press = jac.transpose() * Vec6::new(0.0, 0.0, -PRESS_N, 0.0, 0.0, 0.0);
    (physics.gravity_torque() + press, robot.mass_matrix(&q).diagonal() * DAMPING_PER_S)
}

/// The whole tick the daemons run: the torque through the gate, the physics, the cell's
/// sensors, the checks and the outputs.
struct Whole {
    tick: PlantTick,
    tau0: Vec6,
    damping: Vec6,
}

impl Whole {
    fn new(file: &str, edit: impl Fn(&mut Scenario)) -> Whole {
        let s = scenario(file, edit);
        let physics = Physics::new(&s, &strip::cache::cache_dir()).unwrap();
        let (tau0, damping) = command(&physics);
        Whole { tick: PlantTick::new(&s, physics, Mode::Lockstep), tau0, damping }
    }

    fn step(&mut self) {
        let tau = self.tau0 - self.tick.physics().qd().component_mul(&self.damping);
        let answer = JointTorque {
            contract_version: CONTRACT_VERSION,
            controller_status: ControllerStatus::Active as u32,
            tick: self.tick.tick(),
            controller_id: 1,
            tau: tau.into(),
        };
        std::hint::black_box(self.tick.advance(Some(std::hint::black_box(&answer))));
        std::hint::black_box(self.tick.outputs());
    }
}

/// The parts of a tick the sections touch.
struct Plant {
    physics: Physics,
    /// The constant part of the command: gravity and the press, at the start pose.
    tau0: Vec6,
    /// Joint damping, N m s/rad.
    damping: Vec6,
    sensor: Option<(SensorChain, ToolLoad)>,
    encoders: Option<Encoders>,
    out: [f64; 6],
}

impl Plant {
    /// The plant of `file` with `edit` applied to its scenario.
    fn new(file: &str, edit: impl Fn(&mut Scenario)) -> Plant {
        let s = scenario(file, edit);
        let physics = Physics::new(&s, &strip::cache::cache_dir()).unwrap();
        let (tau0, damping) = command(&physics);
        let robot = physics.robot();
        let q = physics.q();
        let period = s.loop_.period_s;
        let sensor = s.sensor.enabled.then(|| (SensorChain::new(&s.sensor, period), ToolLoad::new(robot, period)));
        let encoders = s.drives.enabled.then(|| Encoders::new(&s.drives, period, &q));
        Plant { physics, tau0, damping, sensor, encoders, out: [0.0; 6] }
    }

    /// One tick: integrate, then read the encoders and the sensor (as `tick.rs` does).
    fn tick(&mut self) {
        let tau = self.tau0 - self.physics.qd().component_mul(&self.damping);
        self.physics.step_tick(std::hint::black_box(&tau));
        if let Some(e) = self.encoders.as_mut() {
            e.update(&self.physics.q(), &self.physics.qd());
        }
        let frames = self.physics.robot().frames(&self.physics.q());
        let (f, m) = self.physics.wrench_on_tool_at(&frames.rot[6]);
        if let Some((chain, load)) = self.sensor.as_mut() {
            let l = load.sample_at(self.physics.robot(), &frames, &self.physics.qd());
            let input = std::array::from_fn(|i| if i < 3 { f[i] } else { m[i - 3] } + l[i]);
            self.out = chain.sample(&input).0;
        } else {
            self.out = [f[0], f[1], f[2], m[0], m[1], m[2]];
        }
        std::hint::black_box(&self.out);
    }
}

/// A plant the bench can tick.
trait Ticked {
    fn step(&mut self);
    fn physics(&self) -> &Physics;

    /// Mean ns per tick over `n` ticks.
    fn time(&mut self, n: usize) -> f64 {
        let t0 = Instant::now();
        for _ in 0..n {
            self.step();
        }
        t0.elapsed().as_nanos() as f64 / n as f64
    }
}

impl Ticked for Whole {
    fn step(&mut self) {
        Whole::step(self)
    }
    fn physics(&self) -> &Physics {
        self.tick.physics()
    }
}

impl Ticked for Plant {
    fn step(&mut self) {
        self.tick()
    }
    fn physics(&self) -> &Physics {
        &self.physics
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // `cargo bench` passes `--bench`; numbers are ours.
    let nums: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (rounds, ticks) = (nums.first().copied().unwrap_or(21), nums.get(1).copied().unwrap_or(2000));
    // The base is cell.toml itself with its plant sections off: the same substeps (cell.toml keeps
    // 10, the default 8) and trajectory, so the ratios are the sections' own cost. `[mismatch]` is
    // the controller's model error: nothing of it runs in the plant.
    type Edit = fn(&mut Scenario);
    let cases: [(&str, &str, Edit); 5] = [
        ("cell.toml, [sensor] and [drives] off (base)", "cell.toml", |s| (s.sensor.enabled, s.drives.enabled) = (false, false)),
        ("cell.toml (sensor, drives, mismatch on)", "cell.toml", |_| {}),
        ("cell.toml without [sensor]", "cell.toml", |s| s.sensor.enabled = false),
        ("cell.toml without [drives]", "cell.toml", |s| s.drives.enabled = false),
        ("default.toml (its 8 substeps)", "default.toml", |_| {}),
    ];
    let mut plants: Vec<(String, Box<dyn Ticked>)> = Vec::new();
    for (name, file, edit) in cases {
        plants.push((format!("whole tick, {name}"), Box::new(Whole::new(file, edit))));
    }
    for (name, file, edit) in cases {
        plants.push((format!("parts, {name}"), Box::new(Plant::new(file, edit))));
    }
    // Settle all on the strip.
    for (name, p) in plants.iter_mut() {
        p.time(2000);
        let f = Vector3::from(p.physics().wrench_on_tool().0).norm();
        println!("{name}: in contact {} (|contact force| {f:.2} N)", p.physics().in_contact());
    }
    let mut ns = vec![Vec::new(); plants.len()];
    for _ in 0..rounds {
        for (i, (_, p)) in plants.iter_mut().enumerate() {
            ns[i].push(p.time(ticks));
        }
    }
    println!("per-tick plant compute, median of {rounds} interleaved rounds of {ticks} ticks:");
    for group in [0, cases.len()] {
        let base = median(&mut ns[group]);
        for i in group..group + cases.len() {
            let m = median(&mut ns[i]);
            println!("  {}: {m:.0} ns, {:.3} of the base ({:+.1} %)", plants[i].0, m / base, (m / base - 1.0) * 100.0);
        }
    }
}
