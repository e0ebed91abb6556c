//! `rig design --egm`: the EGM force controller's loop (`controller::egm_force`) on the actual
//! models, with the EGM path's delay in it.
//!
//! Loop gain, s = jω: `L(s) = H(s) e^{−sτ} / (b s (1 + s/ω_c))`, with `H(s) = 1/(G(s) + 1/k_c)` the
//! force per wheel displacement of the reduced strip model under the wheel at z_a (in series with
//! the contact penalty), `b` the admittance damping of the design rule, `ω_c` the motion
//! controller's position-correction low-pass and `τ` the rest of its lag plus half an EGM cycle
//! (`EgmForceDesign::delay_s`).
//!
//! Force-error bound over the bulge: on the rule's loop in time (static strip stiffness, the
//! reference held over each EGM cycle, the motion controller's pure delay and low-pass exact),
//! `g(t)` is the force error after a unit step of disturbance force; a disturbance `d(t)` then
//! leaves the error `g * ḋ`, so `|e| ≤ ‖g‖₁ max|ḋ|` (Young's inequality). The bulge of height
//! profile `h(z)` under the wheel rolling at `ż` is at most `d = k h`, `max|ḋ| = k max|h'| max|ż|`
//! (the peak of the cosine roll profile, `2 (z_end − z_start)/roll_s`): a bound, not an estimate:
//! the strip's top rises by less than the bulge under it.

use controller::egm_force::EgmForceDesign;
use nalgebra::Complex;
use scenarios::Scenario;
use strip::StripModel;

use crate::freq::{log_grid, margins, unwrap_deg, Margins};
use crate::plant1::StripPoint;

/// What `rig design --egm` computes.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EgmDesignResult {
    pub z_a_mm: f64,
    /// Strip under the wheel in series with the contact penalty, static, N/m.
    pub series_stiffness_n_per_m: f64,
    pub damping_ns_per_m: f64,
    pub delay_s: f64,
    pub correction_radps: f64,
    /// The rule's own crossover and phase margin (strip as `controller.strip_stiffness_n_per_m`).
    pub rule_strip_stiffness_n_per_m: f64,
    pub rule_crossover_hz: f64,
    pub rule_phase_margin_deg: f64,
    /// Margins on the reduced strip model.
    pub margins: Option<Margins>,
    /// ‖g‖₁, s: the force error's step response integrated in absolute value.
    pub step_error_l1_s: f64,
    /// max|ḋ| of the bulge, N/s, and the bound on the force error it gives, N.
    pub bulge_force_rate_n_per_s: f64,
    pub force_error_bound_n: f64,
}

/// The loop on the reduced strip model at `z_a_m`, and the bulge bound.
pub fn design_egm(s: &Scenario, model: &StripModel, z_a_m: f64) -> EgmDesignResult {
    let d = EgmForceDesign::from_scenario(s);
    let strip = StripPoint::new(model, z_a_m);
    let k_c = s.contact.stiffness_n_per_m;
    let series = 1.0 / (1.0 / strip.static_stiffness() + 1.0 / k_c);
    let f = log_grid(0.05, 500.0, 4000);
    let (mut mag, mut ph_h, mut ph_rest) = (Vec::new(), Vec::new(), Vec::new());
    for &fh in &f {
        let w = std::f64::consts::TAU * fh;
        let sj = Complex::new(0.0, w);
        let h = (strip.compliance(sj) + 1.0 / k_c).inv();
        let low = if d.correction_radps > 0.0 { Complex::new(1.0, w / d.correction_radps) } else { Complex::new(1.0, 0.0) };
        let l = h / (sj * d.damping_ns_per_m * low);
        mag.push(l.norm());
        ph_h.push(h.arg().to_degrees());
        ph_rest.push(-90.0 - (w / d.correction_radps.max(f64::MIN_POSITIVE)).atan().to_degrees() - (w * d.delay_s).to_degrees());
    }
    unwrap_deg(&mut ph_h);
    let ph: Vec<f64> = ph_h.iter().zip(&ph_rest).map(|(a, b)| a + b).collect();
    let m = margins(&f, &mag, &ph);
    let l1 = step_error_l1(s, &d, series);
    let rate = bulge_force_rate(s, series);
    EgmDesignResult {
        z_a_mm: z_a_m * 1e3,
        series_stiffness_n_per_m: series,
        damping_ns_per_m: d.damping_ns_per_m,
        delay_s: d.delay_s,
        correction_radps: d.correction_radps,
        rule_strip_stiffness_n_per_m: d.strip_stiffness_n_per_m,
        rule_crossover_hz: d.crossover_hz,
        rule_phase_margin_deg: d.phase_margin_deg,
        margins: m,
        step_error_l1_s: l1,
        bulge_force_rate_n_per_s: rate,
        force_error_bound_n: l1 * rate,
    }
}

