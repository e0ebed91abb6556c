//! Renders the 3D scene of one tick of a recording to a PNG with plotters, from the recording's
//! own Foxglove channels: the robot from `/tf` (each URDF link drawn as its cylinders, sized as
//! in `robot::urdf`, seen as thick lines), the strip's top-surface mesh from `/strip_scene` with
//! its recorded vertex colours, the substrate line, the wheel and the contact-force arrow.
//! Orthographic views; painter's algorithm. Left: the cell; right: the strip close up.
//!
//!     cargo run --release -p recordings --example scene_png -- RUN.mcap OUT.png [TICK]
//!
//! TICK: the scene tick to draw (default: the one nearest the middle of the roll, 2500).

use std::collections::HashMap;

use foxglove::messages::{FrameTransforms, SceneUpdate};
use foxglove::Decode;
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use plotters::prelude::*;
use robot::params::IRB2400_DH;

type P3 = Vector3<f64>;

/// An orthographic camera: looks along `forward` at `target`, `scale` pixels per metre, centred
/// on `centre` (pixels).
struct View {
    right: P3,
    up: P3,
    forward: P3,
    target: P3,
    scale: f64,
    centre: (i32, i32),
}

impl View {
    fn new(azimuth_deg: f64, elevation_deg: f64, up_axis: P3, target: P3, scale: f64, centre: (i32, i32)) -> View {
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        // Right-handed: `up_axis` up, the camera circles it.
        let (a, b) = if up_axis.z.abs() > 0.5 { (P3::x(), P3::y()) } else { (P3::z(), P3::x()) };
        let horizontal = a * az.cos() + b * az.sin();
        let forward = -(horizontal * el.cos() + up_axis * el.sin());
        let right = forward.cross(&up_axis).normalize();
        let up = right.cross(&forward);
        View { right, up, forward, target, scale, centre }
    }

    fn px(&self, p: &P3) -> (i32, i32) {
        let d = p - self.target;
        (self.centre.0 + (d.dot(&self.right) * self.scale) as i32, self.centre.1 - (d.dot(&self.up) * self.scale) as i32)
    }

    fn depth(&self, p: &P3) -> f64 {
        (p - self.target).dot(&self.forward)
    }
}

enum Shape {
    Tri([P3; 3], RGBColor),
    Seg(P3, P3, RGBColor, u32),
}

fn draw(area: &DrawingArea<BitMapBackend, plotters::coord::Shift>, view: &View, mut shapes: Vec<Shape>) {
    let depth = |s: &Shape| match s {
        Shape::Tri(p, _) => view.depth(&((p[0] + p[1] + p[2]) / 3.0)),
        Shape::Seg(a, b, _, _) => view.depth(&((a + b) / 2.0)),
    };
    // far first
    shapes.sort_by(|a, b| depth(b).total_cmp(&depth(a)));
    for s in shapes {
        match s {
            Shape::Tri(p, c) => {
                let _ = area.draw(&Polygon::new(p.iter().map(|q| view.px(q)).collect::<Vec<_>>(), c.filled()));
            }
            Shape::Seg(a, b, c, w) => {
                let _ = area.draw(&PathElement::new(vec![view.px(&a), view.px(&b)], c.stroke_width(w)));
            }
        }
    }
}

fn colour(c: &Option<foxglove::messages::Color>) -> RGBColor {
    let c = c.unwrap_or_default();
    RGBColor((c.r * 255.0).round() as u8, (c.g * 255.0).round() as u8, (c.b * 255.0).round() as u8)
}

fn iso_of(t: &Option<foxglove::messages::Vector3>, r: &Option<foxglove::messages::Quaternion>) -> Isometry3<f64> {
    let (t, r) = (t.unwrap_or_default(), r.unwrap_or_default());
    Isometry3::from_parts(Translation3::new(t.x, t.y, t.z), UnitQuaternion::from_quaternion(Quaternion::new(r.w, r.x, r.y, r.z)))
}

