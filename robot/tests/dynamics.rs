//! Dynamics against identities, an independent energy computation and conservation.

mod common;

use common::{rel_err, robots, Rng};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use robot::{Mat6, Robot, Tool, Vec6};

#[test]
fn mass_matrix_is_symmetric_positive_definite() {
    let mut rng = Rng::new(10);
    for (name, robot) in robots() {
        for _ in 0..50 {
            let q = rng.vec6(3.0);
            let m = robot.mass_matrix(&q);
            assert!((m - m.transpose()).amax() <= 1e-15 * m.amax(), "{name}: M not symmetric");
            let eig = SymmetricEigen::new(m).eigenvalues;
            assert!(eig.min() > 0.0, "{name}: M not positive definite, eigenvalues {eig:?}");
        }
    }
}

#[test]
fn mass_matrix_condition_number_is_about_1e6() {
    // The design note: the tiny wrist inertias make M ill-conditioned.
    let robot = Robot::irb2400();
    let q = Vec6::from(Robot::ABB_ZERO_Q);
    let eig = SymmetricEigen::new(robot.mass_matrix(&q)).eigenvalues;
    let cond = eig.max() / eig.min();
    assert!(cond > 1e5 && cond < 1e7, "cond(M) = {cond:e}");
}

/// Kinetic energy summed link by link from COM velocities (Jacobians of the COM points) and
/// angular velocities, tool counted as its own body, armature added per joint: an evaluation
/// of `qd^T M qd / 2` that shares nothing with the CRBA.
fn kinetic_energy_by_links(robot: &Robot, q: &Vec6, qd: &Vec6) -> f64 {
    let frames = robot.frames(q);
    let mut bodies: Vec<(usize, f64, Vector3<f64>, Matrix3<f64>)> = (0..6)
        .map(|i| {
            let l = robot.link(i);
            (i, l.mass_kg, l.com_m, l.inertia_com)
        })
        .collect();
    if let Some(t) = robot.tool() {
        bodies.push((5, t.mass_kg, t.com_flange_m, t.inertia_com));
    }
    let mut energy = 0.5 * qd.dot(&robot.armature.component_mul(qd));
    for (i, mass, com, inertia) in bodies {
        let (rot, pos) = (frames.rot[i + 1], frames.pos[i + 1]);
        let c = pos + rot * com;
        let (mut v, mut w) = (Vector3::zeros(), Vector3::zeros());
        for j in 0..=i {
            let z = frames.rot[j].column(2).into_owned();
            v += z.cross(&(c - frames.pos[j])) * qd[j];
            w += z * qd[j];
        }
        let i_base = rot * inertia * rot.transpose();
        energy += 0.5 * mass * v.norm_squared() + 0.5 * w.dot(&(i_base * w));
    }
    energy
}

#[test]
fn mass_matrix_matches_link_by_link_kinetic_energy() {
    let mut rng = Rng::new(11);
    for (name, robot) in robots() {
        for _ in 0..30 {
            let q = rng.vec6(3.0);
            let qd = rng.vec6(2.0);
            let crba = 0.5 * qd.dot(&(robot.mass_matrix(&q) * qd));
            let direct = kinetic_energy_by_links(&robot, &q, &qd);
            assert!((crba - direct).abs() <= 1e-12 * direct, "{name}: {crba} vs {direct}");
        }
    }
}

#[test]
fn gravity_is_gradient_of_potential_energy() {
    let mut rng = Rng::new(12);
    for (name, robot) in robots() {
        for _ in 0..20 {
            let q = rng.vec6(3.0);
            let h = 1e-6;
            let numeric = Vec6::from_fn(|j, _| {
                let mut qp = q;
                let mut qm = q;
                qp[j] += h;
                qm[j] -= h;
                (robot.potential_energy(&qp) - robot.potential_energy(&qm)) / (2.0 * h)
            });
            let g = robot.gravity_torque(&q);
            assert!(rel_err(&g, &numeric, 1.0) < 1e-8, "{name}: g {g:?} vs dV/dq {numeric:?}");
        }
    }
}

