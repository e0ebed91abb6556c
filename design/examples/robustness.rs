//! Robustness table of issue 6 (in-process 6-DOF servo, lockstep-equivalent):
//! `robustness [CACHE_DIR]` prints max/RMS rolling-phase tracking for bulge heights 0.1/0.2/0.4 mm,
//! roll times 1/2/4 s and plant inertia ±10 %, with and without integral action, plus the
//! substep-halving check.
use scenarios::Scenario;

fn main() -> anyhow::Result<()> {
    let cache = std::env::args().nth(1).unwrap_or_else(|| "target/strip-cache".into());
    let cache = std::path::Path::new(&cache);
    let base = Scenario::load(&Scenario::default_file())?;
    let only: Option<String> = std::env::args().nth(2);
    let mut cases: Vec<(String, Scenario)> = Vec::new();
    for integral in [true, false] {
        let tag = if integral { "integral" } else { "thesis  " };
        let mut s0 = base.clone();
        s0.controller.force_integral = integral;
        s0.controller.force_rate_feedforward = integral; // the thesis controller has neither
        cases.push((format!("{tag} nominal (0.2 mm, 2 s, 1.0)"), s0.clone()));
        for h in [0.1, 0.4] {
            let mut s = s0.clone();
            s.bulge.height_mm = h;
            cases.push((format!("{tag} bulge {h} mm"), s));
        }
        for r in [1.0, 4.0] {
            let mut s = s0.clone();
            s.trajectory.roll_s = r;
            cases.push((format!("{tag} roll {r} s"), s));
        }
        for k in [0.9, 1.1] {
            let mut s = s0.clone();
            s.robot.plant_inertia_scale = k;
            cases.push((format!("{tag} plant inertia x{k}"), s));
        }
        let mut s = s0.clone();
        s.loop_.substeps = 20;
        cases.push((format!("{tag} substeps 20 (vs 10)"), s));
    }
    println!("| case | max error (N) | RMS error (N) | weakest bond z in [4, 36] mm |\n|---|---|---|---|");
    for (name, s) in cases {
        if only.as_ref().is_some_and(|o| !name.contains(o.as_str())) {
            continue;
        }
        let run = design::servo::run_servo_full(&s, cache, 0.0)?;
        let t = design::servo::tracking(&run.samples);
        let (zb, pb) = run.weakest_bond(4e-3, 36e-3).unwrap_or((f64::NAN, f64::NAN));
        println!("| {name} | {:.4} | {:.4} | {:.0} kPa at {:.0} mm |", t.max_n, t.rms_n, pb / 1e3, zb * 1e3);
    }
    Ok(())
}
