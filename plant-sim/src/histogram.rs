//! Fixed-bucket latency histogram: allocated once before the loop starts, then `record` is a
//! bounds check and an increment (no allocation, no locks), so the 1 kHz thread can keep exact
//! distributions of round-trip latency, period jitter and compute times for the whole run.

/// Linear buckets of `bucket_ns` from 0 to `bucket_ns * n`, an overflow bucket above, and the
/// exact maximum.
#[derive(Debug, Clone)]
pub struct Histogram {
    bucket_ns: u64,
    counts: Box<[u64]>,
    overflow: u64,
    count: u64,
    max_ns: u64,
    sum_ns: u128,
}

impl Histogram {
    /// `n_buckets` linear buckets of `bucket_ns` each.
    pub fn new(bucket_ns: u64, n_buckets: usize) -> Histogram {
        assert!(bucket_ns > 0 && n_buckets > 0);
        Histogram { bucket_ns, counts: vec![0; n_buckets].into_boxed_slice(), overflow: 0, count: 0, max_ns: 0, sum_ns: 0 }
    }

    /// 100 ns resolution up to 5 ms: enough for latencies and jitter of a 1 ms loop.
    pub fn for_latency() -> Histogram {
        Histogram::new(100, 50_000)
    }

    #[inline]
    pub fn record(&mut self, ns: u64) {
        let i = (ns / self.bucket_ns) as usize;
        match self.counts.get_mut(i) {
            Some(c) => *c += 1,
            None => self.overflow += 1,
        }
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns += ns as u128;
    }

    pub fn count(&self) -> u64 {
        self.count
    }
    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }
    pub fn mean_ns(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64
        }
    }

    /// The value below which a fraction `p` (0..=1) of the samples lie: the upper edge of the
    /// bucket holding the p-quantile (so never optimistic by more than one bucket), or the exact
    /// maximum if it falls into the overflow. 0 without samples.
    pub fn quantile_ns(&self, p: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let rank = ((p.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return ((i as u64 + 1) * self.bucket_ns).min(self.max_ns);
            }
        }
        self.max_ns
    }

    /// Counts in coarser bins `[lo_ns, hi_ns)` with the given edges (the last bin open-ended),
    /// for printing.
    pub fn binned(&self, edges_ns: &[u64]) -> Vec<(u64, u64, u64)> {
        let mut out: Vec<(u64, u64, u64)> =
            edges_ns.windows(2).map(|w| (w[0], w[1], 0)).chain(std::iter::once((*edges_ns.last().unwrap(), u64::MAX, 0))).collect();
        let mut add = |v: u64, c: u64| {
            if let Some(b) = out.iter_mut().find(|b| v >= b.0 && v < b.1) {
                b.2 += c;
            }
        };
        for (i, &c) in self.counts.iter().enumerate() {
            if c > 0 {
                add(i as u64 * self.bucket_ns, c);
            }
        }
        if self.overflow > 0 {
            add(self.counts.len() as u64 * self.bucket_ns, self.overflow);
        }
        out
    }

    /// The summary's form: count, mean, p50, p90, p99, p99.9, p99.99, max (µs) and a binned
    /// histogram with bins at `edges_us` (the last one open-ended).
    pub fn distribution(&self, edges_us: &[f64]) -> recordings::plant_summary::Distribution {
        let us = |ns: u64| ns as f64 * 1e-3;
        let edges_ns: Vec<u64> = edges_us.iter().map(|e| (e * 1e3) as u64).collect();
        recordings::plant_summary::Distribution {
            count: self.count,
            mean_us: self.mean_ns() * 1e-3,
            p50_us: us(self.quantile_ns(0.5)),
            p90_us: us(self.quantile_ns(0.9)),
            p99_us: us(self.quantile_ns(0.99)),
            p999_us: us(self.quantile_ns(0.999)),
            p9999_us: us(self.quantile_ns(0.9999)),
            max_us: us(self.max_ns),
            bins: self.binned(&edges_ns).iter().map(|&(lo, hi, c)| (us(lo), (hi != u64::MAX).then(|| us(hi)), c)).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_uniform_ramp() {
        let mut h = Histogram::new(10, 1000);
        for v in 0..10_000u64 {
            h.record(v);
        }
        // Exact p-quantile of 0..9999 is about p*10000; bucket upper edges are within 10 ns.
        for p in [0.5, 0.9, 0.99] {
            let exact = (p * 10_000.0) as u64;
            let got = h.quantile_ns(p);
            assert!(got >= exact && got <= exact + 10, "p{p}: {got} vs {exact}");
        }
        assert_eq!(h.max_ns(), 9_999);
        assert!((h.mean_ns() - 4999.5).abs() < 1e-9);
    }

    #[test]
    fn overflow_reports_the_exact_maximum_and_bins_add_up() {
        let mut h = Histogram::new(100, 10);
        for v in [50, 150, 950, 5_000, 70_000] {
            h.record(v);
        }
        assert_eq!(h.quantile_ns(1.0), 70_000);
        assert_eq!(h.quantile_ns(0.2), 100);
        let bins = h.binned(&[0, 500, 1000]);
        assert_eq!(bins.iter().map(|b| b.2).sum::<u64>(), 5);
        assert_eq!(bins[0].2, 2);
        assert_eq!(bins[1].2, 1);
        assert_eq!(bins[2].2, 2);
    }
}
