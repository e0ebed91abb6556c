//! Pipeline acceptance tests: statics full = CB = reduced, equilibrium, stability, Table D.1
//! frequency agreement, ZOH stepping against a dense matrix exponential, cache round trip.

use faer::Mat;
use strip::report::{compare, Report};
use strip::{StripModel, StripParams, StripStepper, Substrate};

fn params_2mm() -> StripParams {
    StripParams { element_m: 2e-3, ..Default::default() }
}

fn report_for(p: &StripParams) -> (Report, StripModel) {
    let (model, art) = StripModel::build_detailed(p).expect("build");
    (compare(&model, &art).expect("report"), model)
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
    let den: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    num / den
}

fn check_statics(r: &Report) {
    let s = &r.statics;
    // equilibrium: the substrate carries the whole 10 N wheel force
    for m in [&s.full, &s.cb, &s.reduced] {
        assert!((m.total_bottom_reaction_n - 10.0).abs() < 1e-8, "sum of reactions {}", m.total_bottom_reaction_n);
        assert!(m.top_displacement_m < 0.0, "pressing moves the top down");
    }
    // CB statics are exact (boundary-loaded), matched DC keeps the CB static gain
    let e1 = rel(&s.cb.top_uy_m, &s.full.top_uy_m);
    let e2 = rel(&s.cb.bottom_reaction_n, &s.full.bottom_reaction_n);
    let e3 = rel(&s.reduced.top_uy_m, &s.cb.top_uy_m);
    let e4 = rel(&s.reduced.bottom_reaction_n, &s.cb.bottom_reaction_n);
    assert!(e1 < 1e-9 && e2 < 1e-9, "CB vs full statics: {e1:e} {e2:e}");
    assert!(e3 < 1e-8 && e4 < 1e-8, "reduced vs CB statics: {e3:e} {e4:e}");
}

#[test]
fn two_millimetre_bonded_pipeline() {
    let (r, model) = report_for(&params_2mm());
    check_statics(&r);
    assert_eq!(r.statics.full.bottom_sideways_max_m, Some(0.0), "bonded bottom cannot slide");
    assert_eq!(model.order(), 250);
    assert!(r.max_real_pole_per_s < 0.0, "reduced model must be stable");
    assert!(r.d_nonzero, "matched DC gives a feed-through");
    // reduced eigenfrequencies equal the CB ones (Table D.1 columns 3 and 4 agree)
    for (a, b) in r.freq_reduced_hz.iter().zip(&r.freq_cb_hz).take(10) {
        assert!((a / b - 1.0).abs() < 2e-3, "reduced {a} vs CB {b}");
    }
}

#[test]
fn sliding_substrate_and_incompressible_limit() {
    let p = StripParams { substrate: Substrate::Sliding, poisson: 0.4999, ..params_2mm() };
    let (r, _) = report_for(&p);
    check_statics(&r);
    assert!(r.max_real_pole_per_s < 0.0);
    // the sliding bottom moves sideways (Figures 4.3, 5.3: a few hundredths of a mm at 10 N),
    // identically in the CB model (statics exact); the bonded one cannot
    let (sf, sc) = (r.statics.full.bottom_sideways_max_m.unwrap(), r.statics.cb.bottom_sideways_max_m.unwrap());
    assert!(sf > 1e-6 && sf < 1e-4, "sliding sideways {sf}");
    assert!((sf - sc).abs() < 1e-9 * sf);
    // nu = 0.4999 does not lock: the wheel stiffness stays within a few percent of nu = 0.49
    let (r49, _) = report_for(&StripParams { poisson: 0.49, ..p.clone() });
    let ratio = r.statics.full.k_s_n_per_m / r49.statics.full.k_s_n_per_m;
    assert!(ratio > 1.0 && ratio < 1.15, "k_s(0.4999)/k_s(0.49) = {ratio}");
}

