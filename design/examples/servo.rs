//! Debug: in-process servo run of a scenario; prints tracking numbers.
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let s = scenarios::Scenario::load(std::path::Path::new(&args[1]))?;
    let run = design::servo::run_servo_full(&s, std::path::Path::new("target/strip-cache"), 0.0)?;
    if let Some((z, p)) = run.weakest_bond(4e-3, 36e-3) {
        println!("weakest bond in [4, 36] mm: {:.1} kPa at z = {:.1} mm", p / 1e3, z * 1e3);
    }
    let samples = run.samples;
    let every: usize = args.get(2).map_or(100, |x| x.parse().unwrap());
    for x in samples.iter().step_by(every) {
        println!(
            "{:.3} {:?} ref={:.3} f={:.3} bot={:.3} z={:.4}",
            x.t_s, x.phase, x.force_ref_n, x.contact_force_n, x.bottom_force_n, x.wheel_z_m
        );
    }
    println!("{:?}", design::servo::tracking(&samples));
    Ok(())
}
