//! The realistic cell of issue 23, end to end: `rig run` starts the real daemons in lockstep, the
//! checks read the MCAP recording back. The sensor's stages are checked one at a time against
//! their closed forms (the other stages off), the shipped `scenarios/cell.toml` against the
//! thesis' 0.45 N on the TRUE bottom force. Build first: `cargo build --release --workspace --bins`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use harness::*;
use nalgebra::Vector3;
use recording_tools::read::Recording;
use scenarios::Scenario;

const LONG: Duration = Duration::from_secs(300);

fn scenario_file(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenarios").join(name)
}

/// `rig run <file> --mode lockstep`; its exit status must be 0; the recording and the scenario.
fn lockstep(tag: &str, text: &str) -> (Recording, Scenario) {
    lockstep_with(tag, text, &[])
}

/// [`lockstep`] with more `rig run` arguments.
fn lockstep_with(tag: &str, text: &str, extra: &[&str]) -> (Recording, Scenario) {
    let rig = unique_rig(tag);
    let dir = temp_dir(&rig);
    let file = dir.join("scenario.toml");
    std::fs::write(&file, text).unwrap();
    let s = Scenario::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let out = dir.join("out");
    let mut args = vec!["run", file.to_str().unwrap(), "--mode", "lockstep", "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let mut run = Daemon::start("rig", &bin("rig"), &args, &dir);
    let st = run.expect_exit(LONG);
    assert!(st.success(), "{tag}: rig run failed ({st}):\n{}\n{}", run.stdout(), run.stderr());
    (Recording::open_complete(out.join("run.mcap")).expect("complete recording"), s)
}

/// The default servo run with a `[sensor]` section (`sensor`: its lines) and the controller's
/// tool load compensation on.
fn servo_with(sensor: &str) -> String {
    let text = std::fs::read_to_string(scenario_file("default.toml")).unwrap();
    format!("{}\n[sensor]\nenabled = true\n{sensor}", text.replace("[controller]\n", "[controller]\ntool_load_compensation = true\n"))
}

/// The hold runs' controller: joint-space computed torque holding the first state's q, which
/// never reads the wrench (so the sensor's noise does not move the arm); a wrapper gives it 5 s
/// of patience with a loaded host.
fn hold_controller() -> String {
    hold_controller_with(&[])
}

/// [`hold_controller`] with more hold-controller arguments (`--free-joint1`, `--waypoints`, ...).
fn hold_controller_with(extra: &[&str]) -> String {
    use std::os::unix::fs::PermissionsExt;
    let dir = temp_dir(&unique_rig("hold-wrapper"));
    let path = dir.join("hold-patient");
    let extra: String = extra.iter().map(|a| format!(" '{a}'")).collect();
    std::fs::write(&path, format!("#!/bin/sh\nexec {} --silence-ms 5000{extra} \"$@\"\n", bin("hold-controller").display())).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path.to_str().unwrap().to_string()
}

/// Robot alone for `duration_s`, with `sections` (held by [`hold_controller`]).
fn hold_with(duration_s: f64, sections: &str) -> String {
    format!("description = \"hold\"\n[strip]\nenabled = false\n[loop]\nduration_s = {duration_s}\n{sections}")
}

/// Per tick: the reading less the plant tool's gravity load at the recorded q (tool axes).
fn reading_less_tool_weight(rec: &Recording, s: &Scenario) -> Vec<[f64; 6]> {
    let robot = plant_sim::physics::plant_robot(s);
    let tool = *robot.tool().unwrap();
    rec.joint_state
        .iter()
        .zip(&rec.wrench)
        .map(|(st, w)| {
            let rot = robot.frames(&robot::Vec6::from(st.q)).rot[6];
            let g = plant_sim::sensor::gravity_load(tool.mass_kg, &tool.com_flange_m, &tool.tcp_offset_flange_m, &rot);
            let x = [w.force[0], w.force[1], w.force[2], w.torque[0], w.torque[1], w.torque[2]];
            std::array::from_fn(|i| x[i] - g[i])
        })
        .collect()
}

/// The reading's force on the strip along task y (N, negative pressing), per tick.
fn reading_task_y(rec: &Recording, s: &Scenario) -> Vec<f64> {
    let robot = plant_sim::physics::plant_robot(s);
    let task = scenarios::geometry::TaskFrame::from_scenario(s);
    reading_less_tool_weight(rec, s)
        .iter()
        .zip(&rec.joint_state)
        .map(|(x, st)| {
            let rot = robot.frames(&robot::Vec6::from(st.q)).rot[6];
            -task.vector_to_task(&(rot * Vector3::new(x[0], x[1], x[2]))).y
        })
        .collect()
}

/// The true contact force of each tick's state: the strip record of tick k is the state after
/// tick k was integrated, i.e. tick k + 1's.
fn true_task_y(rec: &Recording) -> Vec<f64> {
    let mut t = vec![0.0];
    t.extend(rec.strip.iter().map(|s| s.contact_force_n));
    t.truncate(rec.wrench.len());
    t
}

#[test]
fn the_shipped_cell_keeps_the_true_bottom_force_within_the_thesis_bound() {
    let text = std::fs::read_to_string(scenario_file("cell.toml")).unwrap();
    let (rec, s) = lockstep("cell", &text);
    assert!(s.sensor.enabled && s.drives.enabled && !s.mismatch.is_none());
    let t = recording_tools::report::force_tracking(&rec).expect("a rolling phase");
    eprintln!("cell.toml lockstep: true bottom force error max {:.4} N, RMS {:.4} N", t.max_abs_n, t.rms_n);
    assert!(t.max_abs_n <= 0.45, "max {} N", t.max_abs_n);
    assert!(t.samples > 1900, "{} rolling ticks", t.samples);
    // Seeded: the same seed again is the same run bit for bit, another seed another run.
    let (again, _) = lockstep("cell-again", &text);
    assert_eq!(physics_digest(&rec), physics_digest(&again));
    let (other, _) = lockstep("cell-seed2", &text.replace("seed = 1\n", "seed = 2\n"));
    assert_ne!(physics_digest(&rec), physics_digest(&other));
}

/// An untared sensor's offset is its bias (drawn from the seed); every reading is a whole number
/// of quantisation steps.
#[test]
fn an_untared_sensor_reads_its_bias_in_whole_steps() {
    let sensor = "[sensor]\nenabled = true\nseed = 7\nbias_range = [0.4, 0.4, 1.2, 0.02, 0.02, 0.02]\nresolution = [0.005, 0.005, 0.01, 0.000125, 0.000125, 0.000125]\n";
    let (rec, s) = lockstep_with("cell-bias", &hold_with(0.5, sensor), &["--controller", &hold_controller()]);
    let bias = plant_sim::sensor::SensorChain::new(&s.sensor, s.loop_.period_s).bias();
    assert!(bias.iter().all(|b| b.abs() > 0.0));
    for (k, (x, w)) in reading_less_tool_weight(&rec, &s).iter().zip(&rec.wrench).enumerate() {
        let raw = [w.force[0], w.force[1], w.force[2], w.torque[0], w.torque[1], w.torque[2]];
        for i in 0..6 {
            let q = s.sensor.resolution[i];
            let steps = raw[i] / q;
            assert!((steps - steps.round()).abs() < 1e-6, "tick {k} axis {i}: {} is not a whole number of {q}", raw[i]);
            assert!((x[i] - bias[i]).abs() <= 0.5 * q + 1e-6, "tick {k} axis {i}: offset {} against bias {}", x[i], bias[i]);
        }
    }
}

/// Noise: over 1e5 samples its standard deviation is the stated one within 5 % on every axis,
/// and it is white (the first lags' autocorrelation within 4/√n of zero: a flat spectrum).
#[test]
fn the_noise_has_its_stated_deviation_and_is_white() {
    let sd = [0.005, 0.005, 0.01, 0.000125, 0.000125, 0.000125];
    let sensor = format!("[sensor]\nenabled = true\nseed = 3\nnoise_sd = {sd:?}\n");
    let (rec, s) = lockstep_with("cell-noise", &hold_with(100.0, &sensor), &["--controller", &hold_controller()]);
    let x = reading_less_tool_weight(&rec, &s);
    let n = x.len();
    assert!(n >= 100_000, "{n} samples");
    for i in 0..6 {
        let mean = x.iter().map(|v| v[i]).sum::<f64>() / n as f64;
        let var = x.iter().map(|v| (v[i] - mean).powi(2)).sum::<f64>() / n as f64;
        let sigma = var.sqrt();
        eprintln!("axis {i}: sigma {sigma:.6e} (stated {:.6e})", sd[i]);
        assert!((sigma / sd[i] - 1.0).abs() < 0.05, "axis {i}: sigma {sigma}");
        for lag in 1..=5 {
            let r = x.windows(lag + 1).map(|w| (w[0][i] - mean) * (w[lag][i] - mean)).sum::<f64>() / (n as f64 * var);
            assert!(r.abs() < 4.0 / (n as f64).sqrt(), "axis {i}: autocorrelation {r} at lag {lag}");
        }
    }
}

/// Lag (ticks) at which `measured[k]` best matches `truth[k - lag]`: the peak of the
/// cross-correlation of their tick-to-tick changes (the signals themselves are slow ramps whose
/// correlation is too broad to resolve one tick).
fn best_lag(measured: &[f64], truth: &[f64]) -> usize {
    let d = |v: &[f64]| v.windows(2).map(|w| w[1] - w[0]).collect::<Vec<f64>>();
    let (m, t) = (d(measured), d(truth));
    let c = |lag: usize| (lag..m.len()).map(|k| m[k] * t[k - lag]).sum::<f64>();
    (0..20).max_by(|&a, &b| c(a).total_cmp(&c(b))).unwrap()
}

/// The sample delay found by cross-correlating the reading against the true force is the
/// stated one (and zero without it).
#[test]
fn the_delay_is_the_stated_one_by_cross_correlation() {
    for delay in [0, 3] {
        let (rec, s) = lockstep(&format!("cell-delay{delay}"), &servo_with(&format!("delay_ticks = {delay}\n")));
        let lag = best_lag(&reading_task_y(&rec, &s), &true_task_y(&rec));
        eprintln!("delay {delay}: cross-correlation peak at {lag} ticks");
        assert_eq!(lag, delay);
    }
}

/// The sensor's low-pass: the ratio of the reading's and the true force's DFTs over the whole
/// run (both start and end at rest off the strip) at two frequencies against the closed form
/// H = α / (1 − (1 − α) e^{−jωT}).
#[test]
fn the_filter_has_its_closed_form_gain_and_phase() {
    let (rec, s) = lockstep("cell-filter", &servo_with("lowpass_hz = 30\n"));
    // What enters the filter: the contact force and the tool's whole load (gravity and inertia,
    // recomputed from the recorded states as the plant does); what leaves it: the raw reading.
    let robot = plant_sim::physics::plant_robot(&s);
    let task = scenarios::geometry::TaskFrame::from_scenario(&s);
    let mut load = plant_sim::sensor::ToolLoad::new(&robot, s.loop_.period_s);
    let on_strip_y = |q: &[f64; 6], f: Vector3<f64>| -task.vector_to_task(&(robot.frames(&robot::Vec6::from(*q)).rot[6] * f)).y;
    let y: Vec<f64> = rec.joint_state.iter().zip(&rec.wrench).map(|(st, w)| on_strip_y(&st.q, Vector3::from(w.force))).collect();
    let x: Vec<f64> = rec
        .joint_state
        .iter()
        .zip(true_task_y(&rec))
        .map(|(st, c)| {
            let l = load.sample(&robot, &robot::Vec6::from(st.q), &robot::Vec6::from(st.qd));
            c + on_strip_y(&st.q, Vector3::new(l[0], l[1], l[2]))
        })
        .collect();
    let n = x.len();
    let t = s.loop_.period_s;
    let alpha = 1.0 - (-std::f64::consts::TAU * 30.0 * t).exp();
    for cycles in [8.0, 60.0] {
        // whole cycles over the window: the constant tool load leaks nothing
        let f = cycles / (n as f64 * t);
        let w = std::f64::consts::TAU * f * t;
        let dft = |v: &[f64]| {
            v.iter()
                .enumerate()
                .fold((0.0, 0.0), |(re, im), (k, a)| (re + (a - v[0]) * (w * k as f64).cos(), im - (a - v[0]) * (w * k as f64).sin()))
        };
        let ((yr, yi), (xr, xi)) = (dft(&y), dft(&x));
        let d = xr * xr + xi * xi;
        let (hr, hi) = ((yr * xr + yi * xi) / d, (yi * xr - yr * xi) / d);
        let (gain, phase) = ((hr * hr + hi * hi).sqrt(), hi.atan2(hr));
        let (cr, ci) = (1.0 - (1.0 - alpha) * w.cos(), (1.0 - alpha) * w.sin());
        let (want_gain, want_phase) = (alpha / (cr * cr + ci * ci).sqrt(), -ci.atan2(cr));
        eprintln!(
            "{f:.2} Hz: gain {gain:.4} (closed form {want_gain:.4}), phase {:.2} deg ({:.2})",
            phase.to_degrees(),
            want_phase.to_degrees()
        );
        assert!((gain / want_gain - 1.0).abs() < 0.02, "{f} Hz: gain {gain} vs {want_gain}");
        assert!((phase - want_phase).abs() < 2f64.to_radians(), "{f} Hz: phase {phase} vs {want_phase}");
    }
}

/// The tool's load on the sensor against m g, end to end: the hold visits three orientations of
/// the tool (tool down, then joints 4 and 5 turned), the sensor with every stage off reads the
/// whole tool hanging on it. At rest, in each orientation, the force in base axes is (0, 0, −m g)
/// and the moment about the TCP is (c − p) × F in tool axes, c the tool's centre; while moving,
/// the force is m (g − a) with a the centre's acceleration from second differences of its
/// recorded positions (forward kinematics of the recorded q, not the plant's Jacobian).
#[test]
fn the_tool_loads_the_sensor_with_m_g_in_three_orientations_and_m_a_while_moving() {
    let (move_s, dwell_s) = (3.0, 1.0);
    let duration = dwell_s + 2.0 * (move_s + dwell_s);
    let waypoints = "0,0,0,0.6,0.5,0;0,0,0,-0.5,-0.6,1";
    let controller = hold_controller_with(&["--waypoints", waypoints, "--move-s", "3", "--dwell-s", "1"]);
    let (rec, s) = lockstep_with("cell-toolload", &hold_with(duration, "[sensor]\nenabled = true\n"), &["--controller", &controller]);
    let robot = plant_sim::physics::plant_robot(&s);
    let tool = *robot.tool().unwrap();
    let m = s.robot.tool_mass_kg;
    assert_eq!(tool.mass_kg, m);
    let t = s.loop_.period_s;
    let g = Vector3::new(0.0, 0.0, -robot::Robot::GRAVITY_MPS2);
    let states: Vec<(nalgebra::Matrix3<f64>, Vector3<f64>)> = rec
        .joint_state
        .iter()
        .map(|st| {
            let f = robot.frames(&robot::Vec6::from(st.q));
            (f.rot[6], f.pos[6] + f.rot[6] * tool.com_flange_m)
        })
        .collect();
    let reading = |k: usize| {
        let w = &rec.wrench[k];
        (Vector3::from(w.force), Vector3::from(w.torque))
    };
    assert_eq!(rec.wrench.len(), rec.joint_state.len());
    // At rest: the last 0.3 s of each dwell.
    let mut directions = Vec::new();
    for k in 0..3 {
        let end = ((dwell_s + k as f64 * (move_s + dwell_s)) / t).round() as usize;
        let (mut worst_f, mut worst_m) = (0.0f64, 0.0f64);
        for (i, (rot, _)) in states.iter().enumerate().take(end).skip(end - 300) {
            let (f, mo) = reading(i);
            worst_f = worst_f.max((rot * f - g * m).norm());
            worst_m = worst_m.max((mo - (tool.com_flange_m - tool.tcp_offset_flange_m).cross(&f)).norm());
        }
        let (f, _) = reading(end - 1);
        eprintln!(
            "orientation {k}: tool axes F = ({:.4}, {:.4}, {:.4}) N, |F| = {:.6} N (m g = {:.6} N); worst |R F - m g| {worst_f:.2e} N, moment {worst_m:.2e} N m",
            f.x,
            f.y,
            f.z,
            f.norm(),
            m * robot::Robot::GRAVITY_MPS2
        );
        assert!(worst_f < 1e-6, "orientation {k}: force off m g by {worst_f} N");
        assert!(worst_m < 1e-7, "orientation {k}: moment off (c - p) x F by {worst_m} N m");
        directions.push(f.normalize());
    }
    // Three orientations of the tool against gravity, pairwise at least 0.5 rad apart.
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let angle = directions[a].dot(&directions[b]).clamp(-1.0, 1.0).acos();
        assert!(angle > 0.5, "orientations {a} and {b} only {angle} rad apart");
    }
    // Moving: the plant's acceleration over tick k is (v_k − v_{k−1})/T, i.e. a(t_k − T/2): the mean
    // of the central second differences of the centre's positions at k − 1 and k.
    let (mut worst, mut peak) = (0.0f64, 0.0f64);
    for i in 2..states.len() - 1 {
        let p = |j: usize| states[j].1;
        let a = ((p(i + 1) - p(i) * 2.0 + p(i - 1)) + (p(i) - p(i - 1) * 2.0 + p(i - 2))) / (2.0 * t * t);
        let (rot, _) = states[i];
        let (f, _) = reading(i);
        peak = peak.max((a * m).norm());
        worst = worst.max((rot * f - (g - a) * m).norm());
    }
    eprintln!("moving: peak m|a| {peak:.4} N, worst |R F - m (g - a)| {worst:.2e} N");
    assert!(peak > 0.05, "the moves are too gentle to show the inertial load: {peak} N");
    assert!(worst < 0.005 * peak, "inertial load off by {worst} N (peak {peak} N)");
}