#[test]
fn one_millimetre_table_d1_and_bond_pressure() {
    let (r, _) = report_for(&StripParams::default());
    check_statics(&r);
    // Table D.1: CB within 1 % of the full model for the modes up to about 1.4 kHz
    for (f, c) in r.freq_full_hz.iter().zip(&r.freq_cb_hz) {
        if *f <= 1.45e3 {
            assert!((f / c - 1.0).abs() < 0.01, "mode at {f} Hz: full/CB = {}", f / c);
        }
    }
    assert!(r.freq_full_hz.iter().filter(|f| **f <= 1.45e3).count() >= 5);
    // Section 4.2 / DESIGN 4: 10 N gives a bit above 100 kPa on the centre line
    let pk = r.statics.full.centreline_peak_pressure_pa;
    assert!(pk > 100e3 && pk < 130e3, "centre-line peak {pk} Pa");
}

/// Dense expm by scaling and squaring of a Taylor series (independent of the modal stepper).
fn expm(a: &Mat<f64>) -> Mat<f64> {
    let norm = a.norm_l1();
    let s = (norm.log2().ceil().max(0.0) as i32) + 1;
    let scaled = a * faer::Scale(0.5f64.powi(s));
    let n = a.nrows();
    let mut term = Mat::<f64>::identity(n, n);
    let mut sum = Mat::<f64>::identity(n, n);
    for k in 1..20 {
        term = &term * &scaled * faer::Scale(1.0 / k as f64);
        sum = &sum + &term;
    }
    for _ in 0..s {
        sum = &sum * &sum;
    }
    sum
}

#[test]
fn zoh_stepper_matches_matrix_exponential_and_settles_to_dc() {
    let model = StripModel::build(&params_2mm()).unwrap();
    let dt = 1e-4;
    let (n, m) = (model.order(), model.n_top());
    // augmented exponential [[A, B], [0, 0]] dt gives Ad and Bd exactly
    let mut aug = Mat::<f64>::zeros(n + m, n + m);
    aug.as_mut().submatrix_mut(0, 0, n, n).copy_from(&model.a);
    aug.as_mut().submatrix_mut(0, n, n, m).copy_from(&model.b);
    let e = expm(&(&aug * faer::Scale(dt)));
    let ad = e.as_ref().submatrix(0, 0, n, n).to_owned();
    let bd = e.as_ref().submatrix(0, n, n, m).to_owned();
    let mut w = vec![0.0; m];
    model.gaussian_weights(0.02, &mut w);
    let u: Vec<f64> = w.iter().map(|wi| -10.0 * wi).collect();
    let um = Mat::from_fn(m, 1, |i, _| u[i]);
    let mut x = Mat::<f64>::zeros(n, 1);
    let mut st = StripStepper::new(&model, dt);
    let mut st_w = StripStepper::new(&model, dt);
    st_w.set_wheel(&w);
    let p = model.c.nrows();
    let (mut top, mut bot) = (vec![0.0; m], vec![0.0; p - m]);
    for k in 0..400 {
        x = &ad * &x + &bd * &um;
        st.step(&u);
        // end-of-step prediction of the wheel point, checked against the output after the step
        let predicted = st_w.wheel_uy_predict() + st_w.wheel_step_compliance() * -10.0;
        st_w.step_wheel(-10.0);
        let after = st_w.wheel_uy_free() + st_w.wheel_compliance() * -10.0;
        assert!((predicted - after).abs() <= 1e-12 * after.abs().max(1e-9), "step {k}: {predicted} vs {after}");
        if k % 50 == 49 {
            let y = &model.c * &x + &model.d * &um;
            st.outputs(&u, &mut top, &mut bot);
            let yv: Vec<f64> = (0..p).map(|i| y[(i, 0)]).collect();
            let sv: Vec<f64> = top.iter().chain(&bot).copied().collect();
            assert!(rel(&sv, &yv) < 1e-8, "step {k}: modal ZOH vs expm {:e}", rel(&sv, &yv));
            // wheel scalar helpers agree with the full output map
            let wu: f64 = w.iter().zip(&top).map(|(a, b)| a * b).sum();
            let ws = st_w.wheel_uy_free() + st_w.wheel_compliance() * -10.0;
            assert!((wu - ws).abs() < 1e-9 * wu.abs(), "wheel point {wu} vs {ws}");
        }
    }
    // the end-of-step compliance is positive (well-posed implicit contact) and below the static one
    let mut probe = StripStepper::new(&model, 1e-5);
    probe.set_wheel(&w);
    assert!(probe.wheel_step_compliance() > 0.0);
    // long run settles to the static (DC) response
    let y0 = model.static_response(&u);
    for _ in 0..20000 {
        st.step(&u);
    }
    st.outputs(&u, &mut top, &mut bot);
    let sv: Vec<f64> = top.iter().chain(&bot).copied().collect();
    assert!(rel(&sv, &y0) < 1e-6, "settled vs DC {:e}", rel(&sv, &y0));
}

