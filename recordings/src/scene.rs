//! What Foxglove draws (DESIGN section 8): the robot's URDF, `foxglove.FrameTransforms` from the
//! recorded q, a `foxglove.SceneUpdate` of the strip coloured by bottom pressure, and `/events`
//! again as `foxglove.Log`. Encoded on the writer thread (protobuf, with the schema descriptors
//! of the `foxglove` crate), the transforms and the scene at a decimated rate.
//!
//! Frames: `base` (the robot's base, the root), the URDF's `link1`..`link6`, `flange`, `tcp`
//! (see [`robot::urdf`]) and `task` (origin at the strip's start, bottom centre; x across, y up,
//! z along the strip: DESIGN section 3). The strip scene is drawn in `task`, the wheel in `tcp`.

use foxglove::messages::{
    log, ArrowPrimitive, Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms, LinePrimitive, Log, Point3, Pose,
    Quaternion, SceneEntity, SceneUpdate, TextPrimitive, Timestamp, TriangleListPrimitive, Vector3,
};
use foxglove::Encode;
use nalgebra::{Isometry3, UnitQuaternion};
use robot::{Robot, Tool, Vec6};

use crate::schema::TickHead;
use crate::{EventKind, EventRecord};

/// Default rate of the transforms and the scene (scenario `recording.scene_rate_hz`).
pub const DEFAULT_SCENE_RATE_HZ: f64 = 100.0;

/// Top of the pressure colour scale, Pa; the scale runs from 0 (and below) to this.
pub const COLOUR_SCALE_MAX_PA: f64 = 200e3;
/// The bond criterion (DESIGN section 4): centre-line bottom pressure of at least 100 kPa.
pub const BOND_PRESSURE_PA: f64 = 100e3;
/// Arrow length per newton of contact force, m/N (10 N: 20 mm).
pub const ARROW_M_PER_N: f64 = 2e-3;

/// Topics of the Foxglove channels, in the order the writer registers them after
/// [`crate::schema::CHANNELS`].
pub const ROBOT_DESCRIPTION_TOPIC: &str = "/robot_description";
pub const TRANSFORMS_TOPIC: &str = "/tf";
pub const SCENE_TOPIC: &str = "/strip_scene";
pub const LOG_TOPIC: &str = "/log";
pub const UNDER_WHEEL_TOPIC: &str = "/pressure_under_wheel";

/// `/pressure_under_wheel` (JSON, at the scene rate): the centre-line bottom pressure under the
/// wheel (linear interpolation at `wheel_z`, as `rig report` computes it) beside the constant
/// bond line, so a Plot panel draws both.
pub const UNDER_WHEEL_SCHEMA: &str = r#"{"title":"rig.PressureUnderWheel","type":"object","properties":{"tick":{"type":"integer"},"wheel_z_m":{"type":"number","description":"m, wheel position along the strip"},"pressure_pa":{"type":"number","description":"Pa, centre-line bottom pressure under the wheel"},"bond_line_pa":{"type":"number","description":"Pa, the bond criterion (100 kPa)"}}}"#;

