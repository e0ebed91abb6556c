//! The long straight seal (issue 25) end to end: the real `plant-sim` carrying the 600 mm strip
//! on its chain of 40 mm windows and the real `controller`, LOCKSTEP, read back from the MCAP
//! recording. Build first: `cargo build --release --workspace --bins`.
//!
//! - Window hand-overs: the measured force (the sensor's wrench) steps at no hand-over (the
//!   wheel crossing a window centre, where a window's share reaches 0 or 1 and a pool slot is
//!   reused) by more than its largest tick-to-tick change away from them (more than 2 mm from
//!   every centre, bumps, dips and the seam included). Both numbers are printed.
//! - The true bottom force within the thesis' 0.45 N of the set-point over the whole rolled
//!   length (`recording_tools::report::force_tracking`, what `rig run` prints).
//! - The bond map (`rig report`, `recording_tools::bond_map`): on the flat stretches the peak
//!   pressure per millimetre against the full FE model of a flat strip under a static wheel; every
//!   bump, dip and the seam listed with its worst pressure and the force error near it.

use std::path::Path;
use std::time::Duration;

use harness::*;
use recording_tools::read::Recording;
use scenarios::Scenario;

#[test]
fn long_seal_hands_over_between_windows_without_a_force_step_and_tracks_within_the_thesis_bound() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/long_seal.toml");
    let s = Scenario::load(&path).unwrap();
    let rig = unique_rig("long-seal");
    let dir = temp_dir(&rig);
    let out = dir.join("run.mcap");
    let sc = path.to_str().unwrap();
    let mut plant = Daemon::start(
        "plant",
        &bin("plant-sim"),
        &["--rig", &rig, "--scenario", sc, "--mode", "lockstep", "--out", out.to_str().unwrap()],
        &dir,
    );
    let mut ctrl = start_controller("controller", "controller", &rig, &path, &dir, &[]);
    let ps = plant.expect_exit(Duration::from_secs(600));
    assert!(ps.success(), "plant failed: {}", plant.stderr());
    assert!(ctrl.expect_exit(Duration::from_secs(10)).success(), "controller failed: {}", ctrl.stderr());
    let summary = plant_summary(&plant);
    assert_eq!(summary["misses"], 0, "{summary}");
    assert_eq!(summary["safe_stops"], 0, "{summary}");
    let rec = Recording::open_complete(&out).expect("complete recording");

    // Window centres: the hand-over points of the chain.
    let st = &s.strip;
    let chain = strip::chain::WindowChain::new(st.length_mm * 1e-3, st.window_mm * 1e-3, st.window_spacing_mm * 1e-3, st.element_mm * 1e-3)
        .unwrap();
    let centres = chain.hand_over_points_m();
    assert!(centres.len() > 50, "{} windows", centres.len());
    assert_eq!(rec.wrench.len(), rec.strip.len());
    let force = |i: usize| {
        let f = rec.wrench[i].force;
        (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt()
    };
    let (mut at_hand_over, mut away, mut crossed) = (0.0f64, 0.0f64, 0usize);
    let (z_lo, z_hi) = (s.trajectory.z_start_mm * 1e-3 + 5e-3, s.trajectory.z_end_mm * 1e-3 - 5e-3);
    for i in 1..rec.strip.len() {
        let (a, b) = (&rec.strip[i - 1], &rec.strip[i]);
        // rolling, in contact, away from the start and end of the pass (the force ramps)
        if a.contact_force_n >= 0.0 || b.contact_force_n >= 0.0 || b.wheel_z_m <= a.wheel_z_m || a.wheel_z_m < z_lo || b.wheel_z_m > z_hi {
            continue;
        }
        let step = (force(i) - force(i - 1)).abs();
        let nearest = centres.iter().map(|c| (c - b.wheel_z_m).abs()).fold(f64::INFINITY, f64::min);
        if centres.iter().any(|&c| a.wheel_z_m < c && c <= b.wheel_z_m) {
            // the tick of the crossing and its neighbours
            for j in i.saturating_sub(2)..(i + 3).min(rec.strip.len()) {
                at_hand_over = at_hand_over.max((force(j) - force(j - 1)).abs());
            }
            crossed += 1;
        } else if nearest > 2e-3 {
            away = away.max(step);
        }
    }
    let t = recording_tools::report::force_tracking(&rec).expect("a rolling phase");
    eprintln!(
        "long seal: {crossed} hand-overs crossed; largest measured-force step within 2 ticks of a hand-over {at_hand_over:.4} N, largest tick-to-tick change more than 2 mm from every hand-over {away:.4} N; true bottom force error max {:.3} N, RMS {:.3} N over {} rolling ticks",
        t.max_abs_n, t.rms_n, t.samples
    );
    assert!(crossed >= 50, "{crossed} hand-overs crossed");
    assert!(away > 0.0);
    assert!(at_hand_over <= away, "a hand-over steps the force by {at_hand_over} N, more than the {away} N away from them");
    assert!(t.max_abs_n <= 0.45, "true bottom force error {} N", t.max_abs_n);

    // The bond map (`rig report`): on the flat stretches, more than 20 mm from every bump, dip
    // and seam and from the ends of the roll, the peak pressure the wheel left at each millimetre
    // is the peak centre-line pressure under a static wheel of the set-point on the full FE model
    // of a flat 160 mm strip (no windows, no reduction), within the chain's validated 3 %: the
    // wheel rolls slowly against the strip's dynamics and tracks its set-point there.
    let n = recording_tools::report::numbers(&rec);
    let b = n.bond_map.as_ref().expect("the long seal's bond map");
    eprint!(
        "{}",
        recording_tools::report::format_text(&n).lines().skip_while(|l| !l.starts_with("bond map")).collect::<Vec<_>>().join("\n")
    );
    eprintln!();
    let p = strip::StripParams {
        length_m: 0.16,
        bulge_center_m: 0.08,
        bulge_width_m: 0.08,
        bulge_amplitude_m: 0.0,
        ..plant_sim::contact::strip_params(&s)
    };
    let full = strip::chain::FullStatics::build(&p).unwrap();
    let (statics, _) = full.wheel(0.08, s.trajectory.force_ref_n);
    let p_full = full.centre_line().iter().map(|&(i, _, a)| statics.bottom_reaction_n[i] / a).fold(f64::NEG_INFINITY, f64::max);
    let near_feature = |z: f64| b.features.iter().any(|f| z > f.from_m - 20e-3 && z < f.to_m + 20e-3);
    let flat: Vec<(f64, f64)> = b
        .peak_pa
        .iter()
        .enumerate()
        .map(|(g, p)| (g as f64 * b.step_m, p.expect("every millimetre of the rolled strip was sampled")))
        .filter(|&(z, _)| z > b.rolled_from_m + 20e-3 && z < b.rolled_to_m - 20e-3 && !near_feature(z))
        .collect();
    let worst = flat.iter().map(|&(z, p)| ((p - p_full) / p_full, z)).fold((0.0f64, 0.0), |w, e| if e.0.abs() > w.0.abs() { e } else { w });
    eprintln!(
        "bond map: {} flat millimetres against the full FE model's {:.1} kPa under a static {} N wheel: worst {:+.2} % at z = {:.0} mm",
        flat.len(),
        p_full * 1e-3,
        s.trajectory.force_ref_n,
        worst.0 * 100.0,
        worst.1 * 1e3
    );
    assert!(flat.len() > 100, "{} flat millimetres", flat.len());
    assert!(
        worst.0.abs() <= 0.03,
        "the bond map's flat peak is {:+.2} % off the full FE model at z = {} mm",
        worst.0 * 100.0,
        worst.1 * 1e3
    );
    // every feature of the scenario is listed, each with its worst pressure and the force error near it
    assert_eq!(b.features.len(), s.substrate.bumps.len() + s.substrate.seams.len());
    assert!(b.features.iter().all(|f| f.min_peak_pa.is_some() && f.force_error_max_abs_n.is_some()), "{:?}", b.features);
    assert!((0.0..=1.0).contains(&b.coverage_rolled) && b.along.len() == 30);

    // The Foxglove scene: each `/strip_scene` draws the strip's top around the wheel (within a
    // window and a spacing of it) and the substrate along the whole strip, its profile the
    // scenario's bumps, dips and seam (`strip::chain::SubstrateProfile`, closed form).
    let profile = plant_sim::contact::chain::substrate_profile(&s);
    let mut scenes = 0;
    for (wheel, msg) in strip_scenes(&out, &rec) {
        let strip = msg.entities.iter().find(|e| e.id == "strip").expect("the strip");
        let z: Vec<f64> = strip.triangles[0].points.iter().map(|p| p.z).collect();
        let (lo, hi) = (z.iter().copied().fold(f64::INFINITY, f64::min), z.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        let reach = st.window_mm * 1e-3 + st.window_spacing_mm * 1e-3 + 1e-3;
        assert!(lo <= wheel + 1e-3 && hi >= wheel - 1e-3 && wheel - lo <= reach && hi - wheel <= reach, "wheel {wheel}: drawn {lo}..{hi}");
        let sub = msg.entities.iter().find(|e| e.id == "bulge").expect("the substrate");
        let pts = &sub.lines[0].points;
        assert!((pts.last().unwrap().z - st.length_mm * 1e-3).abs() < 1e-9, "the substrate along the whole strip");
        for p in pts {
            assert!((p.y - profile.height_m(p.z)).abs() < 1e-12, "substrate at z {}: {} vs {}", p.z, p.y, profile.height_m(p.z));
        }
        scenes += 1;
    }
    assert!(scenes > 1000, "{scenes} scenes");
}

/// Issue 25's acceptance on the 40 mm default scenario: the default keeps its single model, and
/// the chain of windows on the same strip gives the same force tracking within 1 %. The smallest
/// chain that shows it is the default's strip under one 40 mm window (the window is the whole
/// strip, so the chain's share is 1 everywhere and nothing hands over): what differs is the chain
/// machinery itself (the pool, the summed outputs) and the bulge, which the chain carries as a
/// substrate offset solved on the window's full FE model where the single model carries it in its
/// own tables. Both run `rig run --mode lockstep --in-process` (the transport is transparent,
/// `tick_identity`); the figures held to 1 % are the rolling phase's force error max |e| and RMS
/// (`recording_tools::report::force_tracking`, what `rig run` prints) and the true bottom force's
/// mean and largest magnitude over the same ticks; the mean error (near zero with integral
/// action, so no relative measure) is printed.
#[test]
fn the_default_scenario_on_one_window_of_the_chain_tracks_as_the_single_model_within_one_percent() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let single = Scenario::load(&path).unwrap();
    assert_eq!(single.strip.window_mm, 0.0, "the default keeps the single model");
    let anchor = "boundary = \"bonded\"\n";
    assert!(text.contains(anchor), "the default scenario's [strip] table");
    let windowed = text.replacen(anchor, &format!("{anchor}window_mm = {}\nwindow_spacing_mm = 10\n", single.strip.length_mm), 1);
    let rig = unique_rig("seal-default");
    let dir = temp_dir(&rig);
    let windowed_path = dir.join("default_one_window.toml");
    std::fs::write(&windowed_path, &windowed).unwrap();
    assert_eq!(Scenario::load(&windowed_path).unwrap().strip.window_mm, 40.0);

    let run = |tag: &str, scenario: &Path| -> Recording {
        let out = dir.join(tag);
        let args = ["run", scenario.to_str().unwrap(), "--mode", "lockstep", "--in-process", "--out", out.to_str().unwrap()];
        let mut r = Daemon::start("rig", &bin("rig"), &args, &dir);
        let st = r.expect_exit(Duration::from_secs(300));
        assert!(st.success(), "rig run {tag} failed ({st}):\n{}\n{}", r.stdout(), r.stderr());
        Recording::open_complete(out.join("run.mcap")).expect("complete recording")
    };
    let figures = |rec: &Recording| -> [f64; 5] {
        let t = recording_tools::report::force_tracking(rec).expect("a rolling phase");
        let roll = recording_tools::report::rolling_ticks(rec);
        let bottom: Vec<f64> = roll.iter().map(|&i| rec.strip[i].bottom_force_n.abs()).collect();
        let mean = bottom.iter().sum::<f64>() / bottom.len() as f64;
        [t.max_abs_n, t.rms_n, t.mean_n, mean, bottom.iter().fold(0.0, |m: f64, &b| m.max(b))]
    };
    let rec_a = run("single", &path);
    let rec_b = run("chain", &windowed_path);
    // the single model names its fixed centre-line nodes in the metadata; the chain records them
    // per tick in strip coordinates
    let (meta_a, meta_b) = (rec_a.run_metadata().unwrap(), rec_b.run_metadata().unwrap());
    assert!(meta_a.centreline_z_m.is_some() && meta_b.centreline_z_m.is_none(), "the chain ran");
    let (a, b) = (figures(&rec_a), figures(&rec_b));
    let names = ["force error max |e|", "force error RMS", "force error mean", "mean |bottom force|", "max |bottom force|"];
    for ((name, x), y) in names.iter().zip(a).zip(b) {
        eprintln!(
            "default, 40 mm: {name:<20} single model {x:+.5} N, chain on one window {y:+.5} N, difference {:+.3e} N ({:+.4} %)",
            y - x,
            (y - x) / x.abs() * 100.0
        );
    }
    // the mean error is near zero with integral action: printed, not held to a relative 1 %
    for k in [0, 1, 3, 4] {
        let (name, x, y) = (names[k], a[k], b[k]);
        assert!((y - x).abs() <= 0.01 * x.abs(), "{name}: single model {x} N, chain {y} N: more than 1 % apart");
    }
}
