//! Acceptance numbers from a recording: `measure RUN.mcap`.
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let rec = recording_tools::read::Recording::open(&args[1])?;
    let t = design::metrics::tracking_from_recording(&rec)?;
    println!("tracking over the roll: max {:.4} N, rms {:.4} N ({} ticks)", t.max_n, t.rms_n, t.samples);
    let p = design::metrics::peak_centreline_pressure(&rec, 4e-3, 36e-3);
    let worst = p.iter().cloned().fold((0.0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    if std::env::var("VERBOSE").is_ok() {
        for (z, pk) in &p {
            println!("  z = {:.1} mm: peak {:.1} kPa", z * 1e3, pk / 1e3);
        }
    }
    println!("bond: {} nodes in [4, 36] mm, lowest peak pressure {:.1} kPa at z = {:.1} mm", p.len(), worst.1 / 1e3, worst.0 * 1e3);
    Ok(())
}