#[test]
fn cache_round_trip_and_key() {
    let p = params_2mm();
    let dir = std::env::temp_dir().join(format!("strip-cache-test-{}", std::process::id()));
    let m1 = StripModel::load_or_build_in(&dir, &p).unwrap();
    let m2 = StripModel::load_or_build_in(&dir, &p).unwrap();
    assert_eq!(m1.a, m2.a);
    assert_eq!(m1.d, m2.d);
    assert_eq!(m1.modal.b, m2.modal.b);
    assert_eq!(m1.bulge_bottom_reaction_n, m2.bulge_bottom_reaction_n);
    let q = StripParams { bulge_amplitude_m: 0.3e-3, ..p.clone() };
    assert_ne!(p.cache_key(), q.cache_key());
    // Another bump height shares the file (the reference bump's model) and scales its bump.
    assert_eq!(strip::cache::cache_path(&dir, &p), strip::cache::cache_path(&dir, &q));
    let m3 = StripModel::load_or_build_in(&dir, &q).unwrap();
    assert_eq!((m3.params.clone(), &m3.a, &m3.modal.b), (q.clone(), &m1.a, &m1.modal.b));
    let k = 0.3e-3 / StripParams::BULGE_REFERENCE_M;
    assert!(m3.bulge_top_uy_m.iter().zip(&m1.bulge_top_uy_m).all(|(a, b)| a.to_bits() == (b * k).to_bits()));
    let w = StripParams { bulge_width_m: 0.011, ..p.clone() };
    assert_ne!(strip::cache::cache_path(&dir, &p), strip::cache::cache_path(&dir, &w), "another bump shape is another model");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The bump's offsets of a model are the reference bump's solve scaled to the height (they are
/// linear in it). Against a direct solve at another height (0.37 mm, both signs) they agree to
/// rounding: the two differ by the solve's rounding error at each right-hand side, which for a
/// backward-stable Cholesky solve is about κ(K) ε relative (κ of the bonded 2 mm strip's
/// stiffness about 1e5-1e6 with ν = 0.49, ε = 2.2e-16), so 1e-9 of the largest offset leaves
/// room for an ill-conditioned mesh and still means < 0.2 pm of surface height for a 0.2 mm bump
/// (far below what the contact resolves); measured: 2.5e-15 (top) and 9e-14 (reactions). The
/// reference height itself is the solve, bit for bit.
#[test]
fn a_scaled_bump_is_the_direct_solve_at_that_height() {
    let p = params_2mm();
    let (model, art) = StripModel::build_detailed(&p).unwrap();
    let (top_ref, bottom_ref) = strip::model::bulge_statics(&art.sys, &art.cb, &p.with_reference_bulge());
    assert!(model.bulge_top_uy_m.iter().zip(&top_ref).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert!(model.bulge_bottom_reaction_n.iter().zip(&bottom_ref).all(|(a, b)| a.to_bits() == b.to_bits()));
    for height in [0.37e-3, -0.37e-3] {
        let q = StripParams { bulge_amplitude_m: height, ..p.clone() };
        let scaled = model.clone().with_bulge_of(&q);
        let (top, bottom) = strip::model::bulge_statics(&art.sys, &art.cb, &q);
        for (what, a, b) in [("top u_y", &scaled.bulge_top_uy_m, &top), ("bottom reactions", &scaled.bulge_bottom_reaction_n, &bottom)] {
            let peak = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = a.iter().zip(b.iter()).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            eprintln!("bump {height} m, {what}: scaled vs direct differ by {:.2e} of the peak {peak:.3e}", diff / peak);
            assert!(peak > 0.0 && diff <= 1e-9 * peak, "bump {height} m, {what}: {diff} vs peak {peak}");
        }
    }
}

#[test]
fn gaussian_weights_and_bulge() {
    let model = StripModel::build(&params_2mm()).unwrap();
    let mut w = vec![0.0; model.n_top()];
    model.gaussian_weights(0.02, &mut w);
    assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    let imax = (0..w.len()).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap();
    let [x, _, z] = model.top_xyz_m[imax];
    assert!(x.abs() < 1e-9 && (z - 0.02).abs() < 1e-9, "peak weight at the node under the wheel");
    // bulge: the bump lifts the strip; the top moves less than the bottom (Figure 6.4), and the
    // reactions balance (no external load): they sum to zero
    let p = &model.params;
    let centre_top = (0..model.n_top())
        .filter(|&j| model.top_xyz_m[j][0].abs() < 1e-9)
        .min_by(|&a, &b| (model.top_xyz_m[a][2] - p.bulge_center_m).abs().total_cmp(&(model.top_xyz_m[b][2] - p.bulge_center_m).abs()))
        .unwrap();
    let top = model.bulge_top_uy_m[centre_top];
    assert!(top > 0.0 && top < p.bulge_amplitude_m, "top lift {top} vs bump {}", p.bulge_amplitude_m);
    let s: f64 = model.bulge_bottom_reaction_n.iter().sum();
    let smax = model.bulge_bottom_reaction_n.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(s.abs() < 1e-9 * smax, "bulge reactions sum {s}");
}

#[test]
fn tabulated_wheel_matches_exact_weights() {
    let model = StripModel::build(&params_2mm()).unwrap();
    let mut w = vec![0.0; model.n_top()];
    let mut exact = StripStepper::new(&model, 1e-4);
    let mut table = StripStepper::new(&model, 1e-4);
    let nc = model.centre_line().count();
    let (mut r1, mut r2) = (vec![0.0; nc], vec![0.0; nc]);
    for (k, &za) in [0.0, 0.7e-3, 3.3e-3, 17.77e-3, 20.0e-3, 31.4e-3, 39.9e-3, 40e-3].iter().enumerate() {
        model.gaussian_weights(za, &mut w);
        exact.set_wheel(&w);
        table.set_wheel_z(za);
        for _ in 0..(5 + 7 * k) {
            exact.step_wheel(-10.0);
            table.step_wheel(-10.0);
        }
        let (a, b) = (exact.wheel_uy_free(), table.wheel_uy_free());
        assert!((a - b).abs() < 1e-5 * a.abs(), "z_a {za}: state part {a} vs {b}");
        let (a, b) = (exact.wheel_step_compliance(), table.wheel_step_compliance());
        assert!((a - b).abs() < 1e-5 * a.abs(), "z_a {za}: step compliance {a} vs {b}");
        let (a, b) = (exact.wheel_compliance(), table.wheel_compliance());
        assert!((a - b).abs() < 1e-5 * exact.wheel_step_compliance().abs(), "z_a {za}: feed-through {a} vs {b}");
        exact.wheel_centre_reactions(-10.0, &mut r1);
        table.wheel_centre_reactions(-10.0, &mut r2);
        assert!(rel(&r2, &r1) < 1e-5, "z_a {za}: centre reactions {:e}", rel(&r2, &r1));
    }
}

/// A model is the same bits whatever the machine's CPU count: built inside rayon pools of 1 and
/// 3 threads (faer's default splits its kernels into one task per thread, and the split decides
/// the order of floating-point sums), the two agree bit for bit, because the build fixes its
/// task count (`strip::BUILD_TASKS`). Pinned physics digests rest on this.
#[test]
fn a_model_is_the_same_bits_in_any_thread_pool() {
    let p = params_2mm();
    let build_in = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("rayon pool");
        pool.install(|| {
            // As a fresh process would start: faer's default (one task per pool thread).
            faer::set_global_parallelism(faer::Par::rayon(0));
            StripModel::build(&p).expect("build")
        })
    };
    let (one, three) = (build_in(1), build_in(3));
    assert_eq!((&one.a, &one.b, &one.c, &one.d), (&three.a, &three.b, &three.c, &three.d));
    assert_eq!((&one.modal.lam, &one.modal.b, &one.modal.c), (&three.modal.lam, &three.modal.b, &three.modal.c));
    assert_eq!((&one.hsv, &one.bulge_top_uy_m), (&three.hsv, &three.bulge_top_uy_m));
    assert_eq!(faer::get_global_parallelism(), faer::Par::rayon(strip::BUILD_TASKS));
}
