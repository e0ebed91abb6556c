//! Debug: print the first ticks of a recording.
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let r = recording_tools::read::Recording::open(&args[1])?;
    let from: usize = args.get(2).map_or(0, |s| s.parse().unwrap());
    let n: usize = args.get(3).map_or(20, |s| s.parse().unwrap());
    for i in from..(from + n).min(r.joint_state.len()) {
        let s = &r.joint_state[i];
        let t = &r.joint_torque[i];
        let st = &r.strip[i];
        println!(
            "{} st={} q={:?} qd={:?} tau={:?} f={:.3} bot={:.3} z={:.4}",
            s.tick,
            s.plant_status,
            s.q.map(|x| (x * 1e4).round() / 1e4),
            s.qd.map(|x| (x * 1e3).round() / 1e3),
            t.torque.tau.map(|x| x.round()),
            st.contact_force_n,
            st.bottom_force_n,
            st.wheel_z_m
        );
    }
    Ok(())
}
