//! `rig design` without the launcher: `design [SCENARIO] [Z_A_MM] [OUT]`.
fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    design::cli::run(design::cli::DesignArgs {
        scenario: a.get(1).map(Into::into),
        z_a_mm: a.get(2).map_or(20.0, |x| x.parse().unwrap()),
        out: a.get(3).map_or("runs/design".into(), Into::into),
        cache_dir: Some("target/strip-cache".into()),
        egm: false,
    })
}