/// Drives end to end: joint 1 (vertical axis, no gravity) left to a constant torque by the hold
/// controller (`--free-joint1`), the other joints held. Under 0.8 of its breakaway it does not
/// move by one encoder count from 0.2 s to 1.2 s; under twice its breakaway its recorded angle
/// follows the closed-form joint M₁₁ q̈ = τ − F(q̇) − b q̇ with F the Stribeck curve
/// τ_c + (τ_s − τ_c) exp(−(q̇/v_s)²) and b the viscous friction, integrated from the recorded
/// applied torque; every recorded q is a whole number of encoder counts (the quantisation step).
#[test]
fn a_joint_sticks_below_breakaway_and_accelerates_above_it_as_the_closed_form_says() {
    let (tc, ts, vs, b) = (5.0, 6.5, 0.01, 2.0);
    let drives = format!(
        "[drives]\nenabled = true\ncoulomb_nm = [{tc}, 5, 2.5, 0.3, 0.3, 0.15]\nbreakaway_nm = [{ts}, 6.5, 3.25, 0.4, 0.4, 0.2]\n\
         stribeck_radps = [{vs}, 0.01, 0.01, 0.02, 0.02, 0.02]\nviscous_nms = [{b}, 2, 1, 0.1, 0.1, 0.05]\n\
         encoder_counts_per_rev = [4194304, 4194304, 4194304, 4194304, 4194304, 4194304]\nvelocity_filter_hz = 100\n"
    );
    let count = std::f64::consts::TAU / 4_194_304.0;
    let run = |tag: &str, tau: f64, duration: f64| {
        let controller = hold_controller_with(&["--free-joint1", "--offset-nm", &tau.to_string()]);
        lockstep_with(tag, &hold_with(duration, &drives), &["--controller", &controller])
    };
    let whole_counts = |rec: &Recording| {
        for st in &rec.joint_state {
            for (j, q) in st.q.iter().enumerate() {
                let c = q / count;
                assert!((c - c.round()).abs() < 1e-6, "tick {} joint {}: {q} rad is not a whole number of counts", st.tick, j + 1);
            }
        }
    };

    let (held, _) = run("cell-stick", 0.8 * ts, 1.3);
    whole_counts(&held);
    let drift = (held.joint_state[1200].q[0] - held.joint_state[200].q[0]).abs();
    eprintln!("joint 1 at 0.8 breakaway: encoder drift {drift:.3e} rad over 1 s (one count {count:.3e} rad)");
    assert!(drift < count, "drift {drift} rad");

    let (moving, s) = run("cell-slide", 2.0 * ts, 0.7);
    whole_counts(&moving);
    let robot = plant_sim::physics::plant_robot(&s);
    let q0 = robot::Vec6::from(moving.joint_state[0].q);
    let m11 = robot.mass_matrix(&q0)[(0, 0)];
    let b = b + s.robot.viscous_nms[0];
    let period = s.loop_.period_s;
    // The scalar joint, stuck while |τ| ≤ τ_s at rest, through each tick's applied torque
    // (JointState k + 1's tau_applied is what acted over tick k), 1000 Euler steps per tick.
    let (mut q, mut v) = (0.0f64, 0.0f64);
    let mut model = vec![(0.0, 0.0)];
    for st in &moving.joint_state[1..] {
        let tau = st.tau_applied[0];
        let h = period / 1000.0;
        for _ in 0..1000 {
            let level = tc + (ts - tc) * (-(v / vs).powi(2)).exp();
            let a = if v == 0.0 && tau.abs() <= ts {
                0.0
            } else {
                (tau - level * if v == 0.0 { tau.signum() } else { v.signum() } - b * v) / m11
            };
            let v_new = v + a * h;
            // friction does not reverse the motion within a step
            v = if v != 0.0 && v_new * v < 0.0 { 0.0 } else { v_new };
            q += v * h;
        }
        model.push((q, v));
    }
    // The closed form is the sliding joint's: compared from 0.1 s on, after the breakaway (the
    // stick spring's pre-sliding deflection, about τ_s/k = 2e-5 rad, and its release are the stick
    // model's, not the closed form's), the angle moved since then and the drive's speed estimate.
    let k0 = 100;
    let mut worst = 0.0f64;
    for k in [200usize, 300, 400, 500, 600, 699] {
        let got = moving.joint_state[k].q[0] - moving.joint_state[k0].q[0];
        let want = model[k].0 - model[k0].0;
        let (got_v, want_v) = (moving.joint_state[k].qd[0], model[k].1);
        eprintln!(
            "joint 1 at twice breakaway, {:.1} s: moved {got:.6} rad since 0.1 s (closed form {want:.6}), speed estimate {got_v:.5} rad/s ({want_v:.5})",
            k as f64 * period
        );
        worst = worst.max((got / want - 1.0).abs()).max((got_v / want_v - 1.0).abs());
    }
    eprintln!("M11 {m11:.3} kg m^2; worst deviation from the closed form {:.2} %", worst * 100.0);
    assert!(worst < 0.03, "off the closed form by {:.1} %", worst * 100.0);
}
