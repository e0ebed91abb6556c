//! The 1-DOF force loop of thesis Chapter 6 built from the actual models.
//!
//! Strip: driving-point compliance under the wheel at z_a, from the reduced model's modal form,
//!   G(s) = wᵀ (C (sI − A)⁻¹ B + D) w = d_ww + Σ_k ½ [c_k b_k/(s − λ_k) + conj(c_k b_k)/(s − conj λ_k)]
//! (c_k = wᵀ C V_k weighted, b_k = (V⁻¹ B)_k w; see `strip::model::ModalForm`). With the contact
//! penalty k_c in series, the force on the strip per wheel displacement is H(s) = 1/(G(s) + 1/k_c).
//!
//! Wheel: m_w ÿ = u − F_e (6.1). Controller (6.2): u = m_w a + F_e, a = (e + u_I − b_d ẏ)/m_d,
//! e = F_r − F_e. Transfer functions (s = jω):
//!   plant                      P(s)   = F_e/u = H / (m_w s² + H)
//!   plant with velocity loop   P_v(s) = F_e/e = H / (s (m_d s + b_d))
//!   loop gain                  L(s)   = P_v(s) (1 + k_i/s) e^{−sT/2} M(z)   (ZOH half-sample delay)
//!   S = 1/(1 + L),  T = L/(1 + L)   (Figure 6.3)
//!
//! M(z), z = e^{sT}, is the force measurement's chain (the realistic cell, `[sensor]` and the
//! controller's `force_filter_hz`; 1 without them): the sensor's first-order low-pass
//! α/(1 − (1 − α) z⁻¹), its sample delay z^{−d} = e^{−s d T}, and the controller's filter
//! β/(1 − (1 − β) z⁻¹), each exactly as the plant and the controller run them per tick. The delay
//! takes ω d T of phase at every frequency and leaves |L| alone: at an unchanged crossover ω_c the
//! phase margin falls by exactly ω_c d T. (The controller's tool-load compensation and tare are
//! outside this linear loop.)

use nalgebra::Complex;
use strip::StripModel;

type C64 = Complex<f64>;

/// The strip under the wheel at one position: everything G(s) needs.
#[derive(Clone, Debug)]
pub struct StripPoint {
    pub z_a_m: f64,
    lam: Vec<C64>,
    cb: Vec<C64>,
    d_ww: f64,
}

impl StripPoint {
    pub fn new(model: &StripModel, z_a_m: f64) -> StripPoint {
        let mf = &model.modal;
        let (modes, n_top) = (mf.modes(), model.n_top());
        let mut w = vec![0.0; n_top];
        model.gaussian_weights(z_a_m, &mut w);
        let mut b = vec![C64::new(0.0, 0.0); modes];
        let mut c = vec![C64::new(0.0, 0.0); modes];
        for j in 0..n_top {
            for k in 0..modes {
                let (bj, cj) = (mf.b[j * modes + k], mf.c[j * modes + k]);
                b[k] += C64::new(bj.re, bj.im) * w[j];
                c[k] += C64::new(cj.re, cj.im) * w[j];
            }
        }
        let mut d_ww = 0.0;
        for i in 0..n_top {
            for j in 0..n_top {
                d_ww += w[i] * model.d[(i, j)] * w[j];
            }
        }
        StripPoint {
            z_a_m,
            lam: mf.lam.iter().map(|l| C64::new(l.re, l.im)).collect(),
            cb: b.iter().zip(&c).map(|(b, c)| b * c).collect(),
            d_ww,
        }
    }

    /// Driving-point compliance G(s) (m/N, +y displacement per +y force).
    pub fn compliance(&self, s: C64) -> C64 {
        let mut g = C64::new(self.d_ww, 0.0);
        for (l, cb) in self.lam.iter().zip(&self.cb) {
            g += (cb / (s - l) + cb.conj() / (s - l.conj())) * 0.5;
        }
        g
    }

    /// Static stiffness under the wheel 1/G(0), N/m.
    pub fn static_stiffness(&self) -> f64 {
        1.0 / self.compliance(C64::new(0.0, 0.0)).re
    }
}

/// Parameters of the 1-DOF loop.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Loop1 {
    pub wheel_mass_kg: f64,
    pub contact_stiffness_n_per_m: f64,
    pub m_d_kg: f64,
    pub b_d_nspm: f64,
    pub k_i_per_s: f64,
    pub period_s: f64,
    /// The measurement chain M(z) (module docs): the sensor's low-pass coefficient α and its delay
    /// in ticks, the controller's force filter coefficient β (α = β = 1, d = 0: an ideal sensor).
    pub sensor_alpha: f64,
    pub sensor_delay_ticks: u32,
    pub force_filter_beta: f64,
}

/// The first-order low-pass y_k = y_{k−1} + c (x_k − y_{k−1}) at z = e^{jωT}: c / (1 − (1 − c) e^{−jωT}).
pub fn first_order_lowpass(c: f64, w_t: f64) -> C64 {
    C64::new(c, 0.0) / (C64::new(1.0, 0.0) - C64::from_polar(1.0 - c, -w_t))
}

