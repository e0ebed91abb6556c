//! The numbers of a study: seeded uniform samples (random or Latin hypercube), the normal
//! distribution's CDF and quantile, the Wilson interval of a pass rate, percentiles and
//! Spearman's rank correlation.

/// SplitMix64 (Steele, Lea, Flood 2014): one 64-bit hash step; the study's only source of
/// randomness, so a case depends on the seed and its number alone, on any machine.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A stream of uniform numbers in [0, 1) from a seed.
struct Uniforms(u64);

impl Uniforms {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        (splitmix64(self.0) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `[case][parameter]` uniforms in [0, 1): independent draws, or a Latin hypercube (`lhs`): per
/// parameter a random permutation of the `cases` strata, a uniform draw within each.
pub fn unit_samples(seed: u64, cases: usize, parameters: usize, lhs: bool) -> Vec<Vec<f64>> {
    let mut rng = Uniforms(splitmix64(seed));
    let mut out = vec![vec![0.0; parameters]; cases];
    for j in 0..parameters {
        let mut strata: Vec<usize> = (0..cases).collect();
        if lhs {
            // Fisher–Yates
            for i in (1..cases).rev() {
                let k = ((rng.next() * (i + 1) as f64) as usize).min(i);
                strata.swap(i, k);
            }
        }
        for (i, row) in out.iter_mut().enumerate() {
            row[j] = if lhs { (strata[i] as f64 + rng.next()) / cases as f64 } else { rng.next() };
        }
    }
    out
}

/// Φ(x), the standard normal CDF.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// Φ⁻¹(p): Acklam's rational approximation (relative error 1.15e-9) refined by one Halley step
/// on `normal_cdf`, which brings it to double precision.
pub fn normal_quantile(p: f64) -> f64 {
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    const A: [f64; 6] =
        [-3.969683028665376e1, 2.209460984245205e2, -2.759285104469687e2, 1.38357751867269e2, -3.066479806614716e1, 2.506628277459239];
    const B: [f64; 5] = [-5.447609879822406e1, 1.615858368580409e2, -1.556989798598866e2, 6.680131188771972e1, -1.328068155288572e1];
    const C: [f64; 6] =
        [-7.784894002430293e-3, -3.223964580411365e-1, -2.400758277161838, -2.549732539343734, 4.374664141464968, 2.938163982698783];
    const D: [f64; 4] = [7.784695709041462e-3, 3.224671290700398e-1, 2.445134137142996, 3.754408661907416];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5]) / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let x = if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    let e = normal_cdf(x) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (x * x / 2.0).exp();
    x - u / (1.0 + x * u / 2.0)
}

/// The Wilson score interval of `passed` of `n` at 95 % (z = 1.959964): (low, high).
pub fn wilson_95(passed: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let z = 1.959_963_984_540_054_f64;
    let (n, p) = (n as f64, passed as f64 / n as f64);
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// The `q` quantile (0..=1) of `x` by linear interpolation between order statistics (the
/// "type 7" of Hyndman and Fan, numpy's default); NaN for no data.
pub fn percentile(x: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let h = (v.len() - 1) as f64 * q;
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    v[lo] + (h - lo as f64) * (v[hi] - v[lo])
}

/// Ranks 1..=n, ties given their mean rank.
fn ranks(x: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut r = vec![0.0; x.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && x[idx[j + 1]] == x[idx[i]] {
            j += 1;
        }
        for &k in &idx[i..=j] {
            r[k] = (i + j) as f64 / 2.0 + 1.0;
        }
        i = j + 1;
    }
    r
}

/// Spearman's rank correlation of the pairs whose both values are finite; NaN when either side
/// is constant or fewer than 3 pairs remain.
pub fn spearman(x: &[f64], y: &[f64]) -> f64 {
    let (x, y): (Vec<f64>, Vec<f64>) = x.iter().zip(y).filter(|(a, b)| a.is_finite() && b.is_finite()).map(|(a, b)| (*a, *b)).unzip();
    if x.len() < 3 {
        return f64::NAN;
    }
    let (rx, ry) = (ranks(&x), ranks(&y));
    let n = rx.len() as f64;
    let (mx, my) = (rx.iter().sum::<f64>() / n, ry.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in rx.iter().zip(&ry) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx).powi(2);
        syy += (b - my).powi(2);
    }
    if sxx == 0.0 || syy == 0.0 {
        f64::NAN
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantile_inverts_the_cdf_and_matches_tables() {
        // table values of Φ⁻¹ (Abramowitz & Stegun 26.2): 0.975 -> 1.959964, 0.9 -> 1.281552
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-12);
        assert!((normal_quantile(0.9) - 1.281_551_565_544_601).abs() < 1e-12);
        for p in [1e-10, 1e-4, 0.01, 0.3, 0.5, 0.77, 0.99, 1.0 - 1e-7] {
            assert!((normal_cdf(normal_quantile(p)) - p).abs() < 4e-16 + 1e-12 * p, "{p}");
        }
        assert_eq!(normal_quantile(0.5), 0.0);
    }

    #[test]
    fn wilson_matches_its_published_example() {
        // Newcombe (1998), Table I: 81 of 263 -> 0.2553 to 0.3662 ; 0 of 10 -> 0 to 0.2775
        let (lo, hi) = wilson_95(81, 263);
        assert!((lo - 0.2553).abs() < 5e-5 && (hi - 0.3662).abs() < 5e-5, "{lo} {hi}");
        let (lo, hi) = wilson_95(0, 10);
        assert!(lo == 0.0 && (hi - 0.2775).abs() < 5e-5, "{hi}");
    }

    #[test]
    fn spearman_of_monotone_and_reversed_and_ties() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(spearman(&x, &[1.0, 4.0, 9.0, 16.0, 25.0]), 1.0);
        assert_eq!(spearman(&x, &[5.0, 3.0, 2.0, 1.0, 0.0]), -1.0);
        assert!(spearman(&x, &[1.0; 5]).is_nan());
        // with ties: the Pearson correlation of the mid-ranks [1, 2.5, 2.5, 4] and [1, 2, 3, 4]
        let r = spearman(&[1.0, 2.0, 2.0, 3.0], &[1.0, 2.0, 3.0, 4.0]);
        assert!((r - 4.5 / (4.5f64 * 5.0).sqrt()).abs() < 1e-15, "{r}");
    }

    #[test]
    fn percentiles_interpolate_like_numpy() {
        let x = [4.0, 1.0, 3.0, 2.0];
        // numpy.percentile([1,2,3,4], [0, 50, 90]) = 1, 2.5, 3.7
        assert_eq!((percentile(&x, 0.0), percentile(&x, 0.5)), (1.0, 2.5));
        assert!((percentile(&x, 0.9) - 3.7).abs() < 1e-15);
        assert!(percentile(&[], 0.5).is_nan());
    }
}