/// The `/pressure_under_wheel` message of one tick.
pub fn under_wheel_json(r: &TickHead, centreline_z_m: &[f32], pressure_pa: &[f32]) -> String {
    let p = interp(centreline_z_m, pressure_pa, r.strip.wheel_z_m);
    format!(r#"{{"tick":{},"wheel_z_m":{},"pressure_pa":{},"bond_line_pa":{}}}"#, r.state.tick, r.strip.wheel_z_m, p, BOND_PRESSURE_PA)
}

/// `/robot_description`: the URDF once, as ROS 2 `std_msgs/msg/String` (what Foxglove's URDF
/// layer reads from a topic).
pub const ROBOT_DESCRIPTION_SCHEMA: &str = "string data\n";

/// What the writer needs to draw the run; the plant fills it from its scenario and strip model.
#[derive(Debug, Clone)]
pub struct SceneConfig {
    /// Transforms and scene per second of simulated time (every `round(1 / (rate T))`-th tick).
    pub rate_hz: f64,
    pub tool: Tool,
    /// The task frame in the base frame.
    pub task_in_base: Isometry3<f64>,
    /// The strip, if the scenario has one.
    pub strip: Option<StripGeometry>,
    /// A contour's path (issue 26): the strip, the substrate and the force are drawn in `base`
    /// along it (each point's path coordinates mapped by `StripPath::point_to_base`), the
    /// substrate line coloured by the bond map so far; None: in `task`, straight.
    pub path: Option<scenarios::path::StripPath>,
    /// Along a contour: the band's points in `base` (one per substrate sample), computed once
    /// ([`SceneConfig::along`]).
    pub band_base: Vec<Point3>,
}

/// Along a contour the band round the whole path is sent with every this many scenes (its colours
/// change only under the wheel; Foxglove keeps an entity until it is replaced): the band's 1227
/// points on the sunroof cost the writer more than the rest of the scene at every scene.
pub const BAND_EVERY_SCENES: u64 = 10;

impl SceneConfig {
    /// This scene drawn along `path` (None: unchanged), the band's base points computed here.
    pub fn along(mut self, path: Option<scenarios::path::StripPath>) -> SceneConfig {
        self.band_base = match (&path, &self.strip) {
            (Some(p), Some(g)) => g
                .substrate_zy_m
                .iter()
                .map(|&[z, y]| {
                    let b = p.point_to_base(&nalgebra::Vector3::new(-g.half_width_m - 1e-3, y, z));
                    Point3 { x: quantise(b.x, POSITION_STEP_M), y: quantise(b.y, POSITION_STEP_M), z: quantise(b.z, POSITION_STEP_M) }
                })
                .collect(),
            _ => Vec::new(),
        };
        self.path = path;
        self
    }
}

/// Grid of the scene's bond map along a contour, m (`bond_peak_pa[i]` at z = i step).
pub const SCENE_BOND_STEP_M: f64 = 1e-3;

/// Raises the running peak `peak_pa` (on the [`SCENE_BOND_STEP_M`] grid) with a tick's
/// centre-line pressures at their z (nearest grid point): the bond map the contour's scene colours
/// its substrate line with (the writer thread keeps it; the report's map interpolates).
pub fn raise_bond_peak(peak_pa: &mut [f32], centreline_z_m: &[f32], pressure_pa: &[f32]) {
    for (&z, &p) in centreline_z_m.iter().zip(pressure_pa) {
        let g = (z as f64 / SCENE_BOND_STEP_M).round();
        if g >= 0.0 && (g as usize) < peak_pa.len() {
            let slot = &mut peak_pa[g as usize];
            *slot = slot.max(p);
        }
    }
}

/// The strip as the scene draws it (task frame, m).
#[derive(Debug, Clone)]
pub struct StripGeometry {
    /// Rest coordinates of the top-surface nodes, layer by layer (z), then by x (the strip
    /// model's input order), `nodes_per_layer` a layer.
    pub top_xyz_m: Vec<[f64; 3]>,
    pub nodes_per_layer: usize,
    /// The substrate's surface under the centre line (the bulge): (z, height along task y), m,
    /// ascending z, as the strip model has it.
    pub substrate_zy_m: Vec<[f64; 2]>,
    pub length_m: f64,
    pub half_width_m: f64,
    /// A windowed long strip (issue 25): `top_xyz_m` covers the whole strip, but each scene draws
    /// only the layers the tick's centre line covers (the windows around the wheel, where the
    /// pressure is recorded) and raises their top by the substrate's height under them (the
    /// chain computes no top centre line: `top_uy_m` is zero). The substrate is drawn whole.
    pub windowed: bool,
}

impl SceneConfig {
    /// Ticks between two scene samples at control period `period_s` (at least 1).
    pub fn every_ticks(&self, period_s: f64) -> u64 {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !positive(self.rate_hz) || !positive(period_s) {
            return 1;
        }
        ((1.0 / (self.rate_hz * period_s)).round() as u64).max(1)
    }
}

/// A Unix-ns time as a Foxglove timestamp.
pub fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

fn vec3(v: &nalgebra::Vector3<f64>) -> Vector3 {
    Vector3 { x: v.x, y: v.y, z: v.z }
}

fn quat(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion { x: q.i, y: q.j, z: q.k, w: q.w }
}

fn pose(iso: &Isometry3<f64>) -> Pose {
    Pose { position: Some(vec3(&iso.translation.vector)), orientation: Some(quat(&iso.rotation)) }
}

fn at(x: f64, y: f64, z: f64) -> Pose {
    pose(&Isometry3::translation(x, y, z))
}

fn rgba(c: [f64; 4]) -> Color {
    Color { r: c[0], g: c[1], b: c[2], a: c[3] }
}

/// The colour of a bottom pressure (Pa): below the 100 kPa bond line a blue that lightens from
/// dark (0 Pa and tension) to light (just under 100 kPa); from 100 kPa on a yellow that turns
/// red at [`COLOUR_SCALE_MAX_PA`] and beyond. With t = p / 100 kPa clamped to [0, 1] below the
/// line and t = (p - 100 kPa) / 100 kPa clamped to [0, 1] above it:
/// below: (0.1 + 0.5 t, 0.2 + 0.6 t, 0.6 + 0.4 t); above: (1, 0.9 (1 - t), 0.1 (1 - t)); alpha 1.
pub fn pressure_colour(p_pa: f64) -> [f64; 4] {
    if p_pa < BOND_PRESSURE_PA {
        let t = (p_pa / BOND_PRESSURE_PA).clamp(0.0, 1.0);
        [0.1 + 0.5 * t, 0.2 + 0.6 * t, 0.6 + 0.4 * t, 1.0]
    } else {
        let t = ((p_pa - BOND_PRESSURE_PA) / (COLOUR_SCALE_MAX_PA - BOND_PRESSURE_PA)).clamp(0.0, 1.0);
        [1.0, 0.9 * (1.0 - t), 0.1 * (1.0 - t), 1.0]
    }
}

/// Mesh vertices are rounded to 2^-20 m (about 1 um, against displacements of 0.1-0.4 mm) and their
/// colours to 1/256: binary steps leave the low bytes of each float64 zero, which zstd then
/// compresses away (the scene is most of the file otherwise).
pub const POSITION_STEP_M: f64 = 1.0 / (1u64 << 20) as f64;
pub const COLOUR_STEP: f64 = 1.0 / 256.0;

fn quantise(v: f64, step: f64) -> f64 {
    round_half_away(v / step) * step
}

/// `x.round()` (halves away from zero) bit for bit, without the libm call x86-64's baseline
/// makes of it (no rounding instruction before SSE4.1): a fifth of the scene's encoding was that
/// call (perf, 2026-12-06). Below 2^52 the cast truncates exactly and `x - t` is exact.
#[inline]
fn round_half_away(x: f64) -> f64 {
    if x.is_nan() || x.abs() >= 4_503_599_627_370_496.0 {
        // NaN, and 2^52 and beyond (infinities too): already an integer
        return x;
    }
    // copysign: -0.3 rounds to -0.0, as `round` gives
    let t = ((x as i64) as f64).copysign(x);
    let r = x - t;
    if r >= 0.5 {
        t + 1.0
    } else if r <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

/// Linear interpolation of `v` over ascending `z` at `x`, held beyond the ends.
fn interp(z: &[f32], v: &[f32], x: f64) -> f64 {
    interp_from(z, v, x, &mut 1)
}

/// [`interp`] starting its search at `*from` (and leaving it where it found `x`): a run of
/// ascending `x` costs one pass over `z` in all.
fn interp_from(z: &[f32], v: &[f32], x: f64, from: &mut usize) -> f64 {
    let n = z.len().min(v.len());
    if n == 0 {
        return 0.0;
    }
    if x <= z[0] as f64 {
        return v[0] as f64;
    }
    if *from < 1 || *from > n || x <= z[*from - 1] as f64 {
        *from = 1;
    }
    for i in *from..n {
        if x <= z[i] as f64 {
            *from = i;
            let (z0, z1) = (z[i - 1] as f64, z[i] as f64);
            let s = if z1 > z0 { (x - z0) / (z1 - z0) } else { 0.0 };
            return (1.0 - s) * v[i - 1] as f64 + s * v[i] as f64;
        }
    }
    v[n - 1] as f64
}

/// The substrate's height at `z` from the (z, y) samples `zy` (ascending z; held beyond the
/// ends), searching from `*from` on as [`interp_from`] does.
fn substrate_height(zy: &[[f64; 2]], z: f64, from: &mut usize) -> f64 {
    let n = zy.len();
    if n == 0 {
        return 0.0;
    }
    if z <= zy[0][0] {
        return zy[0][1];
    }
    if *from < 1 || *from > n || z <= zy[*from - 1][0] {
        *from = 1;
    }
    for i in *from..n {
        if z <= zy[i][0] {
            *from = i;
            let ([z0, y0], [z1, y1]) = (zy[i - 1], zy[i]);
            let s = if z1 > z0 { (z - z0) / (z1 - z0) } else { 0.0 };
            return (1.0 - s) * y0 + s * y1;
        }
    }
    zy[n - 1][1]
}

/// `foxglove.FrameTransforms` of one tick: the URDF chain base → link1 → ... → link6 → flange →
/// tcp from the robot's forward kinematics of the recorded q, and base → task.
pub fn frame_transforms(robot: &Robot, cfg: &SceneConfig, q: &[f64; 6], ns: u64) -> FrameTransforms {
    let edges = robot::urdf::chain_from_fk(robot, &Vec6::from(*q));
    let ts = Some(timestamp(ns));
    let names = robot::urdf::LINK_NAMES;
    let mut transforms: Vec<FrameTransform> = edges
        .iter()
        .enumerate()
        .map(|(k, e)| FrameTransform {
            timestamp: ts,
            parent_frame_id: names[k].into(),
            child_frame_id: names[k + 1].into(),
            translation: Some(vec3(&e.translation.vector)),
            rotation: Some(quat(&e.rotation)),
        })
        .collect();
    transforms.push(FrameTransform {
        timestamp: ts,
        parent_frame_id: "base".into(),
        child_frame_id: "task".into(),
        translation: Some(vec3(&cfg.task_in_base.translation.vector)),
        rotation: Some(quat(&cfg.task_in_base.rotation)),
    });
    FrameTransforms { transforms }
}

/// `foxglove.SceneUpdate` of one tick: the strip's top surface (one vertex per top node, displaced
/// along task y by the recorded top centre-line displacement at its z, coloured by the recorded
/// centre-line bottom pressure at its z, [`pressure_colour`]), the substrate with its bulge,
/// the colour scale with the 100 kPa bond line, the wheel, and the contact force as an arrow.
/// `pressure_pa`, `top_uy_m`: the tick's centre-line values at the nodes `centreline_z_m`.
/// Along a contour (`cfg.path`): the strip, the substrate and the force in `base`, the substrate
/// line coloured by `bond_peak_pa` (the peak centre-line pressure per [`SCENE_BOND_STEP_M`] so
/// far, [`raise_bond_peak`]); the colour scale stays in `task`, 0.2 m long.
pub fn scene_update(cfg: &SceneConfig, t: &SceneTick) -> SceneUpdate {
    scene_update_with(cfg, t, true)
}

/// One tick's inputs of the scene: its head, the centre line's node z with the tick's pressure
/// and top displacement at them, the contour's bond map so far, and the message's time (Unix ns).
#[derive(Debug, Clone, Copy)]
pub struct SceneTick<'a> {
    pub head: &'a TickHead,
    pub centreline_z_m: &'a [f32],
    pub pressure_pa: &'a [f32],
    pub top_uy_m: &'a [f32],
    pub bond_peak_pa: &'a [f32],
    pub ns: u64,
}

/// [`scene_update`]; without `with_mesh` the strip entity has no triangle list (the one
/// [`encode_scene_into`] writes itself).
fn scene_update_with(cfg: &SceneConfig, t: &SceneTick, with_mesh: bool) -> SceneUpdate {
    let SceneTick { head: r, centreline_z_m, pressure_pa, top_uy_m, bond_peak_pa, ns } = *t;
    // Path coordinates to the drawn frame's: `task` itself, or `base` along a contour.
    let strip_frame = if cfg.path.is_some() { "base" } else { "task" };
    let ts = Some(timestamp(ns));
    let entity = |id: &str, frame: &str| SceneEntity {
        timestamp: ts,
        frame_id: frame.into(),
        id: id.into(),
        frame_locked: true,
        ..Default::default()
    };
    let mut entities = Vec::new();
    let tool = &cfg.tool;
    // The wheel, in the TCP frame (its axis is the tool y axis).
    let mut wheel = entity("wheel", "tcp");
    let d = 2.0 * tool.wheel_radius_m;
    wheel.cylinders.push(CylinderPrimitive {
        pose: Some(pose(&Isometry3::from_parts(
            nalgebra::Translation3::identity(),
            UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
        ))),
        size: Some(Vector3 { x: d, y: d, z: robot::urdf::WHEEL_WIDTH_M }),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Some(rgba([0.1, 0.1, 0.1, 0.9])),
    });
    entities.push(wheel);
    if let Some(g) = &cfg.strip {
        let s = &r.strip;
        let mut strip = entity("strip", strip_frame);
        if with_mesh {
            let mesh = StripMesh::new(g, centreline_z_m);
            let (mut points, mut colors) = (Vec::with_capacity(mesh.len()), Vec::with_capacity(mesh.len()));
            mesh.vertices(cfg, g, centreline_z_m, pressure_pa, top_uy_m, |p, c| {
                points.push(Point3 { x: p[0], y: p[1], z: p[2] });
                colors.push(rgba(c));
            });
            let mut indices = Vec::with_capacity(mesh.n_indices());
            mesh.indices(|i| indices.push(i));
            strip.triangles.push(TriangleListPrimitive { pose: Some(at(0.0, 0.0, 0.0)), points, color: None, colors, indices });
        }
        entities.push(strip);

        // The substrate's surface along the centre line: the bulge.
        let mut substrate = entity("bulge", strip_frame);
        if cfg.path.is_none() {
            let points = g.substrate_zy_m.iter().map(|&[z, y]| Point3 { x: 0.0, y, z }).collect();
            substrate.lines.push(LinePrimitive {
                r#type: foxglove::messages::line_primitive::Type::LineStrip as i32,
                pose: Some(at(-g.half_width_m - 1e-3, 0.0, 0.0)),
                thickness: 0.6e-3,
                scale_invariant: false,
                points,
                color: Some(rgba([0.2, 0.2, 0.2, 1.0])),
                ..Default::default()
            });
        } else {
            // The whole contour as a band beside the strip, coloured by the pressure each
            // millimetre received so far (grey where the wheel has not been); every
            // BAND_EVERY_SCENES-th scene.
            let every = cfg.every_ticks(r.state.period_s) * BAND_EVERY_SCENES;
            let points = if r.state.tick.is_multiple_of(every) { cfg.band_base.clone() } else { Vec::new() };
            let colors = g
                .substrate_zy_m
                .iter()
                .take(points.len())
                .map(|&[z, _]| {
                    let peak = bond_peak_pa.get((z / SCENE_BOND_STEP_M).round() as usize).copied().unwrap_or(0.0);
                    if peak > 0.0 {
                        rgba(pressure_colour(peak as f64).map(|v| quantise(v, COLOUR_STEP)))
                    } else {
                        rgba([0.6, 0.6, 0.6, 1.0])
                    }
                })
                .collect();
            if !points.is_empty() {
                substrate.lines.push(LinePrimitive {
                    r#type: foxglove::messages::line_primitive::Type::LineStrip as i32,
                    pose: Some(at(0.0, 0.0, 0.0)),
                    thickness: 2e-3,
                    scale_invariant: false,
                    points,
                    colors,
                    ..Default::default()
                });
            }
        }
        // (a scene without the band leaves the last one standing: no empty entity replaces it)
        if !substrate.lines.is_empty() {
            entities.push(substrate);
        }

        // The colour scale beside the strip: 0..200 kPa along task z, the bond line at 100 kPa.
        let mut scale = entity("pressure_scale", "task");
        let (x0, cells) = (g.half_width_m + 6e-3, 20);
        // (a contour's strip is metres long and not along task z: a 0.2 m legend at its start)
        let scale_m = if cfg.path.is_some() { 0.2 } else { g.length_m };
        let cell_m = scale_m / cells as f64;
        for i in 0..cells {
            let p = COLOUR_SCALE_MAX_PA * (i as f64 + 0.5) / cells as f64;
            scale.cubes.push(CubePrimitive {
                pose: Some(at(x0, 0.0, cell_m * (i as f64 + 0.5))),
                size: Some(Vector3 { x: 3e-3, y: 1e-3, z: cell_m }),
                color: Some(rgba(pressure_colour(p))),
            });
        }
        let z_bond = scale_m * BOND_PRESSURE_PA / COLOUR_SCALE_MAX_PA;
        scale.lines.push(LinePrimitive {
            r#type: foxglove::messages::line_primitive::Type::LineStrip as i32,
            pose: Some(at(0.0, 0.0, 0.0)),
            thickness: 0.5e-3,
            points: vec![Point3 { x: x0 - 3e-3, y: 0.6e-3, z: z_bond }, Point3 { x: x0 + 3e-3, y: 0.6e-3, z: z_bond }],
            color: Some(rgba([0.0, 0.0, 0.0, 1.0])),
            ..Default::default()
        });
        for (z, text) in [(0.0, "0 kPa"), (z_bond, "100 kPa bond"), (scale_m, "200 kPa")] {
            scale.texts.push(TextPrimitive {
                pose: Some(at(x0 + 4e-3, 1e-3, z)),
                billboard: true,
                font_size: 12.0,
                scale_invariant: true,
                color: Some(rgba([0.0, 0.0, 0.0, 1.0])),
                text: text.into(),
            });
        }
        entities.push(scale);

        // The contact force on the strip: an arrow from above ending on the top under the wheel.
        let f = s.contact_force_n;
        let mut arrow = entity("contact_force", strip_frame);
        if f < 0.0 {
            let len = -f * ARROW_M_PER_N;
            let top = scenarios::geometry::STRIP_TOP_HEIGHT_M + s.top_displacement_m;
            // The arrow points along its pose's +x: turned to -y (pressing), or to -z in base.
            let iso = match &cfg.path {
                None => {
                    let rot = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), -std::f64::consts::FRAC_PI_2);
                    Isometry3::from_parts(nalgebra::Translation3::new(0.0, top + len, s.wheel_z_m), rot)
                }
                Some(path) => {
                    let rot = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
                    let b = path.point_to_base(&nalgebra::Vector3::new(0.0, top + len, s.wheel_z_m));
                    Isometry3::from_parts(nalgebra::Translation3::from(b), rot)
                }
            };
            arrow.arrows.push(ArrowPrimitive {
                pose: Some(pose(&iso)),
                shaft_length: 0.7 * len,
                shaft_diameter: 0.6e-3,
                head_length: 0.3 * len,
                head_diameter: 1.6e-3,
                color: Some(rgba([0.85, 0.1, 0.1, 1.0])),
            });
        }
        entities.push(arrow);
    }
    SceneUpdate { deletions: Vec::new(), entities }
}

