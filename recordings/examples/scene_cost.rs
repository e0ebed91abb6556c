//! Writer-thread cost of the Foxglove channels for a default-sized strip (41 layers of 13 top
//! nodes): building + protobuf-encoding one `/strip_scene` (through prost, and as the writer does it,
//! `encode_scene_into`) and one `/tf`, and zstd-compressing one
//! scene (level from `L`, default 3, the writer's). Numbers in recordings/README.md.
//!
//!     cargo run --release -p recordings --example scene_cost

use recordings::scene::*;
use recordings::schema::TickHead;
fn main() {
    let mut top = Vec::new();
    for k in 0..41 {
        for j in 0..13 {
            let a = std::f64::consts::PI * j as f64 / 12.0;
            top.push([-0.004 * a.cos(), 0.004 + 0.004 * a.sin(), k as f64 * 1e-3]);
        }
    }
    let cfg = SceneConfig {
        rate_hz: 100.0,
        tool: robot::Tool::default(),
        task_in_base: scenarios::geometry::TaskFrame::from_scenario(&scenarios::Scenario::default()).pose_in_base(),
        strip: Some(StripGeometry {
            top_xyz_m: top,
            nodes_per_layer: 13,
            substrate_zy_m: (0..=200).map(|i| [i as f64 * 2e-4, 0.0]).collect(),
            length_m: 0.04,
            half_width_m: 0.004,
            windowed: false,
        }),
        path: None,
        band_base: Vec::new(),
    };
    let mut rec = recordings::TickRecord::default();
    rec.strip.n_centreline = 41;
    rec.strip.contact_force_n = -10.0;
    let head = TickHead::of(&rec);
    let z: Vec<f32> = (0..41).map(|k| k as f32 * 1e-3).collect();
    let p: Vec<f32> = (0..41).map(|k| 1e3 * k as f32 * 5.0).collect();
    let u: Vec<f32> = vec![-1e-4; 41];
    let tick = |ns| SceneTick { head: &head, centreline_z_m: &z, pressure_pa: &p, top_uy_m: &u, bond_peak_pa: &[], ns };
    let robot = robot::Robot::irb2400_with_tool(cfg.tool);
    let mut buf = Vec::new();
    let n = 2000;
    let t = std::time::Instant::now();
    for i in 0..n {
        encode_into(&scene_update(&cfg, &tick(i)), &mut buf);
    }
    let scene = t.elapsed().as_secs_f64() / n as f64 * 1e6;
    let mut scratch = SceneScratch::default();
    let t = std::time::Instant::now();
    for i in 0..n {
        encode_scene_into(&cfg, &tick(i), &mut scratch, &mut buf);
    }
    let direct = t.elapsed().as_secs_f64() / n as f64 * 1e6;
    let t = std::time::Instant::now();
    for i in 0..n {
        encode_into(&frame_transforms(&robot, &cfg, &[0.0, -1.3, 0.5, 0.0, 0.8, 0.0], i), &mut buf);
    }
    let tf = t.elapsed().as_secs_f64() / n as f64 * 1e6;
    let mut c = zstd::bulk::Compressor::new(std::env::var("L").map_or(3, |v| v.parse().unwrap())).unwrap();
    encode_into(&scene_update(&cfg, &tick(1)), &mut buf);
    let t = std::time::Instant::now();
    for _ in 0..n {
        let _ = c.compress(&buf).unwrap();
    }
    let z3 = t.elapsed().as_secs_f64() / n as f64 * 1e6;
    println!(
        "scene build+encode {scene:.1} us through prost, {direct:.1} us written directly ({} B), tf {tf:.1} us, zstd of one scene {z3:.1} us",
        buf.len()
    );
}
