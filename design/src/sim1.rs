//! 1-DOF servo run (thesis Section 6.4, Figure 6.7): the wheel as a point mass m_w moving along
//! the strip exactly on the z reference, its height force-controlled by the 1-DOF law (6.2)
//! u = m_w a + F_e with the controller's own impedance/integral law
//! (`controller::law::impedance_accel`) and references (`controller::reference`), on the full
//! strip model with its bulge through the plant's contact (`plant_sim::contact`).

use controller::gains::Gains;
use controller::law::impedance_accel;
use controller::reference::{Phase, ReferenceGenerator, ReferenceParams};
use nalgebra::{Matrix3, Vector3};
use plant_sim::contact::{ContactGeometry, StripContact};
use recordings::StripRecord;
use robot::Vec6;
use scenarios::Scenario;
use strip::StripModel;

use crate::servo::ServoSample;

/// Run the 1-DOF servo of scenario `s` with wheel mass `wheel_mass_kg` and `gains`.
pub fn run_1dof(s: &Scenario, model: &StripModel, gains: &Gains, wheel_mass_kg: f64) -> Vec<ServoSample> {
    let geo = ContactGeometry::from_scenario(s);
    let period = s.loop_.period_s;
    let n_sub = s.loop_.substeps as usize;
    let h = period / n_sub as f64;
    // The 1-DOF servo rolls the straight strip of the thesis (its task frame).
    let task = scenarios::geometry::TaskFrame::from_scenario(s);
    let mut contact = StripContact::new(model, geo, h);
    let mut reference = ReferenceGenerator::new(ReferenceParams::from_scenario(s));
    let rot: Matrix3<f64> = scenarios::geometry::tool_down_rotation();
    // Wheel centre (TCP) in the task frame: z along the strip, y up.
    let start = reference.params().start_task_m;
    let (mut y, mut vy, mut z) = (start.y, 0.0, start.z);
    let mut integral = 0.0;
    let mut rec = StripRecord::default();
    let mut out = Vec::new();
    let mut done_ticks = 0;
    let (kp, kd) = (gains.kp_pos, gains.kd_pos);
    for tick in 0..(120.0 / period) as u64 {
        let t = tick as f64 * period;
        let f_meas = contact.contact_force_n();
        let r = reference.update(t, f_meas, y);
        contact.fill_record(&mut rec);
        out.push(ServoSample {
            t_s: t,
            phase: r.phase,
            force_ref_n: r.force_y_n,
            contact_force_n: rec.contact_force_n,
            bottom_force_n: rec.bottom_force_n,
            wheel_z_m: rec.wheel_z_m,
            z_ref_m: r.pos_m.z,
        });
        let a = if r.force_mode {
            impedance_accel(gains, &mut integral, r.force_y_n, f_meas, vy, period)
        } else {
            integral = 0.0;
            r.acc_mps2.y + kp * (r.pos_m.y - y) + kd * (r.vel_mps.y - vy)
        };
        // (6.2): control force with the measured contact force fed forward (F_e = −p, the force
        // on the strip along task y; messages/README.md, "Frames and signs").
        let u = wheel_mass_kg * a + f_meas;
        // z follows its reference exactly over the tick (motion control is not the 1-DOF's topic).
        let (z0, vz0) = (z, r.vel_mps.z);
        for i in 0..n_sub {
            let tau = i as f64 * h;
            let zz = z0 + vz0 * tau + 0.5 * r.acc_mps2.z * tau * tau;
            let vz = vz0 + r.acc_mps2.z * tau;
            let pos = task.point_to_base(&Vector3::new(0.0, y, zz));
            let v = task.vector_to_base(&Vector3::new(0.0, vy, vz));
            let w = contact.substep(&pos, &rot, &Vec6::new(v.x, v.y, v.z, 0.0, 0.0, 0.0));
            // m_w ÿ = u + p (the strip pushes the wheel up with p = −F_e).
            let acc = (u + task.vector_to_task(&w.force_base_n).y) / wheel_mass_kg;
            y += vy * h + 0.5 * acc * h * h;
            vy += acc * h;
        }
        z = r.pos_m.z + r.vel_mps.z * period + 0.5 * r.acc_mps2.z * period * period;
        if r.phase == Phase::Done {
            done_ticks += 1;
            if done_ticks > (0.1 / period) as u64 {
                break;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use strip::StripParams;

    /// On a flat strip (no bulge) the impedance law (6.4) settles on the reference: at the end of
    /// the dwell the bottom force equals F_r (static equilibrium, no integral action needed), and
    /// the run goes through every phase to the lift-off.
    #[test]
    fn flat_strip_settles_on_the_reference_and_lifts_off() {
        let p = StripParams {
            length_m: 0.02,
            element_m: 0.002,
            order: 40,
            bulge_amplitude_m: 0.0,
            bulge_width_m: 0.01,
            bulge_center_m: 0.01,
            ..StripParams::default()
        };
        let model = StripModel::load_or_build(&p).unwrap();
        let mut s = Scenario::default();
        s.strip.length_mm = 20.0;
        s.trajectory.z_end_mm = 18.0;
        s.trajectory.dwell_s = 0.5;
        s.controller.force_integral = false;
        s.controller.strip_stiffness_n_per_m =
            1.0 / crate::plant1::StripPoint::new(&model, 0.01).compliance(nalgebra::Complex::new(0.0, 0.0)).re;
        let gains = Gains::from_scenario(&s, 20.0);
        let out = run_1dof(&s, &model, &gains, 20.0);
        let last_dwell = out.iter().rfind(|x| x.phase == Phase::Dwell).expect("dwell phase");
        assert!((last_dwell.bottom_force_n - s.trajectory.force_ref_n).abs() < 2e-3, "{last_dwell:?}");
        assert!((last_dwell.contact_force_n - last_dwell.bottom_force_n).abs() < 1e-3);
        let last = out.last().unwrap();
        assert_eq!(last.phase, Phase::Done);
        assert_eq!(last.contact_force_n, 0.0, "the wheel lifted off");
        assert!((last.wheel_z_m - 0.018).abs() < 1e-6, "{}", last.wheel_z_m);
    }
}