/// Frequency responses of one frequency.
#[derive(Clone, Copy, Debug)]
pub struct Response {
    pub plant: C64,
    pub plant_velocity_loop: C64,
    pub loop_gain: C64,
    pub sensitivity: C64,
    pub complementary: C64,
    /// Phase of the loop gain, degrees, as a sum of its factors (the strip factor still needs
    /// unwrapping along the grid).
    pub loop_phase_parts_deg: (f64, f64),
}

impl Loop1 {
    pub fn response(&self, strip: &StripPoint, f_hz: f64) -> Response {
        let w = std::f64::consts::TAU * f_hz;
        let s = C64::new(0.0, w);
        let h = (strip.compliance(s) + 1.0 / self.contact_stiffness_n_per_m).inv();
        let plant = h / (s * s * self.wheel_mass_kg + h);
        let pv = h / (s * (s * self.m_d_kg + self.b_d_nspm));
        let pi = C64::new(1.0, 0.0) + C64::new(self.k_i_per_s, 0.0) / s;
        let delay = C64::from_polar(1.0, -w * self.period_s / 2.0);
        let wt = w * self.period_s;
        let (lp_sensor, lp_controller) = (first_order_lowpass(self.sensor_alpha, wt), first_order_lowpass(self.force_filter_beta, wt));
        let measurement = lp_sensor * lp_controller * C64::from_polar(1.0, -wt * self.sensor_delay_ticks as f64);
        let l = pv * pi * delay * measurement;
        let one = C64::new(1.0, 0.0);
        let rest = -90.0
            - (self.m_d_kg * w / self.b_d_nspm).atan().to_degrees()
            - (self.k_i_per_s / w).atan().to_degrees()
            - (w * self.period_s / 2.0).to_degrees()
            - (wt * self.sensor_delay_ticks as f64).to_degrees()
            + lp_sensor.arg().to_degrees()
            + lp_controller.arg().to_degrees();
        Response {
            plant,
            plant_velocity_loop: pv,
            loop_gain: l,
            sensitivity: one / (one + l),
            complementary: l / (one + l),
            loop_phase_parts_deg: (h.arg().to_degrees(), rest),
        }
    }
}

impl Loop1 {
    /// The measurement chain of a scenario (ideal without `[sensor]` and a force filter).
    pub fn with_measurement_of(mut self, s: &scenarios::Scenario) -> Loop1 {
        let coeff = |f_hz: f64| if f_hz > 0.0 { 1.0 - (-std::f64::consts::TAU * f_hz * self.period_s).exp() } else { 1.0 };
        (self.sensor_alpha, self.sensor_delay_ticks) =
            if s.sensor.enabled { (coeff(s.sensor.lowpass_hz), s.sensor.delay_ticks) } else { (1.0, 0) };
        self.force_filter_beta = coeff(s.controller.force_filter_hz);
        self
    }

    /// The same loop with an ideal sensor (M = 1).
    pub fn ideal_sensor(self) -> Loop1 {
        Loop1 { sensor_alpha: 1.0, sensor_delay_ticks: 0, force_filter_beta: 1.0, ..self }
    }