/// ‖g‖₁ of the sampled loop: unit disturbance step at t = 0, the admittance updated every EGM
/// cycle from the force it sees, the motion controller as its delay line and low-pass, the
/// strip a spring of stiffness `k`. Integrated at 10 µs for 3 s (g has decayed by then: the
/// loop's slowest pole is near its crossover).
fn step_error_l1(s: &Scenario, d: &EgmForceDesign, k: f64) -> f64 {
    let h = 1e-5;
    let cycle_steps = (s.egm.cycle_s / h).round() as usize;
    let pure_delay_s = d.delay_s - 0.5 * s.egm.cycle_s;
    let delay_steps = (pure_delay_s / h).round() as usize;
    let mut line = vec![0.0f64; delay_steps + 1];
    let (mut y_cmd, mut y, mut l1) = (0.0f64, 0.0f64, 0.0f64);
    for n in 0..(3.0 / h) as usize {
        let force_err = k * y + 1.0; // F − F_ref, disturbance 1 N
        if n % cycle_steps == 0 {
            y_cmd -= force_err / d.damping_ns_per_m * s.egm.cycle_s;
        }
        line[n % (delay_steps + 1)] = y_cmd;
        let y_in = line[(n + 1) % (delay_steps + 1)];
        y += if d.correction_radps > 0.0 { (y_in - y) * (1.0 - (-d.correction_radps * h).exp()) } else { y_in - y };
        l1 += force_err.abs() * h;
    }
    l1
}

/// max|ḋ| of the bulge under the wheel rolling with the cosine velocity profile, N/s.
fn bulge_force_rate(s: &Scenario, k: f64) -> f64 {
    let p = plant_sim::contact::strip_params(s);
    let (c, w) = (p.bulge_center_m, p.bulge_width_m);
    let n = 10_000;
    let mut slope = 0.0f64;
    for i in 0..n {
        let z0 = c - w + 2.0 * w * i as f64 / n as f64;
        let dz = 2.0 * w / n as f64;
        slope = slope.max(((p.bulge_height_m(z0 + dz) - p.bulge_height_m(z0)) / dz).abs());
    }
    let t = &s.trajectory;
    let v_peak = 2.0 * (t.z_end_mm - t.z_start_mm) * 1e-3 / t.roll_s;
    k * slope * v_peak
}

/// The summary lines `rig design --egm` prints.
pub fn summary_text(r: &EgmDesignResult) -> String {
    let mut s =
        format!("strip under the wheel at z_a = {:.1} mm with the contact in series: {:.0} N/m\n", r.z_a_mm, r.series_stiffness_n_per_m);
    s += &format!(
        "EGM force loop (admittance b = {:.0} N s/m, delay {:.2} ms + low-pass {:.1} Hz):\n  rule (strip {:.0} N/m, controller.strip_stiffness_n_per_m): crossover {:.2} Hz, phase margin {:.1} deg\n",
        r.damping_ns_per_m,
        r.delay_s * 1e3,
        r.correction_radps / std::f64::consts::TAU,
        r.rule_strip_stiffness_n_per_m,
        r.rule_crossover_hz,
        r.rule_phase_margin_deg
    );
    match &r.margins {
        Some(m) => {
            s += &format!(
                "  reduced strip model at z_a = {:.1} mm: crossover {:.2} Hz, phase margin {:.1} deg, |S| peak {:.2} dB at {:.1} Hz\n",
                r.z_a_mm, m.crossover_hz, m.phase_margin_deg, m.sensitivity_peak_db, m.sensitivity_peak_hz
            )
        }
        None => s += "  reduced strip model: |L| never crosses 1\n",
    }
    s += &format!(
        "  bulge: max|dd/dt| {:.1} N/s, step-error L1 {:.4} s -> force error bound {:.3} N while rolling",
        r.bulge_force_rate_n_per_s, r.step_error_l1_s, r.force_error_bound_n
    );
    s
}
