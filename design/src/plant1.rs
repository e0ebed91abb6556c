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
//!   loop gain                  L(s)   = P_v(s) (1 + k_i/s) e^{−sT/2}   (ZOH half-sample delay)
//!   S = 1/(1 + L),  T = L/(1 + L)   (Figure 6.3)

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
        let l = pv * pi * delay;
        let one = C64::new(1.0, 0.0);
        let rest = -90.0
            - (self.m_d_kg * w / self.b_d_nspm).atan().to_degrees()
            - (self.k_i_per_s / w).atan().to_degrees()
            - (w * self.period_s / 2.0).to_degrees();
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
}