/// The strip's top surface as the scene draws it: the top nodes of the layers drawn (a windowed
/// strip: those within the tick's centre line, + half an element for f32 z), one vertex each,
/// two triangles per quad of neighbouring nodes.
struct StripMesh<'a> {
    top: &'a [[f64; 3]],
    per: usize,
}

impl<'a> StripMesh<'a> {
    fn new(g: &'a StripGeometry, centreline_z_m: &[f32]) -> Self {
        let per = g.nodes_per_layer.max(1);
        let top: &[[f64; 3]] = match (g.windowed, centreline_z_m.first(), centreline_z_m.last()) {
            (true, Some(&lo), Some(&hi)) => {
                let layer_z = |k: usize| g.top_xyz_m[k * per][2];
                let layers = g.top_xyz_m.len() / per;
                let tol = 0.5 * (hi - lo) as f64 / centreline_z_m.len().max(2) as f64;
                let k0 = (0..layers).find(|&k| layer_z(k) >= lo as f64 - tol).unwrap_or(layers);
                let k1 = (k0..layers).find(|&k| layer_z(k) > hi as f64 + tol).unwrap_or(layers);
                &g.top_xyz_m[k0 * per..k1 * per]
            }
            (true, _, _) => &[],
            _ => &g.top_xyz_m,
        };
        StripMesh { top, per }
    }