#[test]
fn rnea_equals_mass_matrix_coriolis_gravity() {
    let mut rng = Rng::new(13);
    for (name, robot) in robots() {
        for _ in 0..50 {
            let (q, qd, qdd) = (rng.vec6(3.0), rng.vec6(2.0), rng.vec6(5.0));
            let tau = robot.rnea(&q, &qd, &qdd);
            let sum = robot.mass_matrix(&q) * qdd
                + robot.coriolis_times_qd(&q, &qd)
                + robot.gravity_torque(&q)
                + robot.viscous.component_mul(&qd);
            assert!(rel_err(&tau, &sum, 1e-9) < 1e-13, "{name}: {tau:?} vs {sum:?}");
        }
    }
}

#[test]
fn coriolis_is_quadratic_in_velocity() {
    let robot = Robot::irb2400_with_tool(Tool::default());
    let mut rng = Rng::new(14);
    let (q, qd) = (rng.vec6(3.0), rng.vec6(2.0));
    let c1 = robot.coriolis_times_qd(&q, &qd);
    let c3 = robot.coriolis_times_qd(&q, &(qd * 3.0));
    assert!(rel_err(&(c1 * 9.0), &c3, 1e-9) < 1e-13);
}

#[test]
fn forward_dynamics_inverts_rnea() {
    let mut rng = Rng::new(15);
    for (name, robot) in robots() {
        for _ in 0..200 {
            let (q, qd, qdd) = (rng.vec6(3.0), rng.vec6(2.0), rng.vec6(5.0));
            let tau = robot.rnea(&q, &qd, &qdd);
            let back = robot.forward_dynamics(&q, &qd, &tau);
            assert!(rel_err(&back, &qdd, 1e-9) < 1e-9, "{name}: qdd {qdd:?} -> {back:?}");
        }
    }
}

#[test]
fn mdot_minus_2c_is_skew_along_qd() {
    // qd^T (M-dot - 2C) qd = 0, with M-dot by central differences along q(t) = q + t qd.
    let mut rng = Rng::new(16);
    for (name, robot) in robots() {
        for _ in 0..30 {
            let (q, qd) = (rng.vec6(3.0), rng.vec6(2.0));
            let h = 1e-6;
            let mdot: Mat6 = (robot.mass_matrix(&(q + qd * h)) - robot.mass_matrix(&(q - qd * h))) / (2.0 * h);
            let lhs = qd.dot(&(mdot * qd));
            let rhs = 2.0 * qd.dot(&robot.coriolis_times_qd(&q, &qd));
            assert!((lhs - rhs).abs() < 1e-7 * lhs.abs().max(1.0), "{name}: qd'Mdot qd = {lhs}, 2 qd'C qd = {rhs}");
        }
    }
}

#[test]
fn armature_and_viscous_enter_as_documented() {
    let base = Robot::irb2400_with_tool(Tool::default());
    let armature = Vec6::new(0.5, 0.4, 0.3, 0.2, 0.1, 0.05);
    let viscous = Vec6::new(6.0, 5.0, 4.0, 3.0, 2.0, 1.0);
    let robot = base.clone().with_armature(armature).with_viscous(viscous);
    let mut rng = Rng::new(17);
    let (q, qd, qdd) = (rng.vec6(3.0), rng.vec6(2.0), rng.vec6(5.0));
    let diff = robot.mass_matrix(&q) - base.mass_matrix(&q);
    assert!((diff - Mat6::from_diagonal(&armature)).amax() < 1e-12);
    let dtau = robot.rnea(&q, &qd, &qdd) - base.rnea(&q, &qd, &qdd);
    assert!(rel_err(&dtau, &(armature.component_mul(&qdd) + viscous.component_mul(&qd)), 1.0) < 1e-12);
}

#[test]
fn scaled_inertia_scales_every_dynamic_term() {
    let robot = Robot::irb2400_with_tool(Tool::default()).with_armature(Vec6::from_element(0.1));
    let scaled = robot.scaled_inertia(1.3);
    let mut rng = Rng::new(18);
    let (q, qd, qdd) = (rng.vec6(3.0), rng.vec6(2.0), rng.vec6(5.0));
    assert!(rel_err(&(robot.rnea(&q, &qd, &qdd) * 1.3), &scaled.rnea(&q, &qd, &qdd), 1.0) < 1e-13);
    assert!((robot.mass_matrix(&q) * 1.3 - scaled.mass_matrix(&q)).amax() < 1e-12);
    assert!((robot.tcp_pose(&q).translation.vector - scaled.tcp_pose(&q).translation.vector).norm() == 0.0);
}

