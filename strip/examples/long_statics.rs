//! Issue 25 in statics: the decay length of a wheel load on the full FE model of a long bonded
//! strip, and the window chain against that full model.
//!
//! `cargo run --release -p strip --example long_statics -- [strip_mm 160] [window_mm 40] [spacing_mm 10] [element_mm 1]`
use std::time::Instant;

use strip::chain::{compare, validation_positions, ChainStatics, FullStatics, WindowChain};
use strip::{StripModel, StripParams};

fn main() {
    let arg = |i: usize, d: f64| std::env::args().nth(i).map(|s| s.parse::<f64>().expect("number")).unwrap_or(d);
    let (ls, lw, sp, h) = (arg(1, 160.0) * 1e-3, arg(2, 40.0) * 1e-3, arg(3, 10.0) * 1e-3, arg(4, 1.0) * 1e-3);
    let force = -10.0;
    let t = Instant::now();
    let full = FullStatics::build(&StripParams { length_m: ls, element_m: h, ..Default::default() }).expect("full model");
    println!("full model {:.0} mm, {} free DOF, built and factored in {:.2} s", ls * 1e3, full.sys.n_free(), t.elapsed().as_secs_f64());
    let line = full.centre_line();

    // decay along the strip: wheel in the middle, centre-line pressure and top u_y against distance
    let mid = 0.5 * ls;
    let (out, _) = full.wheel(mid, force);
    let p: Vec<f64> = line.iter().map(|&(i, _, a)| out.bottom_reaction_n[i] / a).collect();
    let peak = p.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let top_centre: Vec<(f64, f64)> =
        full.top_xyz_m.iter().zip(&out.top_uy_m).filter(|(x, _)| x[0].abs() < 1e-9 && x[1] > 7.9e-3).map(|(x, u)| (x[2], *u)).collect();
    let u_peak = top_centre.iter().fold(0.0f64, |m, v| m.max(v.1.abs()));
    println!("decay from a {force} N wheel at z = {:.1} mm (centre line; |value| / peak):", mid * 1e3);
    println!("  d (mm)   bottom pressure   top u_y (crest)");
    for d in [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 25.0, 30.0] {
        let z = mid + d * 1e-3;
        let pj = line.iter().position(|l| (l.1 - z).abs() < 0.5 * h).map(|j| p[j] / peak).unwrap_or(f64::NAN);
        let uj = top_centre.iter().find(|l| (l.0 - z).abs() < 0.5 * h).map(|l| l.1 / u_peak).unwrap_or(f64::NAN);
        println!("  {d:6.1}   {pj:+15.3e}   {uj:+15.3e}");
    }
    let beyond =
        |frac: f64| line.iter().zip(&p).filter(|(l, v)| v.abs() > frac * peak && l.1 >= mid).map(|(l, _)| l.1 - mid).fold(0.0f64, f64::max);
    println!("  |pressure| > 1 % of peak up to {:.1} mm from the wheel, > 0.1 % up to {:.1} mm", beyond(1e-2) * 1e3, beyond(1e-3) * 1e3);
    // e-folding length: least squares of ln|p| over 1 %..0.01 % of the peak, beyond the wheel
    let pts: Vec<(f64, f64)> = line
        .iter()
        .zip(&p)
        .filter(|(l, v)| l.1 > mid && v.abs() < 1e-2 * peak && v.abs() > 1e-4 * peak)
        .map(|(l, v)| (l.1 - mid, v.abs().ln()))
        .collect();
    if pts.len() >= 2 {
        let n = pts.len() as f64;
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, q| (a.0 + q.0, a.1 + q.1));
        let (sxx, sxy) = pts.iter().fold((0.0, 0.0), |a, q| (a.0 + q.0 * q.0, a.1 + q.0 * q.1));
        let slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
        println!("  e-folding length of |pressure| (fit over {} nodes at 1e-2..1e-4 of peak): {:.2} mm", pts.len(), -1e3 / slope);
    }

    // free-end effect: the wheel d from the strip's end against the wheel in the middle
    let uy = |z: f64| {
        let (o, w) = full.wheel(z, force);
        w.iter().zip(&o.top_uy_m).map(|(a, b)| a * b).sum::<f64>()
    };
    let u_mid = uy(mid);
    println!("free-end effect on the displacement under the wheel (u(d) / u(middle) - 1):");
    for d in [4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0] {
        println!("  d = {d:5.1} mm: {:+.3e}", uy(d * 1e-3) / u_mid - 1.0);
    }

    // the chain against the full model
    let t = Instant::now();
    let window = StripModel::load_or_build(&StripParams { length_m: lw, element_m: h, ..Default::default() }).expect("window model");
    let chain = WindowChain::new(ls, lw, sp, h).expect("chain");
    let cs = ChainStatics::new(window, chain.clone()).expect("chain statics");
    println!(
        "chain: {} windows of {:.0} mm, spacing {:.0} mm, hand-over points {:?} mm ({:.2} s)",
        chain.len(),
        lw * 1e3,
        sp * 1e3,
        chain.hand_over_points_m().iter().map(|z| (z * 1e4).round() / 10.0).collect::<Vec<_>>(),
        t.elapsed().as_secs_f64()
    );
    let cmp = compare(&cs, &full, &validation_positions(&chain, 40), force);
    println!("  z_a (mm)   u_y full (mm)  err       p full (kPa)  err       profile err (at z mm)");
    for c in &cmp {
        println!(
            "  {:8.2}   {:12.5}  {:.2e}  {:11.3}  {:.2e}  {:.2e} ({:.0})",
            c.z_a_m * 1e3,
            c.wheel_uy_m[0] * 1e3,
            c.uy_err_rel(),
            c.pressure_pa[0] * 1e-3,
            c.pressure_err_rel(),
            c.profile_err_rel,
            c.profile_err_z_m * 1e3
        );
    }
    let worst = |f: &dyn Fn(&strip::chain::Comparison) -> f64| {
        cmp.iter().map(|c| (f(c), c.z_a_m)).fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a })
    };
    let (e, z) = worst(&|c| c.uy_err_rel());
    println!("worst displacement error {:.3e} at z = {:.2} mm", e, z * 1e3);
    let (e, z) = worst(&|c| c.stiffness_err_rel());
    println!("worst driving-point stiffness error {:.3e} at z = {:.2} mm", e, z * 1e3);
    let (e, z) = worst(&|c| c.pressure_err_rel());
    println!("worst centre-line pressure (under the wheel) error {:.3e} at z = {:.2} mm", e, z * 1e3);
    let (e, z) = worst(&|c| c.profile_err_rel);
    println!("worst centre-line pressure profile error (over the peak) {:.3e} at z = {:.2} mm", e, z * 1e3);
}