    fn len(&self) -> usize {
        self.top.len()
    }

    fn layers(&self) -> usize {
        self.top.len() / self.per
    }

    fn n_indices(&self) -> usize {
        6 * self.layers().saturating_sub(1) * self.per.saturating_sub(1)
    }

    /// Each vertex in order, drawn position (in the strip's frame: `task`, or `base` along a
    /// contour) and colour: displaced along task y by the top centre-line displacement at its z
    /// (a windowed strip: raised by the substrate under it), coloured by the centre-line bottom
    /// pressure at its rounded z; positions and colours quantised.
    fn vertices(
        &self,
        cfg: &SceneConfig,
        g: &StripGeometry,
        centreline_z_m: &[f32],
        pressure_pa: &[f32],
        top_uy_m: &[f32],
        mut vertex: impl FnMut([f64; 3], [f64; 4]),
    ) {
        // The nodes come layer by layer in ascending z: one cursor per quantity.
        let (mut at_u, mut at_p, mut at_s) = (1, 1, 1);
        // Along a contour a layer's vertices share their z, so its moving frame is found once a
        // layer (`StripPath::point_to_base` is that frame applied to (x, y, 0)).
        let mut layer_frame: Option<(f64, scenarios::geometry::TaskFrame)> = None;
        // What depends on a node's z only (its displacement, drawn z and colour), found once per
        // z: a layer's nodes share it. The same calls on the same values: the same bits.
        let mut layer: Option<(f64, f64, f64, [f64; 4])> = None;
        for p in self.top {
            let (uy, z, c) = match layer {
                Some((rest_z, uy, z, c)) if rest_z.to_bits() == p[2].to_bits() => (uy, z, c),
                _ => {
                    let mut uy = interp_from(centreline_z_m, top_uy_m, p[2], &mut at_u);
                    if g.windowed {
                        uy += substrate_height(&g.substrate_zy_m, p[2], &mut at_s);
                    }
                    let z = quantise(p[2], POSITION_STEP_M);
                    // the colour of the vertex as drawn (at its rounded z)
                    let c = pressure_colour(interp_from(centreline_z_m, pressure_pa, z, &mut at_p)).map(|v| quantise(v, COLOUR_STEP));
                    layer = Some((p[2], uy, z, c));
                    (uy, z, c)
                }
            };
            let (x, y) = (quantise(p[0], POSITION_STEP_M), quantise(p[1] + uy, POSITION_STEP_M));
            let drawn = match &cfg.path {
                None => [x, y, z],
                Some(path) => {
                    let b = match path {
                        scenarios::path::StripPath::Contour { .. } => {
                            let frame = match layer_frame {
                                Some((fz, f)) if fz == z => f,
                                _ => layer_frame.insert((z, path.frame_at(z))).1,
                            };
                            frame.point_to_base(&nalgebra::Vector3::new(x, y, 0.0))
                        }
                        scenarios::path::StripPath::Straight(_) => path.point_to_base(&nalgebra::Vector3::new(x, y, z)),
                    };
                    [quantise(b.x, POSITION_STEP_M), quantise(b.y, POSITION_STEP_M), quantise(b.z, POSITION_STEP_M)]
                }
            };
            vertex(drawn, c);
        }
    }