#[test]
fn tool_adds_its_mass_to_the_total() {
    let tool = Tool::default();
    let bare = Robot::irb2400();
    let tooled = Robot::irb2400_with_tool(tool);
    assert!((tooled.total_mass_kg() - bare.total_mass_kg() - tool.mass_kg).abs() < 1e-12);
    // Static: the extra gravity torque on joint 1 about the vertical axis is zero, on joint 2
    // it is the tool weight times its horizontal lever arm from the joint-2 axis.
    let q = Vec6::from(Robot::ABB_ZERO_Q);
    let dg = tooled.gravity_torque(&q) - bare.gravity_torque(&q);
    let frames = bare.frames(&q);
    let tool_com = frames.pos[6] + frames.rot[6] * tool.com_flange_m;
    let lever = tool_com.x - frames.pos[1].x;
    assert!(dg[0].abs() < 1e-12);
    // Joint 2 turns about base +y; a weight at lever +x has moment (x e_x) x (-m g e_z) =
    // +m g x about +y, so the holding torque g_2 = tau at rest is -m g lever.
    assert!((dg[1] + tool.mass_kg * Robot::GRAVITY_MPS2 * lever).abs() < 1e-9, "{} vs {}", dg[1], -tool.mass_kg * 9.81 * lever);
}

fn rk4_step(robot: &Robot, q: &Vec6, qd: &Vec6, dt: f64) -> (Vec6, Vec6) {
    let zero = Vec6::zeros();
    let f = |q: &Vec6, qd: &Vec6| (*qd, robot.forward_dynamics(q, qd, &zero));
    let (k1q, k1v) = f(q, qd);
    let (k2q, k2v) = f(&(q + k1q * (dt / 2.0)), &(qd + k1v * (dt / 2.0)));
    let (k3q, k3v) = f(&(q + k2q * (dt / 2.0)), &(qd + k2v * (dt / 2.0)));
    let (k4q, k4v) = f(&(q + k3q * dt), &(qd + k3v * dt));
    (q + (k1q + k2q * 2.0 + k3q * 2.0 + k4q) * (dt / 6.0), qd + (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (dt / 6.0))
}

#[test]
fn unforced_motion_conserves_energy() {
    // tau = 0 under gravity, no friction: kinetic + potential energy is constant. The arm
    // falls and swings for 0.5 s; RK4 at 0.1 ms.
    for robot in
        [Robot::irb2400(), Robot::irb2400_with_tool(Tool::default()).with_armature(Vec6::from_element(0.05)), common::random_arm(7)]
    {
        let mut q = Vec6::new(0.3, -1.2, 0.4, 0.5, 0.8, -0.3);
        let mut qd = Vec6::new(0.5, -0.3, 0.4, 1.0, -1.5, 2.0);
        let energy = |q: &Vec6, qd: &Vec6| robot.kinetic_energy(q, qd) + robot.potential_energy(q);
        let e0 = energy(&q, &qd);
        let dt = 1e-4;
        let mut max_kinetic: f64 = 0.0;
        let mut max_drift: f64 = 0.0;
        for _ in 0..5000 {
            (q, qd) = rk4_step(&robot, &q, &qd, dt);
            max_kinetic = max_kinetic.max(robot.kinetic_energy(&q, &qd));
            max_drift = max_drift.max((energy(&q, &qd) - e0).abs());
        }
        // The arm must really have moved (energy exchanged), and the total must hold.
        assert!(max_kinetic > 100.0, "kinetic energy only reached {max_kinetic} J");
        // Observed: ~1e-14 of the peak kinetic energy (RK4's error at 0.1 ms is below round-off).
        assert!(max_drift < 1e-11 * max_kinetic, "energy drift {max_drift:e} J of {max_kinetic} J kinetic");
    }
}

#[test]
fn cholesky_solve_solves_and_rejects_indefinite_matrices() {
    let mut rng = Rng::new(19);
    let a = Mat6::from_fn(|_, _| rng.uniform(-1.0, 1.0));
    let spd = a * a.transpose() + Mat6::identity() * 1e-3;
    let x = rng.vec6(1.0);
    let solved = robot::dynamics::cholesky_solve(spd, spd * x);
    assert!((solved - x).norm() < 1e-9 * x.norm(), "{solved:?} vs {x:?}");
    let mut indefinite = spd;
    indefinite[(3, 3)] = -1.0;
    assert!(robot::dynamics::cholesky_solve(indefinite, x).iter().all(|v| v.is_nan()));
}