fn pose_of(p: &Option<foxglove::messages::Pose>) -> Isometry3<f64> {
    let p = p.unwrap_or_default();
    iso_of(&p.position, &p.orientation)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (input, output) = (args.first().expect("RUN.mcap"), args.get(1).expect("OUT.png"));
    let want_tick: u64 = args.get(2).map_or(Ok(2500), |t| t.parse())?;
    let bytes = std::fs::read(input)?;
    let mut tf: Option<FrameTransforms> = None;
    let mut scene: Option<SceneUpdate> = None;
    for m in mcap::MessageStream::new(&bytes)? {
        let m = m?;
        if m.sequence as u64 != want_tick {
            continue;
        }
        match m.channel.topic.as_str() {
            "/tf" => tf = Some(FrameTransforms::decode(&m.data[..])?),
            "/strip_scene" => scene = Some(SceneUpdate::decode(&m.data[..])?),
            _ => {}
        }
    }
    let (tf, scene) = (tf.expect("no /tf at that tick"), scene.expect("no /strip_scene at that tick"));

    // World (base) pose of every frame from the recorded edges.
    let edges: HashMap<String, (String, Isometry3<f64>)> = tf
        .transforms
        .iter()
        .map(|t| (t.child_frame_id.clone(), (t.parent_frame_id.clone(), iso_of(&t.translation, &t.rotation))))
        .collect();
    fn world(f: &str, e: &HashMap<String, (String, Isometry3<f64>)>) -> Isometry3<f64> {
        e.get(f).map_or(Isometry3::identity(), |(p, t)| world(p, e) * t)
    }

    // The robot: each link's DH offsets as cylinders (robot::urdf), in its recorded frame.
    let orange = RGBColor(237, 115, 26);
    let grey = RGBColor(90, 90, 97);
    let mut robot_shapes = Vec::new();
    let radius_px = [18u32, 12, 11, 9, 7, 6];
    for (i, r) in IRB2400_DH.iter().enumerate() {
        let w = world(&format!("link{}", i + 1), &edges);
        let (o, d, a) = (w * Point3::origin(), w * Point3::new(0.0, 0.0, r.d_m), w * Point3::new(r.a_m, 0.0, r.d_m));
        let c = if i < 3 { orange } else { grey };
        robot_shapes.push(Shape::Seg(o.coords, d.coords, c, radius_px[i]));
        robot_shapes.push(Shape::Seg(d.coords, a.coords, c, radius_px[i]));
    }
    let flange = world("flange", &edges);
    let tcp = world("tcp", &edges);
    robot_shapes.push(Shape::Seg(flange.translation.vector, tcp.translation.vector, grey, 4));
    robot_shapes.push(Shape::Tri([P3::new(-0.2, -0.2, 0.0), P3::new(0.2, -0.2, 0.0), P3::new(0.2, 0.2, 0.0)], RGBColor(150, 150, 150)));
    robot_shapes.push(Shape::Tri([P3::new(-0.2, -0.2, 0.0), P3::new(0.2, 0.2, 0.0), P3::new(-0.2, 0.2, 0.0)], RGBColor(150, 150, 150)));

    // The strip scene in the task frame, and in the base frame for the overview.
    let task = world("task", &edges);
    let mut strip_task = Vec::new();
    let mut arrow = None;
    let mut scale_cells: Vec<(P3, RGBColor, foxglove::messages::Vector3)> = Vec::new();
    let mut substrate = Vec::new();
    for e in &scene.entities {
        for t in &e.triangles {
            let pose = pose_of(&t.pose);
            for k in t.indices.chunks(3) {
                let p: [P3; 3] = std::array::from_fn(|j| {
                    let v = &t.points[k[j] as usize];
                    (pose * Point3::new(v.x, v.y, v.z)).coords
                });
                // the triangle's colour: its vertices' mean
                let cs: Vec<RGBColor> = k.iter().map(|&i| colour(&Some(t.colors[i as usize]))).collect();
                let mean = |f: fn(&RGBColor) -> u8| (cs.iter().map(|c| f(c) as u32).sum::<u32>() / 3) as u8;
                strip_task.push(Shape::Tri(p, RGBColor(mean(|c| c.0), mean(|c| c.1), mean(|c| c.2))));
            }
        }
        for a in &e.arrows {
            arrow = Some((pose_of(&a.pose), a.shaft_length + a.head_length));
        }
        for c in &e.cubes {
            scale_cells.push((pose_of(&c.pose).translation.vector, colour(&c.color), c.size.unwrap_or_default()));
        }
        for l in &e.lines {
            if e.id == "bulge" {
                let pose = pose_of(&l.pose);
                substrate = l.points.iter().map(|p| (pose * Point3::new(p.x, p.y, p.z)).coords).collect();
            }
        }
    }

    let root = BitMapBackend::new(output, (1600, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(800);
    let font = ("sans-serif", 22).into_font();

    // Left: the cell, base frame, seen from the front left and above.
    let target = P3::new(0.55, 0.0, 0.75);
    let overview = View::new(-60.0, 20.0, P3::z(), target, 330.0, (400, 420));
    let mut shapes = robot_shapes;
    for s in &strip_task {
        if let Shape::Tri(p, c) = s {
            shapes.push(Shape::Tri(p.map(|q| (task * Point3::from(q)).coords), *c));
        }
    }
    let wheel_world = tcp.translation.vector;
    draw(&left, &overview, shapes);
    let _ = left.draw(&Circle::new(overview.px(&wheel_world), 4, BLACK.filled()));
    left.draw(&Text::new("IRB 2400 + wheel (from /tf), strip (from /strip_scene)", (20, 20), font.clone()))?;

    // Right: the strip close up in the task frame (x across, y up, z along).
    let close = View::new(-35.0, 28.0, P3::y(), P3::new(0.0, 0.004, 0.02), 15000.0, (400, 470));
    let mut shapes = strip_task;
    for w in substrate.windows(2) {
        shapes.push(Shape::Seg(w[0], w[1], RGBColor(40, 40, 40), 2));
    }
    // The wheel in the task frame: a circle in the plane normal to the tool y axis.
    let tcp_task = task.inverse() * tcp;
    let axis = tcp_task.rotation * P3::y();
    let (u, v) = (axis.cross(&P3::x()).normalize(), axis.cross(&axis.cross(&P3::x())).normalize());
    let radius = 0.010;
    let ring: Vec<P3> = (0..=48)
        .map(|k| {
            let t = k as f64 / 48.0 * std::f64::consts::TAU;
            tcp_task.translation.vector + (u * t.cos() + v * t.sin()) * radius
        })
        .collect();
    for w in ring.windows(2) {
        shapes.push(Shape::Seg(w[0], w[1], BLACK, 3));
    }
    if let Some((pose, len)) = arrow {
        let a = pose.translation.vector;
        let b = a + pose.rotation * P3::new(len, 0.0, 0.0);
        shapes.push(Shape::Seg(a, b, RGBColor(217, 26, 26), 4));
    }
    draw(&right, &close, shapes);
    right.draw(&Text::new(
        format!("strip at tick {want_tick}: top surface coloured by centre-line bottom pressure"),
        (20, 20),
        font.clone(),
    ))?;
    right.draw(&Text::new(
        "blue < 100 kPa (not bonded) | yellow 100 kPa -> red 200 kPa; red arrow: contact force",
        (20, 50),
        ("sans-serif", 18).into_font(),
    ))?;
    // The scene's colour scale (its cells, 0..200 kPa in order) as a legend bar, the bond line marked.
    let (x0, y0, w) = (120, 720, 560);
    let n = scale_cells.len().max(1) as i32;
    for (i, (_, col, _)) in scale_cells.iter().enumerate() {
        let i = i as i32;
        right.draw(&Rectangle::new([(x0 + i * w / n, y0), (x0 + (i + 1) * w / n, y0 + 24)], col.filled()))?;
    }
    right.draw(&Rectangle::new([(x0 + w / 2 - 2, y0 - 8), (x0 + w / 2 + 2, y0 + 32)], BLACK.filled()))?;
    for (dx, label) in [(0, "0 kPa"), (w / 2, "100 kPa bond line"), (w, "200 kPa")] {
        right.draw(&Text::new(label, (x0 + dx - 20, y0 + 36), ("sans-serif", 18).into_font()))?;
    }
    let sub = close.px(substrate.first().unwrap_or(&P3::zeros()));
    right.draw(&Text::new("substrate with its bulge", (sub.0 - 60, sub.1 - 28), ("sans-serif", 16).into_font()))?;
    root.present()?;
    println!(
        "{output}: tick {want_tick}, {} strip triangles",
        scene.entities.iter().map(|e| e.triangles.iter().map(|t| t.indices.len() / 3).sum::<usize>()).sum::<usize>()
    );
    Ok(())
}
