//! Per-stage wall times of repeated cold builds (min and median over runs of `info.timings_s`):
//! `cargo run --release -p strip --example stages -- [element_mm] [runs]`.
use std::collections::BTreeMap;
use strip::{StripModel, StripParams};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let h: f64 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(1.0);
    let runs: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(5);
    let p = StripParams { element_m: h * 1e-3, ..Default::default() };
    let mut best: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut order = Vec::new();
    for _ in 0..runs {
        let t = std::time::Instant::now();
        let m = StripModel::build(&p).unwrap();
        let tot = t.elapsed().as_secs_f64();
        for (k, v) in m.info.timings_s.iter().cloned().chain([("total".to_string(), tot)]) {
            if !best.contains_key(&k) {
                order.push(k.clone());
            }
            best.entry(k).or_default().push(v);
        }
    }
    for k in order {
        let mut v = best[&k].clone();
        v.sort_by(f64::total_cmp);
        println!("{k:<44} min {:7.3}  median {:7.3}", v[0], v[v.len() / 2]);
    }
}