    /// The triangles' vertex indices: per quad (a, b) on one layer and (c, e) on the next,
    /// (a, b, e) and (a, e, c).
    fn indices(&self, mut index: impl FnMut(u32)) {
        let per = self.per;
        for k in 0..self.layers().saturating_sub(1) {
            for j in 0..per - 1 {
                let (a, b) = ((k * per + j) as u32, (k * per + j + 1) as u32);
                let (c, e) = (a + per as u32, b + per as u32);
                for i in [a, b, e, a, e, c] {
                    index(i);
                }
            }
        }
    }
}

/// Protobuf wire format, the little the strip's mesh needs (what prost writes for these fields).
mod wire {
    /// Field `field` of wire type LEN (2).
    pub fn len_tag(field: u32) -> u8 {
        ((field << 3) | 2) as u8
    }

    pub fn varint(mut v: u64, out: &mut Vec<u8>) {
        while v >= 0x80 {
            out.push((v as u8) | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
    }

    /// A message of doubles (fields 1..): proto3 leaves a zero out (prost: `!= 0.0`).
    pub fn doubles(field: u32, values: &[f64], out: &mut Vec<u8>) {
        let n = values.iter().filter(|&&v| v != 0.0).count();
        out.push(len_tag(field));
        out.push((9 * n) as u8);
        for (i, &v) in values.iter().enumerate() {
            if v != 0.0 {
                out.push((((i + 1) as u8) << 3) | 1);
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
}

/// Reused buffers of [`encode_scene_into`].
#[derive(Debug, Default)]
pub struct SceneScratch {
    mesh: Vec<u8>,
    entity: Vec<u8>,
}

/// [`scene_update`] encoded into `buf` (cleared first), byte for byte what [`encode_into`] of it
/// gives (tested), with the strip's triangle list written straight from the vertex walk: prost
/// would build 2 × 533 point and colour messages for the default strip and size each of them
/// three times over while encoding them (half the writer thread's scene time, 2026-12-06).
pub fn encode_scene_into(cfg: &SceneConfig, t: &SceneTick, scratch: &mut SceneScratch, buf: &mut Vec<u8>) {
    use prost::Message;
    let SceneTick { centreline_z_m, pressure_pa, top_uy_m, .. } = *t;
    let msg = scene_update_with(cfg, t, false);
    buf.clear();
    // SceneUpdate: deletions (field 1) are empty; each entity a field 2.
    for e in &msg.entities {
        let strip = match &cfg.strip {
            Some(g) if e.id == "strip" => g,
            _ => {
                prost::encoding::message::encode(2, e, buf);
                continue;
            }
        };
        // TriangleListPrimitive: pose (1), points (2), colors (4), indices (5, packed fixed32).
        let mesh = StripMesh::new(strip, centreline_z_m);
        let tri = &mut scratch.mesh;
        tri.clear();
        prost::encoding::message::encode(1, &at(0.0, 0.0, 0.0), tri);
        let mut colours = std::mem::take(&mut scratch.entity);
        colours.clear();
        mesh.vertices(cfg, strip, centreline_z_m, pressure_pa, top_uy_m, |p, c| {
            wire::doubles(2, &p, tri);
            wire::doubles(4, &c, &mut colours);
        });
        tri.extend_from_slice(&colours);
        if mesh.n_indices() > 0 {
            tri.push(wire::len_tag(5));
            wire::varint(4 * mesh.n_indices() as u64, tri);
            mesh.indices(|i| tri.extend_from_slice(&i.to_le_bytes()));
        }
        // The entity: its fields below 12 as prost writes them, then the triangle list (12),
        // its only field from 12 on.
        colours.clear();
        e.encode_raw(&mut colours);
        let entity_len = colours.len() + 1 + prost::length_delimiter_len(tri.len()) + tri.len();
        buf.push(wire::len_tag(2));
        wire::varint(entity_len as u64, buf);
        buf.extend_from_slice(&colours);
        buf.push(wire::len_tag(12));
        wire::varint(tri.len() as u64, buf);
        buf.extend_from_slice(tri);
        scratch.entity = colours;
    }
}

/// The Log level of an event kind: faults and refusals are errors, safe stops, reflexes and
/// misses warnings, the rest information.
pub fn log_level(kind: EventKind) -> log::Level {
    use EventKind::*;
    match kind {
        Fault | RecordingError | VersionMismatch | TorqueRefused | ControllerEnded => log::Level::Error,
        SafeStop | Reflex | EndStop | Miss | ForeignTorque | EgmRefused => log::Level::Warning,
        Start | Stop | ModeChange | ControllerChange | SafeStopCleared | Info | EgmSession => log::Level::Info,
    }
}

/// `/events` entry as `foxglove.Log`: name = the kind's name, message = "tick N: text".
pub fn log_message(e: &EventRecord, ns: u64) -> Log {
    // The plant's event texts begin with their tick already; others get it.
    let text = e.text();
    let message = if text.starts_with(&format!("tick {}: ", e.tick)) { text.to_string() } else { format!("tick {}: {text}", e.tick) };
    Log {
        timestamp: Some(timestamp(ns)),
        level: log_level(e.kind) as i32,
        message,
        name: e.kind.name().into(),
        file: String::new(),
        line: 0,
    }
}

/// Schema name, encoding and data of a Foxglove message type, for the writer.
pub fn schema_of<T: Encode>() -> (String, String, Vec<u8>) {
    let s = T::get_schema().expect("the foxglove schemas have descriptors");
    (s.name, s.encoding, s.data.into_owned())
}

/// Encodes `msg` into `buf` (cleared first).
pub fn encode_into<T: Encode>(msg: &T, buf: &mut Vec<u8>) {
    buf.clear();
    msg.encode(buf).expect("a Vec grows");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 41-layer strip of 13 nodes a layer (some raised, some not) on a substrate with a step.
    fn test_strip(windowed: bool) -> SceneConfig {
        SceneConfig {
            rate_hz: 100.0,
            tool: Tool::default(),
            task_in_base: Isometry3::identity(),
            strip: Some(StripGeometry {
                top_xyz_m: (0..41)
                    .flat_map(|k| (0..13).map(move |j| [(j as f64 - 6.0) * 1e-3, if j % 4 == 0 { 0.0 } else { 0.004 }, k as f64 * 1e-3]))
                    .collect(),
                nodes_per_layer: 13,
                substrate_zy_m: (0..=40).map(|i| [i as f64 * 1e-3, if i > 20 { 2e-4 } else { 0.0 }]).collect(),
                length_m: 0.04,
                half_width_m: 0.004,
                windowed,
            }),
            path: None,
            band_base: Vec::new(),
        }
    }

    fn sunroof_path() -> scenarios::path::StripPath {
        let sunroof =
            scenarios::Scenario::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/sunroof.toml")).unwrap();
        scenarios::path::StripPath::from_scenario(&sunroof)
    }

    /// A tick's centre line (z, pressure, top displacement) over 10-30 mm.
    fn test_centreline() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let z: Vec<f32> = (0..21).map(|i| (0.01 + i as f64 * 1e-3) as f32).collect();
        let p: Vec<f32> = (0..21).map(|i| [0.0, -3e3, 60e3, 100e3, 170e3, 250e3][i % 6]).collect();
        let u: Vec<f32> = (0..21).map(|i| if i % 3 == 0 { 0.0 } else { -1.5e-4 * i as f32 }).collect();
        (z, p, u)
    }

    /// The mesh's vertices, found once per layer for what depends on z only, are those of the
    /// plain per-vertex formulas (fresh searches, the path's frame at each vertex).
    #[test]
    fn the_vertices_are_the_per_vertex_formulas() {
        let (z, p, u) = test_centreline();
        let along = test_strip(true).along(Some(sunroof_path()));
        for (name, cfg) in [("straight", test_strip(false)), ("windowed", test_strip(true)), ("along the sunroof", along)] {
            let g = cfg.strip.as_ref().unwrap();
            let mesh = StripMesh::new(g, &z);
            let mut got = Vec::new();
            mesh.vertices(&cfg, g, &z, &p, &u, |v, c| got.push((v, c)));
            let want: Vec<([f64; 3], [f64; 4])> = mesh
                .top
                .iter()
                .map(|n| {
                    let uy = interp(&z, &u, n[2]) + if g.windowed { substrate_height(&g.substrate_zy_m, n[2], &mut 1) } else { 0.0 };
                    let (x, y, zq) =
                        (quantise(n[0], POSITION_STEP_M), quantise(n[1] + uy, POSITION_STEP_M), quantise(n[2], POSITION_STEP_M));
                    let v = match &cfg.path {
                        None => [x, y, zq],
                        Some(path) => {
                            let b = match path {
                                scenarios::path::StripPath::Contour { .. } => {
                                    path.frame_at(zq).point_to_base(&nalgebra::Vector3::new(x, y, 0.0))
                                }
                                scenarios::path::StripPath::Straight(_) => path.point_to_base(&nalgebra::Vector3::new(x, y, zq)),
                            };
                            [b.x, b.y, b.z].map(|c| quantise(c, POSITION_STEP_M))
                        }
                    };
                    (v, pressure_colour(interp(&z, &p, zq)).map(|c| quantise(c, COLOUR_STEP)))
                })
                .collect();
            assert!(got.len() > 100, "{name}: {} vertices", got.len());
            let bits = |v: &[([f64; 3], [f64; 4])]| v.iter().map(|(a, b)| (a.map(f64::to_bits), b.map(f64::to_bits))).collect::<Vec<_>>();
            assert!(bits(&got) == bits(&want), "{name}");
        }
    }

    /// The cursor search gives what the plain one does, for ascending, repeated and falling x.
    #[test]
    fn a_log_message_names_its_tick_once() {
        let miss = EventRecord::new(980, 0.98, EventKind::Miss, "tick 980: no valid torque in time, holding the last one");
        assert_eq!(log_message(&miss, 0).message, "tick 980: no valid torque in time, holding the last one");
        let probe = EventRecord::new(2000, 2.0, EventKind::Info, "host probe: 37 stalls");
        assert_eq!(log_message(&probe, 0).message, "tick 2000: host probe: 37 stalls");
    }

    /// The scene's rounding is std's `round`, bit for bit: halves, their neighbours, signed
    /// zeros, the 2^52 edge, the non-finite, and a million quantised coordinates and colours.
    #[test]
    fn the_rounding_is_stds_bit_for_bit() {
        let mut xs =
            vec![0.0, -0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX, f64::MIN, f64::MIN_POSITIVE, 4_503_599_627_370_496.0];
        for k in -40i64..=40 {
            let h = k as f64 + 0.5;
            for x in [h, h.next_up(), h.next_down(), k as f64, (k as f64).next_up(), (k as f64).next_down()] {
                xs.extend([x, x * 1e-3, x * 2f64.powi(51), 2f64.powi(52) - 0.5, -(2f64.powi(52) - 0.5)]);
            }
        }
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..1_000_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let u = (seed >> 11) as f64 / (1u64 << 53) as f64;
            xs.extend([(u - 0.5) * 4.0 / POSITION_STEP_M, u / COLOUR_STEP]);
        }
        for x in xs {
            assert_eq!(round_half_away(x).to_bits(), x.round().to_bits(), "{x:e}");
        }
    }

    #[test]
    fn interpolation_with_a_cursor_is_the_plain_interpolation() {
        let z = [0.0f32, 0.001, 0.002, 0.004, 0.008];
        let v = [1.0f32, -2.0, 3.0, 5.0, 0.5];
        let mut at = 1;
        for x in [-0.001, 0.0, 0.0005, 0.0005, 0.0015, 0.003, 0.0079, 0.009, 0.0012, 0.0, 0.006] {
            let plain = {
                let i = z.iter().position(|&zi| x <= zi as f64);
                match i {
                    Some(0) => v[0] as f64,
                    Some(i) => {
                        let s = (x - z[i - 1] as f64) / (z[i] as f64 - z[i - 1] as f64);
                        (1.0 - s) * v[i - 1] as f64 + s * v[i] as f64
                    }
                    None => v[4] as f64,
                }
            };
            assert_eq!(interp_from(&z, &v, x, &mut at), plain, "x = {x}");
        }
    }

    /// The colour map at its documented points.
    /// A windowed long strip: the scene draws only the layers the tick's centre line covers,
    /// their top raised by the substrate's height there (a 0.3 mm step at 100 mm here), coloured
    /// by the tick's pressure, and the substrate whole.
    #[test]
    fn a_windowed_strip_draws_the_layers_around_the_wheel_on_the_substrate() {
        let (per, layers, el) = (3usize, 301usize, 1e-3);
        let top_xyz_m = (0..layers).flat_map(|k| [-2e-3, 0.0, 2e-3].map(|x| [x, 0.01, k as f64 * el])).collect();
        let step = |z: f64| if z >= 0.1 { 3e-4 } else { 0.0 };
        let cfg = SceneConfig {
            rate_hz: 100.0,
            tool: Tool::default(),
            task_in_base: Isometry3::identity(),
            strip: Some(StripGeometry {
                top_xyz_m,
                nodes_per_layer: per,
                substrate_zy_m: (0..layers).map(|k| [k as f64 * el, step(k as f64 * el)]).collect(),
                length_m: 0.3,
                half_width_m: 4e-3,
                windowed: true,
            }),
            path: None,
            band_base: Vec::new(),
        };
        let mut rec = crate::TickRecord::default();
        rec.strip.n_centreline = 61;
        rec.strip.wheel_z_m = 0.1;
        let head = TickHead::of(&rec);
        // the nodes 70..=130 mm, as the writer expands z0 = 70 mm, dz = 1 mm
        let z: Vec<f32> = (0..61).map(|i| (0.07 + i as f64 * el) as f32).collect();
        let p: Vec<f32> = (0..61).map(|i| if i == 30 { 150e3 } else { 50e3 }).collect();
        let u = vec![0.0f32; 61];
        let msg =
            scene_update(&cfg, &SceneTick { head: &head, centreline_z_m: &z, pressure_pa: &p, top_uy_m: &u, bond_peak_pa: &[], ns: 0 });
        let strip = msg.entities.iter().find(|e| e.id == "strip").unwrap();
        let tri = &strip.triangles[0];
        assert_eq!(tri.points.len(), 61 * per, "the 61 layers around the wheel");
        assert!((tri.points[0].z - 0.07).abs() < 1e-6 && (tri.points[61 * per - 1].z - 0.13).abs() < 1e-6);
        for q in &tri.points {
            let want = 0.01
                + if q.z > 0.1 + 1e-6 {
                    3e-4
                } else if q.z < 0.1 - 1e-6 {
                    0.0
                } else {
                    q.y - 0.01
                };
            assert!((q.y - want).abs() < 2e-6, "z {} y {} want {want}", q.z, q.y);
        }
        assert_eq!(tri.indices.len(), 6 * 60 * (per - 1));
        let c = &tri.colors[30 * per];
        assert_eq!([c.r, c.g, c.b], [1.0, 0.9 * 0.5, 0.1 * 0.5].map(|v| quantise(v, COLOUR_STEP)), "150 kPa under the wheel");
        let bulge = msg.entities.iter().find(|e| e.id == "bulge").unwrap();
        assert_eq!(bulge.lines[0].points.len(), layers, "the substrate along the whole strip");
    }

    /// The strip's triangle list written straight (`encode_scene_into`) is prost's encoding of
    /// [`scene_update`] byte for byte: a straight strip with zeros among its coordinates and
    /// colours (proto3 leaves zeros out), a windowed one, the same with an empty centre line (no
    /// mesh), a strip along the sunroof contour, and a scene without a strip.
    #[test]
    fn the_direct_encoding_is_prosts_byte_for_byte() {
        let (straight, along, bare) =
            (test_strip, test_strip(true).along(Some(sunroof_path())), SceneConfig { strip: None, ..test_strip(false) });
        let (z, p, u) = test_centreline();
        let peak: Vec<f32> = (0..400).map(|i| (i * 500) as f32).collect();
        let mut rec = crate::TickRecord::default();
        rec.strip.contact_force_n = -10.0;
        rec.strip.wheel_z_m = 0.02;
        let head = TickHead::of(&rec);
        let (mut scratch, mut direct, mut reference) = (SceneScratch::default(), Vec::new(), Vec::new());
        let cases: [(&str, &SceneConfig, &[f32]); 5] = [
            ("straight", &straight(false), &z),
            ("windowed", &straight(true), &z),
            ("windowed, empty", &straight(true), &[]),
            ("along the sunroof", &along, &z),
            ("no strip", &bare, &z),
        ];
        for (name, cfg, z) in cases {
            let (p, u) = (&p[..z.len()], &u[..z.len()]);
            for ns in [0, 1_765_000_000_123_456_789] {
                let t = SceneTick { head: &head, centreline_z_m: z, pressure_pa: p, top_uy_m: u, bond_peak_pa: &peak, ns };
                encode_into(&scene_update(cfg, &t), &mut reference);
                encode_scene_into(cfg, &t, &mut scratch, &mut direct);
                assert!(reference.len() > 100, "{name}: {} bytes", reference.len());
                assert!(direct == reference, "{name}: {} bytes direct against {} from prost", direct.len(), reference.len());
            }
        }
    }

    #[test]
    fn pressure_colours_at_the_documented_points() {
        assert_eq!(pressure_colour(-5e3), [0.1, 0.2, 0.6, 1.0]);
        assert_eq!(pressure_colour(0.0), [0.1, 0.2, 0.6, 1.0]);
        assert_eq!(pressure_colour(100e3), [1.0, 0.9, 0.1, 1.0]);
        assert_eq!(pressure_colour(300e3), [1.0, 0.0, 0.0, 1.0]);
        let below = pressure_colour(99.999e3);
        assert!((below[0] - 0.6).abs() < 1e-4 && (below[1] - 0.8).abs() < 1e-4 && (below[2] - 1.0).abs() < 1e-4);
    }
}
