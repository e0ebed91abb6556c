//! Figure 7.4 check: `stress RUN.mcap SCENARIO.toml [Z_MM]`.
fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    let rec = recording_tools::read::Recording::open(&a[1])?;
    let s = scenarios::Scenario::load(std::path::Path::new(&a[2]))?;
    let z: f64 = a.get(3).map_or(8.0, |x| x.parse().unwrap());
    let model = strip::StripModel::load_or_build_in(std::path::Path::new("target/strip-cache"), &plant_sim::contact::strip_params(&s))?;
    let c = design::stress::compare_at(&rec, &model, z * 1e-3)?;
    println!(
        "tick {} wheel z {:.3} mm force {:.3} N: max |recorded - full static| / peak = {:.2} %",
        c.tick,
        c.wheel_z_m * 1e3,
        c.wheel_force_n,
        100.0 * c.max_rel_diff
    );
    for (z, r, f) in &c.profile {
        println!("  z {:5.1} mm  recorded {:8.1} kPa  full static {:8.1} kPa", z * 1e3, r / 1e3, f / 1e3);
    }
    Ok(())
}
