//! Prints one line every `every` ticks of a recording: tick, q, force ref/meas, pos error, strip
//! contact force (a debugging aid for scenario tuning).
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rec = recording_tools::read::Recording::open(&args[1]).unwrap();
    let every: usize = args.get(2).map_or(50, |s| s.parse().unwrap());
    for (i, s) in rec.joint_state.iter().enumerate().step_by(every) {
        let d = rec.controller.get(i);
        let st = rec.strip.get(i);
        println!(
            "{:5} q2 {:.6} q3 {:.6} qd2 {:+.5} | Fref {:+.3} Fmeas {:+.3} ey {:+.6} ez {:+.6} | contact {:+.3} bottom {:+.3} z {:.4}",
            s.tick,
            s.q[1],
            s.q[2],
            s.qd[1],
            d.map_or(0.0, |d| d.force_ref_n),
            d.map_or(0.0, |d| d.force_meas_n),
            d.map_or(0.0, |d| d.pos_err_task_m[1]),
            d.map_or(0.0, |d| d.pos_err_task_m[2]),
            st.map_or(0.0, |s| s.contact_force_n),
            st.map_or(0.0, |s| s.bottom_force_n),
            st.map_or(0.0, |s| s.wheel_z_m * 1e3)
        );
    }
}