    /// Responses over `f_hz` and the margins (the strip's phase unwrapped along the grid).
    pub fn sweep(&self, strip: &StripPoint, f_hz: &[f64]) -> (Vec<Response>, Option<crate::freq::Margins>) {
        let resp: Vec<_> = f_hz.iter().map(|&f| self.response(strip, f)).collect();
        let mag: Vec<f64> = resp.iter().map(|r| r.loop_gain.norm()).collect();
        let mut ph_h: Vec<f64> = resp.iter().map(|r| r.loop_phase_parts_deg.0).collect();
        crate::freq::unwrap_deg(&mut ph_h);
        let ph: Vec<f64> = ph_h.iter().zip(&resp).map(|(a, r)| a + r.loop_phase_parts_deg.1).collect();
        let m = crate::freq::margins(f_hz, &mag, &ph);
        (resp, m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strip::StripParams;

    fn coarse() -> StripModel {
        let p = StripParams {
            length_m: 0.02,
            element_m: 0.002,
            order: 40,
            bulge_amplitude_m: 0.2e-3,
            bulge_width_m: 0.01,
            bulge_center_m: 0.01,
            ..StripParams::default()
        };
        StripModel::load_or_build(&p).unwrap()
    }

    /// G(0) from the modal sum equals wᵀ y_static(w) of the reduced model's own static solve.
    #[test]
    fn modal_compliance_at_dc_matches_the_static_solve() {
        let m = coarse();
        let z = 0.01;
        let sp = StripPoint::new(&m, z);
        let mut w = vec![0.0; m.n_top()];
        m.gaussian_weights(z, &mut w);
        let y = m.static_response(&w);
        let g0: f64 = w.iter().zip(&y).map(|(a, b)| a * b).sum();
        let g = sp.compliance(C64::new(0.0, 0.0));
        assert!((g.re - g0).abs() < 1e-8 * g0.abs() && g.im.abs() < 1e-12 * g0.abs(), "{g} vs {g0}");
        assert!(g0 > 0.0);
    }

    /// A passive driving point dissipates: the mobility jω G(jω) has a non-negative real part,
    /// i.e. Im G(jω) ≤ 0 for ω > 0 — checked up to the Craig–Bampton cut-off: balanced truncation
    /// does not preserve passivity exactly, and above the cut-off the model makes no claim.
    #[test]
    fn compliance_is_passive() {
        let m = coarse();
        let sp = StripPoint::new(&m, 0.01);
        for f in crate::freq::log_grid(0.1, m.params.cb_cutoff_hz, 200) {
            let g = sp.compliance(C64::new(0.0, std::f64::consts::TAU * f));
            assert!(g.im < 1e-9 * sp.compliance(C64::new(0.0, 0.0)).re, "Im G > 0 at {f} Hz: {g}");
        }
    }

    /// A loop on a coarse strip with a 25 Hz crossover (b_d = k_s / (2π 25), m_d = b_d / (2π 250)).
    fn loop_on_coarse_strip() -> (Loop1, StripPoint) {
        let model = coarse();
        let strip = StripPoint::new(&model, 0.01);
        let k = 1.0 / (1.0 / strip.static_stiffness() + 1.0 / 1e6);
        let b_d = k / (std::f64::consts::TAU * 25.0);
        let lp = Loop1 {
            wheel_mass_kg: 20.0,
            contact_stiffness_n_per_m: 1e6,
            m_d_kg: b_d / (std::f64::consts::TAU * 250.0),
            b_d_nspm: b_d,
            k_i_per_s: 0.0,
            period_s: 1e-3,
            sensor_alpha: 1.0,
            sensor_delay_ticks: 0,
            force_filter_beta: 1.0,
        };
        (lp, strip)
    }

    /// The sensor's delay of d ticks leaves the crossover where it was and takes exactly
    /// ω_c d T (radians) off the phase margin.
    #[test]
    fn a_sample_delay_costs_omega_c_d_t_of_phase_margin() {
        let (ideal, strip) = loop_on_coarse_strip();
        let f = crate::freq::log_grid(0.5, 5000.0, 1200);
        let m0 = ideal.sweep(&strip, &f).1.expect("crossover");
        for d in [1u32, 3] {
            let m = Loop1 { sensor_delay_ticks: d, ..ideal }.sweep(&strip, &f).1.expect("crossover");
            let want = (std::f64::consts::TAU * m0.crossover_hz * d as f64 * ideal.period_s).to_degrees();
            eprintln!(
                "delay {d} ticks: crossover {:.3} Hz (ideal {:.3} Hz), phase margin {:.3} deg (ideal {:.3}, closed form {:.3})",
                m.crossover_hz,
                m0.crossover_hz,
                m.phase_margin_deg,
                m0.phase_margin_deg,
                m0.phase_margin_deg - want
            );
            assert!((m.crossover_hz / m0.crossover_hz - 1.0).abs() < 1e-12, "{} vs {}", m.crossover_hz, m0.crossover_hz);
            assert!(
                (m0.phase_margin_deg - m.phase_margin_deg - want).abs() < 1e-3,
                "lost {} deg, want {want}",
                m0.phase_margin_deg - m.phase_margin_deg
            );
        }
    }

    /// The low-pass stages multiply the loop by their closed forms α/(1 − (1 − α) e^{−jωT}) at
    /// every frequency: gain and phase (the phase the margins use) at two frequencies.
    #[test]
    fn the_filters_enter_the_loop_with_their_closed_forms() {
        let (ideal, strip) = loop_on_coarse_strip();
        let alpha = 1.0 - (-std::f64::consts::TAU * 150.0 * 1e-3f64).exp();
        let beta = 1.0 - (-std::f64::consts::TAU * 100.0 * 1e-3f64).exp();
        let lp = Loop1 { sensor_alpha: alpha, force_filter_beta: beta, ..ideal };
        for f in [25.0, 120.0] {
            let wt = std::f64::consts::TAU * f * 1e-3;
            let closed = |c: f64| {
                let (re, im) = (1.0 - (1.0 - c) * wt.cos(), (1.0 - c) * wt.sin());
                (c / re.hypot(im), -im.atan2(re))
            };
            let ((ga, pa), (gb, pb)) = (closed(alpha), closed(beta));
            let (r0, r) = (ideal.response(&strip, f), lp.response(&strip, f));
            let ratio = r.loop_gain / r0.loop_gain;
            assert!((ratio.norm() / (ga * gb) - 1.0).abs() < 1e-12, "{f} Hz: gain {} vs {}", ratio.norm(), ga * gb);
            assert!((ratio.arg() - (pa + pb)).abs() < 1e-12, "{f} Hz: phase {} vs {}", ratio.arg(), pa + pb);
            let parts = r.loop_phase_parts_deg.1 - r0.loop_phase_parts_deg.1;
            assert!((parts - (pa + pb).to_degrees()).abs() < 1e-9, "{f} Hz: margin phase {parts} deg");
        }
    }
}
