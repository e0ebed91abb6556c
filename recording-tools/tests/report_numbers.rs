//! `rig report` numbers on a synthetic recording whose contents are known in closed form
//! (see `recordings::synthetic`).

use recording_tools::read::Recording;
use recording_tools::report::{self, BOND_PRESSURE_PA};
use recordings::synthetic::SyntheticRun;
use recordings::RecorderConfig;

#[test]
fn report_on_a_known_recording_gives_the_known_numbers() {
    let run = SyntheticRun::default();
    let dir = std::env::temp_dir().join(format!("recordings-report-{}", std::process::id()));
    let path = dir.join("known.mcap");
    run.record(RecorderConfig::new(&path, run.metadata())).unwrap();
    let rec = Recording::open_complete(&path).unwrap();
    let n = report::numbers(&rec);

    assert_eq!(n.ticks as u64, run.ticks);
    assert!((n.duration_s - run.ticks as f64 * run.period_s).abs() < 1e-12);
    assert_eq!(n.misses, (0..run.ticks).filter(|&k| run.is_miss(k)).count() as u64);
    assert_eq!(n.misses, 3);
    assert_eq!(n.safe_stops, 1);
    assert_eq!(n.dropped, 0);
    assert_eq!(n.events, 4);
    let kinds: Vec<&str> = n.event_list.iter().map(|e| e.kind.as_str()).collect();
    assert_eq!(kinds, ["start", "safe_stop", "safe_stop_cleared", "stop"]);
    assert_eq!((n.event_list[1].tick, n.event_list[1].text.as_str()), (run.ticks / 2, "synthetic safe stop"));

    // Latency: smallest value with at least p of the in-time ticks at or below it, counted
    // directly from the run's round-trip law.
    let lat: Vec<u64> = (0..run.ticks).filter(|&k| !run.is_miss(k)).map(|k| run.round_trip_ns(k)).collect();
    let nearest_rank = |p: f64| {
        let need = (p * lat.len() as f64).ceil() as usize;
        (0..=200_000u64).step_by(1000).find(|&v| lat.iter().filter(|&&x| x <= v).count() >= need).unwrap() as f64 * 1e-3
    };
    let l = n.latency_us.unwrap();
    assert_eq!(l.n, lat.len());
    assert_eq!((l.p50, l.p90, l.p99), (nearest_rank(0.5), nearest_rank(0.9), nearest_rank(0.99)));
    assert_eq!(l.max, *lat.iter().max().unwrap() as f64 * 1e-3);

    let r = n.rolling.clone().expect("the wheel rolls");
    assert_eq!(r.ticks as u64, run.roll_ticks);
    assert_eq!((r.z_from_m, r.z_to_m), (run.z_start_m, run.z_end_m));
    assert!((r.rolled_length_m - (run.z_end_m - run.z_start_m)).abs() < 1e-12, "monotone roll: length telescopes");
    // A sin over m whole periods sampled N times: max A, RMS A / sqrt(2), mean 0.
    let a = run.force_error_n;
    assert!((r.force_error_max_abs_n.unwrap() - a).abs() < 1e-9, "{r:?}");
    assert!((r.force_error_rms_n.unwrap() - a / 2f64.sqrt()).abs() < 1e-9, "{r:?}");
    assert!(r.force_error_mean_n.unwrap().abs() < 1e-9, "{r:?}");
    // Bond share: the peak under the wheel is >= 100 kPa exactly while z < coverage_z (and the
    // Gaussian between two nodes stays above 100 kPa), so the pressed length telescopes to the
    // last wheel position below coverage_z.
    assert!(run.peak_pressure_pa * (-(0.25f64 / 2.0).powi(2)).exp() > BOND_PRESSURE_PA && run.peak_pressure_pa / 3.0 < BOND_PRESSURE_PA);
    let last_below = (0..run.ticks)
        .filter(|&k| run.is_rolling(k) && run.wheel_z_m(k) < run.coverage_z_m)
        .map(|k| run.wheel_z_m(k))
        .fold(f64::MIN, f64::max);
    let want = (last_below - run.z_start_m) / (run.z_end_m - run.z_start_m);
    let share = r.bond_pressure_share.unwrap();
    assert!((share - want).abs() < 1e-12, "{share} vs {want}");
    assert!((share - 0.75).abs() < 1e-3, "{share}: the closed form (29 - 2) / 36 within one tick's step");
    // Weakest under the wheel: past coverage_z the peak is a third; between two nodes 0.5 mm
    // apart the interpolated Gaussian dips to at most exp(-(0.25/2)^2) of it.
    let [p, z] = r.bond_weakest_pa_at_z_m.unwrap();
    let third = run.peak_pressure_pa / 3.0;
    assert!(
        z >= run.coverage_z_m && p <= third * (1.0 + 1e-12) && p >= third * (-(0.25f64 / 2.0).powi(2)).exp() * (1.0 - 1e-12),
        "{p} Pa at {z} m"
    );

    let text = report::format_text(&n);
    assert!(text.contains("misses      3") && text.contains("safe stops  1") && text.contains("75.0 %"), "{text}");
}

