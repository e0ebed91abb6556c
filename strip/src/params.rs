//! Build parameters of the weatherstrip model (DESIGN section 4). Every field changes the result,
//! so every field goes into the cache key.

use serde::{Deserialize, Serialize};

use crate::error::StripError;

/// How the bottom face is held by the substrate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Substrate {
    /// All bottom DOFs fixed (double-sided tape; the default).
    Bonded,
    /// Bottom normal (y) DOF fixed, frictionless in-plane, plus the end-face constraints of
    /// Appendix A.5 (z = 0 face: u_z = 0; z = 0, x = 0 line: u_x = 0) against rigid-body motion.
    Sliding,
}

/// Which DOFs of the top-surface nodes form the Craig-Bampton boundary.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum CbBoundary {
    /// Only the normal (y) DOFs: the wheel inputs act there, so statics stay exact.
    Y,
    /// All three directions of every top node.
    Xyz,
}

/// Every parameter of the model build. SI units (m, Pa, kg/m^3, Hz, s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StripParams {
    /// Strip length along task z (m).
    pub length_m: f64,
    /// Target element edge (m); the cross-section divisions follow from it (see `mesh`).
    pub element_m: f64,
    /// Young's modulus (Pa): the linearised Ogden fit of Section 4.1.
    pub youngs_pa: f64,
    /// Poisson's ratio (0.49 default; 0.4999 as in the thesis works thanks to mean dilatation).
    pub poisson: f64,
    /// Density (kg/m^3): EPDM datasheet value (DESIGN 4 explains why not the thesis' listing).
    pub density_kg_m3: f64,
    /// Rayleigh damping B = alpha M + beta K (5.24).
    pub damping_alpha_per_s: f64,
    pub damping_beta_s: f64,
    pub substrate: Substrate,
    pub cb_boundary: CbBoundary,
    /// Fixed-interface modes kept up to this frequency (Hz).
    pub cb_cutoff_hz: f64,
    /// Balanced-truncation order (states of the plant model).
    pub order: usize,
    /// Substrate bump under the bottom face: raised cosine of this peak height (m, +y) ...
    pub bulge_amplitude_m: f64,
    /// ... full width along z (m) ...
    pub bulge_width_m: f64,
    /// ... centred at this z (m).
    pub bulge_center_m: f64,
}

impl Default for StripParams {
    fn default() -> Self {
        Self {
            length_m: 40e-3,
            element_m: 1e-3,
            youngs_pa: 3.46e6,
            poisson: 0.49,
            density_kg_m3: 1080.0,
            damping_alpha_per_s: 60.0,
            damping_beta_s: 3e-6,
            substrate: Substrate::Bonded,
            cb_boundary: CbBoundary::Y,
            cb_cutoff_hz: 2500.0,
            order: 250,
            // the default scenario's bump (issue 6: 0.2 mm high, 10 mm half-width, at z = 20 mm),
            // so `rig model` builds and checks the strip `rig run` uses
            bulge_amplitude_m: 0.2e-3,
            bulge_width_m: 20e-3,
            bulge_center_m: 20e-3,
        }
    }
}

impl StripParams {
    /// Rejects values the pipeline cannot handle, naming the field.
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > 0.0)` refuses NaN too; `x <= 0.0` would let it through
    pub fn validate(&self) -> Result<(), StripError> {
        let bad = |field: &'static str, value: f64, why: &'static str| Err(StripError::Param { field, value, why });
        if !(self.length_m > 0.0 && self.length_m < 1.0) {
            return bad("length_m", self.length_m, "must be in (0, 1) m");
        }
        if !(self.element_m >= 0.2e-3 && self.element_m <= 4e-3) {
            return bad("element_m", self.element_m, "must be in [0.2, 4] mm");
        }
        if self.length_m / self.element_m < 2.0 {
            return bad("element_m", self.element_m, "needs at least two elements along the strip");
        }
        if !(self.youngs_pa > 0.0) {
            return bad("youngs_pa", self.youngs_pa, "must be positive");
        }
        if !(self.poisson > -1.0 && self.poisson < 0.5) {
            return bad("poisson", self.poisson, "must be in (-1, 0.5)");
        }
        if !(self.density_kg_m3 > 0.0) {
            return bad("density_kg_m3", self.density_kg_m3, "must be positive");
        }
        if !(self.damping_alpha_per_s >= 0.0) || !(self.damping_beta_s >= 0.0) {
            return bad("damping_alpha_per_s/damping_beta_s", self.damping_alpha_per_s, "must be >= 0");
        }
        if self.damping_alpha_per_s == 0.0 && self.damping_beta_s == 0.0 {
            return bad("damping_beta_s", 0.0, "balanced truncation needs a stable (damped) system");
        }
        if !(self.cb_cutoff_hz > 0.0) {
            return bad("cb_cutoff_hz", self.cb_cutoff_hz, "must be positive");
        }
        if self.order < 2 {
            return bad("order", self.order as f64, "must be >= 2");
        }
        if !(self.bulge_width_m > 0.0) {
            return bad("bulge_width_m", self.bulge_width_m, "must be positive");
        }
        if !(self.bulge_center_m >= 0.0 && self.bulge_center_m <= self.length_m) {
            return bad("bulge_center_m", self.bulge_center_m, "must lie on the strip [0, length_m]");
        }
        if !self.bulge_amplitude_m.is_finite() {
            return bad("bulge_amplitude_m", self.bulge_amplitude_m, "must be finite");
        }
        Ok(())
    }

    /// Substrate height (m, +y) under the bottom face at z (m): raised cosine bump.
    pub fn bulge_height_m(&self, z_m: f64) -> f64 {
        let s = (z_m - self.bulge_center_m) / (0.5 * self.bulge_width_m);
        if s.abs() >= 1.0 {
            0.0
        } else {
            0.5 * self.bulge_amplitude_m * (1.0 + (std::f64::consts::PI * s).cos())
        }
    }

    /// Stable 64-bit FNV-1a hash of the canonical JSON of every parameter plus the code version.
    pub fn cache_key(&self) -> String {
        let json = serde_json::to_string(self).expect("params serialise");
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in json.bytes().chain(crate::CODE_VERSION.bytes()) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        format!("{h:016x}")
    }
}
