//! Frequency-response helpers: log grids and loop margins from sampled (|L|, phase) data.

/// `n` frequencies from `f_lo` to `f_hi` (Hz), logarithmically spaced.
pub fn log_grid(f_lo: f64, f_hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (f_lo.log10(), f_hi.log10());
    (0..n).map(|i| 10f64.powf(a + (b - a) * i as f64 / (n - 1) as f64)).collect()
}

/// Loop margins of a sampled loop gain.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Margins {
    /// First frequency where |L| falls through 1, Hz (log-interpolated).
    pub crossover_hz: f64,
    /// 180° + arg L at the crossover, degrees (phase linearly interpolated in log f).
    pub phase_margin_deg: f64,
    /// max |S| = max 1/|1 + L| over the grid, dB, and where.
    pub sensitivity_peak_db: f64,
    pub sensitivity_peak_hz: f64,
}

/// Margins from the grid `f_hz`, the loop gain magnitude `mag` and its UNWRAPPED phase in degrees
/// (continuous along the grid). Returns None if |L| never falls through 1.
pub fn margins(f_hz: &[f64], mag: &[f64], phase_deg: &[f64]) -> Option<Margins> {
    let i = (1..f_hz.len()).find(|&i| mag[i - 1] >= 1.0 && mag[i] < 1.0)?;
    let (l0, l1) = (mag[i - 1].log10(), mag[i].log10());
    let s = l0 / (l0 - l1);
    let (x0, x1) = (f_hz[i - 1].log10(), f_hz[i].log10());
    let crossover_hz = 10f64.powf(x0 + s * (x1 - x0));
    let phase = phase_deg[i - 1] + s * (phase_deg[i] - phase_deg[i - 1]);
    let (mut peak, mut peak_f) = (0.0f64, f_hz[0]);
    for k in 0..f_hz.len() {
        let (re, im) = (1.0 + mag[k] * phase_deg[k].to_radians().cos(), mag[k] * phase_deg[k].to_radians().sin());
        let s_mag = 1.0 / re.hypot(im);
        if s_mag > peak {
            peak = s_mag;
            peak_f = f_hz[k];
        }
    }
    Some(Margins { crossover_hz, phase_margin_deg: 180.0 + phase, sensitivity_peak_db: 20.0 * peak.log10(), sensitivity_peak_hz: peak_f })
}

/// Unwrap a phase sequence (degrees) so consecutive samples differ by less than 180°.
pub fn unwrap_deg(phase: &mut [f64]) {
    for i in 1..phase.len() {
        while phase[i] - phase[i - 1] > 180.0 {
            phase[i] -= 360.0;
        }
        while phase[i] - phase[i - 1] < -180.0 {
            phase[i] += 360.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Complex;

    /// L(s) = k / (s (s + a)): |L(jω_c)| = 1 at ω_c² = √(a⁴/4 + k²) − a²/2, PM = 90° − atan(ω_c/a),
    /// and for this loop max|S| has the closed form of the standard second-order system
    /// T = ω_n²/(s² + 2ζω_n s + ω_n²) with ω_n² = k, 2ζω_n = a.
    #[test]
    fn second_order_loop_margins_match_closed_forms() {
        let (k, a) = (1.0e4_f64, 60.0_f64);
        let f = log_grid(0.01, 1e4, 20001);
        let l: Vec<Complex<f64>> = f
            .iter()
            .map(|&f| {
                let s = Complex::new(0.0, std::f64::consts::TAU * f);
                Complex::new(k, 0.0) / (s * (s + a))
            })
            .collect();
        let mag: Vec<f64> = l.iter().map(|z| z.norm()).collect();
        let mut ph: Vec<f64> = l.iter().map(|z| z.arg().to_degrees()).collect();
        unwrap_deg(&mut ph);
        let m = margins(&f, &mag, &ph).unwrap();
        let wc = ((a.powi(4) / 4.0 + k * k).sqrt() - a * a / 2.0).sqrt();
        let pm = 90.0 - (wc / a).atan().to_degrees();
        assert!(
            (m.crossover_hz - wc / std::f64::consts::TAU).abs() < 1e-4 * m.crossover_hz,
            "{} vs {}",
            m.crossover_hz,
            wc / std::f64::consts::TAU
        );
        assert!((m.phase_margin_deg - pm).abs() < 1e-3, "{} vs {pm}", m.phase_margin_deg);
        // S = s(s + a)/(s² + a s + k): |S(jω)|² = ω²(ω² + a²)/((k − ω²)² + a²ω²); its maximum
        // found by dense evaluation of the closed form (independent of `margins`' arithmetic).
        let s_peak = f
            .iter()
            .map(|&f| {
                let w = std::f64::consts::TAU * f;
                (w * w * (w * w + a * a) / ((k - w * w).powi(2) + a * a * w * w)).sqrt()
            })
            .fold(0.0, f64::max);
        assert!((m.sensitivity_peak_db - 20.0 * s_peak.log10()).abs() < 1e-9);
        assert!(m.sensitivity_peak_db > 0.0);
    }

    #[test]
    fn a_loop_below_one_everywhere_has_no_crossover() {
        let f = log_grid(1.0, 100.0, 50);
        assert!(margins(&f, &vec![0.5; 50], &vec![-90.0; 50]).is_none());
    }
}