#[test]
fn report_writes_text_json_and_every_figure() {
    let run = SyntheticRun { ticks: 2600, ..Default::default() };
    let dir = std::env::temp_dir().join(format!("recordings-report-files-{}", std::process::id()));
    let path = dir.join("figs.mcap");
    run.record(RecorderConfig::new(&path, run.metadata())).unwrap();
    let rec = Recording::open_complete(&path).unwrap();
    let out = dir.join("report");
    let (n, files) = report::write_report(&rec, &out, &[]).unwrap();
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&files.json).unwrap()).unwrap();
    assert_eq!(json["ticks"], 2600);
    assert_eq!(json["misses"], n.misses);
    assert!(std::fs::read_to_string(&files.text).unwrap().contains("safe stops  1"));
    for stem in ["force_tracking", "bond_pressure", "bottom_pressure", "joint_torques", "latency_histogram"] {
        for ext in ["png", "svg"] {
            let f = out.join(format!("{stem}.{ext}"));
            assert!(files.figures.contains(&f), "{} missing from {:?}", f.display(), files.figures);
            assert!(std::fs::metadata(&f).unwrap().len() > 1000, "{} is empty", f.display());
        }
    }
    // Default instants: the wheel at 10..90 % of its roll, in order.
    let inst = report::default_instants(&rec);
    assert_eq!(inst.len(), 5);
    assert!(inst.windows(2).all(|w| w[0] < w[1]));
    let svg = std::fs::read_to_string(out.join("bottom_pressure.svg")).unwrap();
    assert!(svg.contains("100 kPa bond pressure") && svg.contains("wheel at"), "legend missing");
}

/// `rig run`'s read-back decodes only the channels the numbers read
/// (`report::NUMBERS_CHANNELS`): the same numbers and the same integrity verdict as a whole
/// read, for a complete file, a cut one and one with a damaged chunk; the skipped channels'
/// columns stay empty.
#[test]
fn the_summary_channels_give_the_numbers_of_the_whole_recording() {
    use recording_tools::read::Channels;
    let run = SyntheticRun { ticks: 2600, ..Default::default() };
    let dir = std::env::temp_dir().join(format!("recordings-report-channels-{}", std::process::id()));
    let path = dir.join("whole.mcap");
    let mut cfg = RecorderConfig::new(&path, run.metadata());
    cfg.chunk_size_bytes = 64 << 10;
    run.record(cfg).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).unwrap();
    // One byte flipped in the middle of the file: inside a chunk, which then fails its CRC.
    let damaged = dir.join("damaged.mcap");
    let mut d = bytes.clone();
    d[bytes.len() / 2] ^= 0x5a;
    std::fs::write(&damaged, &d).unwrap();
    for (p, kind) in [(&path, "complete"), (&cut, "cut"), (&damaged, "corrupt")] {
        let whole = Recording::open(p).unwrap();
        let some = Recording::open_channels(p, report::NUMBERS_CHANNELS).unwrap();
        assert_eq!(whole.integrity, some.integrity, "{}", p.display());
        assert_eq!(report::numbers(&some), report::numbers(&whole), "{}", p.display());
        assert_eq!(report::numbers(&some).integrity, kind, "{}", p.display());
        assert_eq!(recording_tools::cli::summary_numbers(p).unwrap(), report::numbers(&whole));
        assert!(!whole.joint_torque.is_empty() && !whole.wrench.is_empty());
        assert!(some.joint_torque.is_empty() && some.wrench.is_empty());
        assert_eq!(
            (some.joint_state.len(), some.strip.len(), some.timing.len()),
            (whole.joint_state.len(), whole.strip.len(), whole.timing.len())
        );
        // No other channel: the integrity is still found from every chunk (and /joint_state).
        assert_eq!(Recording::open_channels(p, Channels::of(&[])).unwrap().integrity, whole.integrity);
    }
}
