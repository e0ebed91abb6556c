//! Benchmarks of issue 4: the cold pipeline (mesh -> 250 states) at 2 mm and 1 mm, the cache
//! load, and one discrete step of the 250-state model. `cargo bench -p strip`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use strip::{StripModel, StripParams, StripStepper};

fn cold(c: &mut Criterion) {
    let mut g = c.benchmark_group("cold_pipeline");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    let p2 = StripParams { element_m: 2e-3, ..Default::default() };
    g.bench_function("2mm", |b| b.iter(|| StripModel::build(black_box(&p2)).unwrap()));
    let p1 = StripParams::default();
    g.measurement_time(Duration::from_secs(35));
    g.bench_function("1mm", |b| b.iter(|| StripModel::build(black_box(&p1)).unwrap()));
    g.finish();
}

fn cache_and_step(c: &mut Criterion) {
    let p = StripParams::default();
    let dir = std::env::temp_dir().join(format!("strip-bench-cache-{}", std::process::id()));
    let model = StripModel::load_or_build_in(&dir, &p).unwrap();
    let path = strip::cache::cache_path(&dir, &p);
    c.bench_function("cache_load_1mm", |b| b.iter(|| strip::cache::load(black_box(&path), &p).unwrap().unwrap()));

    let mut w = vec![0.0; model.n_top()];
    model.gaussian_weights(0.02, &mut w);
    let u: Vec<f64> = w.iter().map(|wi| -10.0 * wi).collect();
    let mut st = StripStepper::new(&model, 1e-4);
    st.set_wheel(&w);
    c.bench_function("step_wheel_250", |b| b.iter(|| st.step_wheel(black_box(-10.0))));
    c.bench_function("wheel_loop_substep_250", |b| {
        // one plant substep: predict, solve the scalar contact loop, step
        b.iter(|| {
            let pred = st.wheel_uy_predict();
            let f = -(1e5 * (pred + 1e-4)).max(0.0) / (1.0 + 1e5 * st.wheel_step_compliance());
            st.step_wheel(black_box(f));
        })
    });
    c.bench_function("step_gaussian_vector_250", |b| b.iter(|| st.step(black_box(&u))));
    c.bench_function("set_wheel_exact", |b| b.iter(|| st.set_wheel(black_box(&w))));
    let mut za = 0.0;
    c.bench_function("set_wheel_z_table", |b| {
        b.iter(|| {
            za = (za + 1.37e-4) % 0.04;
            st.set_wheel_z(black_box(za))
        })
    });
    let mut cr = vec![0.0; model.centre_line().count()];
    c.bench_function("wheel_centre_reactions", |b| b.iter(|| st.wheel_centre_reactions(black_box(-10.0), &mut cr)));
    c.bench_function("stepper_new_dt", |b| b.iter(|| StripStepper::new(black_box(&model), 1e-4)));
    let (mut top, mut bot) = (vec![0.0; model.n_top()], vec![0.0; model.n_bottom()]);
    c.bench_function("outputs_all", |b| b.iter(|| st.outputs(black_box(&u), &mut top, &mut bot)));
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, cache_and_step, cold);
criterion_main!(benches);
