//! A planar contour on the substrate (issue 26, DESIGN section 15): straight lines and circular
//! arcs, each continuing the tangent of the one before, so the tangent is continuous by
//! construction; a closed contour must also meet its own start with the start's tangent. The
//! reference of a contour run is the path `r(s)` of this module composed with a time law `s(t)`
//! (Drake's path × time law), so everything here is a function of the arc length s.
//!
//! Frames: the contour lies in the substrate's plane, a level table (its normal is base +z), in
//! base x and y (m). The heading is the tangent's angle from base +x towards base +y
//! (counter-clockwise seen from above); an arc with a positive turn bends to the left. The moving
//! frame at s is the task frame of a straight strip laid along the tangent there: task z the
//! tangent, task y the substrate normal (base +z), task x the lateral direction to the left.
//!
//! A scenario's `[contour]` builds one ([`Contour::from_scenario`]); `crate::path` lays the strip
//! along it for the plant and the controller and checks the arm's reach along it, and [`TimeLaw`]
//! is the roll's speed along it.

use std::f64::consts::TAU;

/// One piece of a contour, continuing the previous piece's end point and tangent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Piece {
    /// A straight line this long, m.
    Line { length_m: f64 },
    /// A circular arc of this radius (m) that turns the tangent by `turn_rad` (positive: to the
    /// left); its length is `radius_m · |turn_rad|`.
    Arc { radius_m: f64, turn_rad: f64 },
}

impl Piece {
    /// Arc length of the piece, m.
    pub fn length_m(&self) -> f64 {
        match *self {
            Piece::Line { length_m } => length_m,
            Piece::Arc { radius_m, turn_rad } => radius_m * turn_rad.abs(),
        }
    }

    /// Signed curvature, 1/m (positive when the piece bends to the left).
    pub fn curvature_per_m(&self) -> f64 {
        match *self {
            Piece::Line { .. } => 0.0,
            Piece::Arc { radius_m, turn_rad } => turn_rad.signum() / radius_m,
        }
    }
}

/// A point of the contour with its moving frame's heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourPoint {
    /// Arc length from the contour's start, m.
    pub s_m: f64,
    /// Position in the substrate plane, base x and y, m.
    pub xy_base_m: [f64; 2],
    /// Tangent's angle from base +x towards base +y, rad.
    pub heading_rad: f64,
    /// Signed curvature, 1/m (positive: bending to the left).
    pub curvature_per_m: f64,
    /// Index of the piece the point lies on.
    pub piece: usize,
    /// The heading's sine and cosine, as [`Heading`] found them.
    sin_h: f64,
    cos_h: f64,
}

impl ContourPoint {
    /// The unit tangent (task z of the moving frame), base x and y.
    pub fn tangent(&self) -> [f64; 2] {
        [self.cos_h, self.sin_h]
    }

    /// The unit lateral direction to the left (task x of the moving frame), base x and y.
    pub fn left(&self) -> [f64; 2] {
        [-self.sin_h, self.cos_h]
    }
}

/// A heading (rad, from base +x towards base +y) with its sine and cosine, found once: the
/// plant projects the wheel onto the contour every substep and the controller every tick, and
/// the sines and cosines of the pieces' start headings were a tenth of the plant's time on the
/// sunroof (perf, 2026-12-06). `f64::sin_cos` is `(sin, cos)`, so every value is the one the
/// per-call `sin()` and `cos()` gave, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Heading {
    rad: f64,
    sin: f64,
    cos: f64,
}

impl Heading {
    fn new(rad: f64) -> Heading {
        let (sin, cos) = rad.sin_cos();
        Heading { rad, sin, cos }
    }
}

/// Where a piece starts: its arc length (m), point (base x and y, m) and heading.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Start {
    s_m: f64,
    xy_base_m: [f64; 2],
    heading: Heading,
}

/// Why a contour was refused, and which piece (its index in the file's list) or field it is.
#[derive(Debug, Clone, PartialEq)]
pub struct ContourError {
    /// The offending piece's index, or None for the contour as a whole (its closure).
    pub piece: Option<usize>,
    /// What is wrong, worded to follow the piece's or the contour's name.
    pub why: String,
}

impl std::fmt::Display for ContourError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.piece {
            Some(i) => write!(f, "piece {i}: {}", self.why),
            None => write!(f, "the contour: {}", self.why),
        }
    }
}

/// How far (m) and how much turned (rad) a closed contour's end may be from its start: far below
/// anything the wheel or the strip resolve, far above the rounding of summing the pieces.
pub const CLOSURE_TOLERANCE_M: f64 = 1e-6;
pub const CLOSURE_TOLERANCE_RAD: f64 = 1e-6;

/// A contour: a start pose and its pieces, with each piece's start (arc length, point, heading)
/// precomputed.
#[derive(Debug, Clone, PartialEq)]
pub struct Contour {
    pieces: Vec<Piece>,
    /// Per piece: arc length, point and heading at its start.
    starts: Vec<Start>,
    length_m: f64,
    /// The shortest piece's length, m ([`Contour::project_near`]'s fall-back distance).
    shortest_m: f64,
    closed: bool,
}

impl Contour {
    /// The contour from `start_xy_base_m` with heading `start_heading_rad` through `pieces`,
    /// refused when a piece has no length (or not a finite one), an arc's radius is below
    /// `min_radius_m` (what the wheel can follow) or it turns by 2π or more, or, when `closed`,
    /// the end misses the start ([`CLOSURE_TOLERANCE_M`]) or meets it at another tangent (a
    /// tangent jump, [`CLOSURE_TOLERANCE_RAD`]).
    pub fn new(
        start_xy_base_m: [f64; 2],
        start_heading_rad: f64,
        pieces: &[Piece],
        closed: bool,
        min_radius_m: f64,
    ) -> Result<Contour, ContourError> {
        let bad = |i: usize, why: String| ContourError { piece: Some(i), why };
        if pieces.is_empty() {
            return Err(ContourError { piece: None, why: "has no pieces".into() });
        }
        let mut starts = Vec::with_capacity(pieces.len());
        let (mut s, mut p, mut h) = (0.0, start_xy_base_m, Heading::new(start_heading_rad));
        for (i, piece) in pieces.iter().enumerate() {
            match *piece {
                Piece::Line { length_m } => {
                    if !(length_m.is_finite() && length_m > 0.0) {
                        return Err(bad(i, format!("a line of length {length_m} m: a piece must have a positive length")));
                    }
                }
                Piece::Arc { radius_m, turn_rad } => {
                    if !(radius_m.is_finite() && radius_m >= min_radius_m) {
                        return Err(bad(
                            i,
                            format!("an arc of radius {:.1} mm: the wheel follows {:.1} mm or more", radius_m * 1e3, min_radius_m * 1e3),
                        ));
                    }
                    if !(turn_rad.is_finite() && turn_rad != 0.0) {
                        return Err(bad(i, format!("an arc turning by {turn_rad} rad: a piece must have a positive length")));
                    }
                    if turn_rad.abs() >= TAU {
                        return Err(bad(i, format!("an arc turning by {:.1}°: one piece turns by less than 360°", turn_rad.to_degrees())));
                    }
                }
            }
            starts.push(Start { s_m: s, xy_base_m: p, heading: h });
            (p, h) = end_of(piece, p, h, piece.length_m());
            s += piece.length_m();
        }
        if closed {
            let gap = ((p[0] - start_xy_base_m[0]).powi(2) + (p[1] - start_xy_base_m[1]).powi(2)).sqrt();
            if gap > CLOSURE_TOLERANCE_M {
                return Err(ContourError { piece: None, why: format!("is closed but its end is {:.3} mm from its start", gap * 1e3) });
            }
            let jump = wrap_pi(h.rad - start_heading_rad);
            if jump.abs() > CLOSURE_TOLERANCE_RAD {
                return Err(ContourError {
                    piece: None,
                    why: format!("is closed but its tangent jumps by {:.3}° where it meets its start", jump.to_degrees()),
                });
            }
        }
        let shortest_m = pieces.iter().map(Piece::length_m).fold(f64::INFINITY, f64::min);
        Ok(Contour { pieces: pieces.to_vec(), starts, length_m: s, shortest_m, closed })
    }

    /// A closed rounded rectangle, `width_m` along the start heading and `height_m` across it, with
    /// corner radius `radius_m`, run counter-clockwise from the middle of a long side: what a
    /// sunroof opening's edge looks like (issue 26's `scenarios/sunroof.toml`).
    pub fn rounded_rectangle(
        mid_side_xy_base_m: [f64; 2],
        heading_rad: f64,
        width_m: f64,
        height_m: f64,
        radius_m: f64,
        min_radius_m: f64,
    ) -> Result<Contour, ContourError> {
        let (w, h) = (width_m - 2.0 * radius_m, height_m - 2.0 * radius_m);
        let quarter = Piece::Arc { radius_m, turn_rad: TAU / 4.0 };
        let mut pieces = vec![Piece::Line { length_m: w / 2.0 }];
        for side in [h, w, h] {
            pieces.extend([quarter, Piece::Line { length_m: side }]);
        }
        pieces.extend([quarter, Piece::Line { length_m: w / 2.0 }]);
        Contour::new(mid_side_xy_base_m, heading_rad, &pieces, true, min_radius_m)
    }

    /// Total arc length, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    pub fn is_closed(&self) -> bool {
        self.closed
    }

    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }

    /// Arc length at which piece `i` starts, m.
    pub fn piece_start_m(&self, i: usize) -> f64 {
        self.starts[i].s_m
    }

    /// The point at arc length `s_m`: a closed contour wraps around (a run that overlaps its start
    /// goes on round), an open one is held at its ends.
    pub fn at(&self, s_m: f64) -> ContourPoint {
        let (s, i) = self.piece_at(s_m);
        let Start { s_m: s0, xy_base_m: p0, heading: h0 } = self.starts[i];
        let piece = &self.pieces[i];
        let (xy, h) = end_of(piece, p0, h0, (s - s0).min(piece.length_m()));
        ContourPoint {
            s_m: s,
            xy_base_m: xy,
            heading_rad: h.rad,
            curvature_per_m: piece.curvature_per_m(),
            piece: i,
            sin_h: h.sin,
            cos_h: h.cos,
        }
    }

    /// Arc length `s_m` wrapped around a closed contour or held at an open one's ends, and the
    /// index of the piece it lies on (the last one starting at or before it).
    fn piece_at(&self, s_m: f64) -> (f64, usize) {
        let s = if self.closed { s_m.rem_euclid(self.length_m) } else { s_m.clamp(0.0, self.length_m) };
        (s, self.starts.partition_point(|st| st.s_m <= s).saturating_sub(1))
    }

    /// The nearest point of the contour to `xy_base_m`: its arc length and the signed lateral
    /// offset of `xy_base_m` from it along the moving frame's task x (positive to the left).
    /// Where two pieces are equally near (a corner's centre), the first one in the list is taken.
    pub fn project(&self, xy_base_m: [f64; 2]) -> (f64, f64) {
        let mut best: Option<(f64, f64, f64)> = None;
        for i in 0..self.pieces.len() {
            let (dist, s, lateral) = self.foot_on(i, xy_base_m);
            if best.is_none_or(|b| dist < b.0) {
                best = Some((dist, s, lateral));
            }
        }
        let (_, s, lateral) = best.expect("a contour has pieces");
        (s, lateral)
    }

    /// [`Contour::project`] over the piece at `s_hint_m` and its two neighbours only (the wheel
    /// moves a fraction of a millimetre between two calls): the same answer wherever the nearest
    /// point lies on those three pieces, a third of the work on the sunroof's nine. Falls back to
    /// every piece when the point is farther from them than the shortest piece is long.
    pub fn project_near(&self, xy_base_m: [f64; 2], s_hint_m: f64) -> (f64, f64) {
        let n = self.pieces.len();
        if n <= 3 {
            return self.project(xy_base_m);
        }
        let i = self.piece_at(s_hint_m).1;
        let before = if i > 0 {
            i - 1
        } else if self.closed {
            n - 1
        } else {
            0
        };
        let after = if i + 1 < n {
            i + 1
        } else if self.closed {
            0
        } else {
            n - 1
        };
        let mut best: Option<(f64, f64, f64)> = None;
        // In list order, as `project` takes the first of two equally near pieces.
        let mut order = [before, i, after];
        order.sort_unstable();
        for (k, &j) in order.iter().enumerate() {
            if k > 0 && order[k - 1] == j {
                continue;
            }
            let (dist, s, lateral) = self.foot_on(j, xy_base_m);
            if best.is_none_or(|b| dist < b.0) {
                best = Some((dist, s, lateral));
            }
        }
        let (dist, s, lateral) = best.expect("three pieces");
        if dist > self.shortest_m {
            return self.project(xy_base_m);
        }
        (s, lateral)
    }

    /// Distance from `xy_base_m` to piece `i`'s nearest point, that point's arc length, and the
    /// signed lateral offset there.
    fn foot_on(&self, i: usize, xy_base_m: [f64; 2]) -> (f64, f64, f64) {
        let Start { s_m: s0, xy_base_m: p0, heading: h0 } = self.starts[i];
        let piece = &self.pieces[i];
        let a = nearest_along(piece, p0, h0, xy_base_m);
        let (foot, h) = end_of(piece, p0, h0, a);
        let d = [xy_base_m[0] - foot[0], xy_base_m[1] - foot[1]];
        (d[0].hypot(d[1]), s0 + a, -d[0] * h.sin + d[1] * h.cos)
    }

    /// The highest speed (m/s) at arc length `s_m` at which the lateral acceleration `v² κ` stays
    /// within `lateral_accel_mps2`: the time law's rule for slowing down in arcs (unbounded on a
    /// line).
    pub fn speed_limit_mps(&self, s_m: f64, lateral_accel_mps2: f64) -> f64 {
        let k = self.pieces[self.piece_at(s_m).1].curvature_per_m().abs();
        if k == 0.0 {
            f64::INFINITY
        } else {
            (lateral_accel_mps2 / k).sqrt()
        }
    }
}

/// The tightest arc a contour may have, m: twice the wheel's 10 mm radius. The loop neglects
/// the strip's curvature in arcs; at the sunroof's 50 mm the curved FE model moves the centre
/// line's pressure by 0.06 % and the edges' by 7.9 % (`rig model curvature`), growing as 1/R, so
/// below 20 mm the straight strip no longer stands for the bent one.
pub const MIN_RADIUS_M: f64 = 0.02;

impl Contour {
    /// The scenario's `[contour]`, from `[placement]`'s strip start on (see `ContourConfig`).
    pub fn from_scenario(s: &crate::Scenario) -> Result<Contour, ContourError> {
        let c = &s.contour;
        let pieces: Vec<Piece> = c
            .pieces
            .iter()
            .map(|&[line_mm, radius_mm, turn_deg]| {
                if line_mm > 0.0 {
                    Piece::Line { length_m: line_mm * 1e-3 }
                } else {
                    Piece::Arc { radius_m: radius_mm * 1e-3, turn_rad: turn_deg.to_radians() }
                }
            })
            .collect();
        let start = [s.placement.strip_start_x_m, s.placement.strip_y_m];
        Contour::new(start, c.heading_deg.to_radians(), &pieces, c.closed, MIN_RADIUS_M)
    }
}

/// The roll's time law along a contour (Drake's path × time law: `s(t)` composed with the
/// contour's `r(s)`): the speed rises from rest at the tangential acceleration `accel`, cruises
/// at `speed` on lines, stays at or below `sqrt(a_lat R)` in arcs (the lateral-acceleration rule,
/// [`Contour::speed_limit_mps`]), and slows to rest at the end, each change at `accel`. Tabulated
/// every [`TimeLaw::STEP_M`] with a constant acceleration between samples (so s, v and a follow
/// from each other exactly); built once before the run, read allocation-free per tick.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeLaw {
    /// Arc length from the roll's start, speed and time at each sample.
    s_m: Vec<f64>,
    v_mps: Vec<f64>,
    t_s: Vec<f64>,
}

impl TimeLaw {
    /// Sample spacing, m.
    pub const STEP_M: f64 = 0.5e-3;

    /// The law over `[s_from_m, s_to_m]` of `contour`.
    pub fn new(contour: &Contour, s_from_m: f64, s_to_m: f64, speed_mps: f64, accel_mps2: f64, lateral_accel_mps2: f64) -> TimeLaw {
        let dist = (s_to_m - s_from_m).max(0.0);
        let n = ((dist / Self::STEP_M).ceil() as usize).max(1);
        let ds = dist / n as f64;
        // Each sample's limit: the lowest of the pieces within a step of it (the speed must be
        // down before an arc begins).
        let limit = |k: usize| {
            let s = s_from_m + k as f64 * ds;
            [s - ds, s, s + ds]
                .iter()
                .map(|&x| contour.speed_limit_mps(x.clamp(s_from_m, s_to_m), lateral_accel_mps2))
                .fold(speed_mps, f64::min)
        };
        let mut v: Vec<f64> = (0..=n).map(limit).collect();
        v[0] = 0.0;
        v[n] = 0.0;
        for k in 1..=n {
            v[k] = v[k].min((v[k - 1] * v[k - 1] + 2.0 * accel_mps2 * ds).sqrt());
        }
        for k in (0..n).rev() {
            v[k] = v[k].min((v[k + 1] * v[k + 1] + 2.0 * accel_mps2 * ds).sqrt());
        }
        let s_m: Vec<f64> = (0..=n).map(|k| k as f64 * ds).collect();
        let mut t_s = vec![0.0; n + 1];
        for k in 0..n {
            t_s[k + 1] = t_s[k] + 2.0 * ds / (v[k] + v[k + 1]);
        }
        TimeLaw { s_m, v_mps: v, t_s }
    }

    /// The scenario's roll along its `[contour]` (None without one): `trajectory.z_start_mm` to
    /// `z_end_mm` at `contour.speed_mm_s`, `accel_mm_s2` and `lateral_accel_mm_s2`.
    pub fn of_scenario(s: &crate::Scenario) -> Option<TimeLaw> {
        let c = &s.contour;
        if !c.is_given() {
            return None;
        }
        let contour = Contour::from_scenario(s).unwrap_or_else(|e| panic!("[contour] was not checked: {e}"));
        let t = &s.trajectory;
        Some(TimeLaw::new(
            &contour,
            t.z_start_mm * 1e-3,
            t.z_end_mm * 1e-3,
            c.speed_mm_s * 1e-3,
            c.accel_mm_s2 * 1e-3,
            c.lateral_accel_mm_s2 * 1e-3,
        ))
    }

    /// How long the scenario's roll takes, s: its contour's time law, or `trajectory.roll_s`.
    pub fn roll_s(s: &crate::Scenario) -> f64 {
        TimeLaw::of_scenario(s).map_or(s.trajectory.roll_s, |l| l.duration_s())
    }

    /// How long the roll takes, s.
    pub fn duration_s(&self) -> f64 {
        *self.t_s.last().expect("a law has samples")
    }

    /// Distance from the roll's start (m), speed (m/s) and tangential acceleration (m/s²) `tau`
    /// seconds into the roll; at rest at the ends outside `[0, duration]`.
    pub fn at(&self, tau: f64) -> (f64, f64, f64) {
        let last = self.t_s.len() - 1;
        if tau <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        if tau >= self.t_s[last] {
            return (self.s_m[last], 0.0, 0.0);
        }
        let k = self.t_s.partition_point(|&t| t <= tau) - 1;
        let ds = self.s_m[k + 1] - self.s_m[k];
        let (v0, v1) = (self.v_mps[k], self.v_mps[k + 1]);
        let a = (v1 * v1 - v0 * v0) / (2.0 * ds);
        let x = tau - self.t_s[k];
        (self.s_m[k] + v0 * x + 0.5 * a * x * x, v0 + a * x, a)
    }
}

/// How close to the wrist singularity (joint 5 at zero: joints 4 and 6 aligned) a contour may
/// take the arm, rad: within 10° the wrist's speeds for a turn of the heading grow as 1 / sin q5.
pub const WRIST_SINGULARITY_MARGIN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// The reach check's sample spacing along the contour, m: a heading change of at most 0.1 rad
/// per sample at the sunroof's 20 mm minimum radius, so each IK starts next to its answer.
pub const REACH_STEP_M: f64 = 2e-3;

/// Largest joint move between two samples the reach check accepts, rad: more is the IK jumping
/// to another branch (a wrist flip), not the arm following the contour.
pub const REACH_MAX_JOINT_STEP_RAD: f64 = 0.3;

/// Where along a contour the arm cannot follow it, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct ReachError {
    /// Arc length of the first sample that fails, m.
    pub s_m: f64,
    pub why: String,
}

impl std::fmt::Display for ReachError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "at arc length {:.1} mm: {}", self.s_m * 1e3, self.why)
    }
}

impl Contour {
    /// The TCP pose over the contour at `s_m`: at height `tcp_z_base_m`, the tool pointing down
    /// and turned about the normal by the heading (the wheel's axis across the tangent; at
    /// heading 0 the straight strip's tool-down pose).
    pub fn tcp_pose(&self, s_m: f64, tcp_z_base_m: f64) -> nalgebra::Isometry3<f64> {
        let p = self.at(s_m);
        let down = robot::tool_down_pose(p.xy_base_m[0], p.xy_base_m[1], tcp_z_base_m);
        let turn = nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), p.heading_rad);
        nalgebra::Isometry3::from_parts(down.translation, turn * down.rotation)
    }

    /// The arm's joints along the contour from `s_from_m` to `s_to_m` (past the length of a
    /// closed contour: round again) every [`REACH_STEP_M`], the TCP on [`Contour::tcp_pose`], each
    /// IK seeded with the sample before (the first with `seed`): the check before a run. Refused
    /// at the first sample that is out of reach, puts a joint past its range (joint 6 winds up
    /// through a closed contour), comes within [`WRIST_SINGULARITY_MARGIN_RAD`] of the wrist
    /// singularity, or jumps to another branch ([`REACH_MAX_JOINT_STEP_RAD`]).
    pub fn joints_along(
        &self,
        robot: &robot::Robot,
        tcp_z_base_m: f64,
        s_from_m: f64,
        s_to_m: f64,
        seed: &robot::Vec6,
    ) -> Result<Vec<(f64, robot::Vec6)>, ReachError> {
        let n = ((s_to_m - s_from_m) / REACH_STEP_M).ceil().max(0.0) as usize;
        let mut out = Vec::with_capacity(n + 1);
        let mut prev = *seed;
        for k in 0..=n {
            let s = (s_from_m + k as f64 * REACH_STEP_M).min(s_to_m);
            let q = robot.ik_tcp(&self.tcp_pose(s, tcp_z_base_m), &prev).map_err(|e| ReachError { s_m: s, why: e.to_string() })?;
            if q[4].abs() < WRIST_SINGULARITY_MARGIN_RAD {
                return Err(ReachError {
                    s_m: s,
                    why: format!(
                        "joint 5 at {:.1}°, within {:.0}° of the wrist singularity",
                        q[4].to_degrees(),
                        WRIST_SINGULARITY_MARGIN_RAD.to_degrees()
                    ),
                });
            }
            if k > 0 {
                if let Some(j) = (0..6).find(|&j| (q[j] - prev[j]).abs() > REACH_MAX_JOINT_STEP_RAD) {
                    return Err(ReachError {
                        s_m: s,
                        why: format!(
                            "joint {} jumps by {:.1}° in {:.0} mm (another IK branch)",
                            j + 1,
                            (q[j] - prev[j]).to_degrees(),
                            REACH_STEP_M * 1e3
                        ),
                    });
                }
            }
            out.push((s, q));
            prev = q;
        }
        Ok(out)
    }
}

/// Point and heading a distance `a_m` (0 ≤ a ≤ the piece's length) into `piece` from `(p, h)`.
fn end_of(piece: &Piece, p: [f64; 2], h: Heading, a_m: f64) -> ([f64; 2], Heading) {
    match *piece {
        Piece::Line { .. } => ([p[0] + a_m * h.cos, p[1] + a_m * h.sin], h),
        Piece::Arc { radius_m, turn_rad } => {
            let side = turn_rad.signum();
            let dh = side * a_m / radius_m;
            // Chord form: exact for any turn, no centre needed.
            let end = Heading::new(h.rad + dh);
            ([p[0] + side * radius_m * (end.sin - h.sin), p[1] - side * radius_m * (end.cos - h.cos)], end)
        }
    }
}

/// The distance into `piece` (starting at `(p, h)`) of its point nearest to `xy`.
fn nearest_along(piece: &Piece, p: [f64; 2], h: Heading, xy: [f64; 2]) -> f64 {
    let d = [xy[0] - p[0], xy[1] - p[1]];
    match *piece {
        Piece::Line { length_m } => (d[0] * h.cos + d[1] * h.sin).clamp(0.0, length_m),
        Piece::Arc { radius_m, turn_rad } => {
            let side = turn_rad.signum();
            // The centre, on the side the arc bends to; the angle swept from the start radius to
            // xy's, counted in the turn's sense, in [0, 2π).
            let c = [p[0] - side * radius_m * h.sin, p[1] + side * radius_m * h.cos];
            let (r0, r) = ([p[0] - c[0], p[1] - c[1]], [xy[0] - c[0], xy[1] - c[1]]);
            let phi = (side * (r0[0] * r[1] - r0[1] * r[0]).atan2(r0[0] * r[0] + r0[1] * r[1])).rem_euclid(TAU);
            let total = turn_rad.abs();
            if phi <= total {
                return radius_m * phi;
            }
            // Outside the arc's sweep: the nearer of its two ends.
            let end = end_of(piece, p, h, radius_m * total).0;
            if (xy[0] - end[0]).hypot(xy[1] - end[1]) < d[0].hypot(d[1]) {
                radius_m * total
            } else {
                0.0
            }
        }
    }
}

/// `a` wrapped into (−π, π].
fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > TAU / 2.0 {
        w - TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const MIN_R: f64 = 0.02;

    /// The sunroof's opening of issue 26: 400 x 250 mm, corners of 50 mm.
    fn sunroof() -> Contour {
        Contour::rounded_rectangle([0.9, 0.1], 0.3, 0.4, 0.25, 0.05, MIN_R).unwrap()
    }

    fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    /// A circle of four quarter arcs (either sense): length 2πR, every point R from the centre,
    /// closed with its start's tangent.
    #[test]
    fn a_circle_of_quarter_arcs_is_a_circle() {
        for (turn, side) in [(PI / 2.0, 1.0), (-PI / 2.0, -1.0)] {
            let r = 0.07;
            let c = Contour::new([0.8, -0.2], 1.0, &[Piece::Arc { radius_m: r, turn_rad: turn }; 4], true, MIN_R).unwrap();
            assert!((c.length_m() - TAU * r).abs() < 1e-15);
            let centre = [0.8 - side * r * 1.0f64.sin(), -0.2 + side * r * 1.0f64.cos()];
            for k in 0..100 {
                let p = c.at(k as f64 * c.length_m() / 100.0);
                assert!((dist(p.xy_base_m, centre) - r).abs() < 1e-15, "{p:?}");
                assert_eq!(p.curvature_per_m, side / r);
            }
        }
    }

    /// The rounded rectangle's length is its straight sides plus one circle, 2(w − 2r) + 2(h − 2r)
    /// + 2πr; it closes; its extent is w by h.
    #[test]
    fn the_rounded_rectangle_has_its_closed_form_length_and_extent() {
        let c = Contour::rounded_rectangle([0.0, 0.0], 0.0, 0.4, 0.25, 0.05, MIN_R).unwrap();
        assert!((c.length_m() - (2.0 * 0.3 + 2.0 * 0.15 + TAU * 0.05)).abs() < 1e-14);
        let pts: Vec<[f64; 2]> = (0..4000).map(|k| c.at(k as f64 * c.length_m() / 4000.0).xy_base_m).collect();
        let (min_x, max_x) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[0]), b.max(p[0])));
        let (min_y, max_y) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[1]), b.max(p[1])));
        // Started in the middle of the long side along +x, running counter-clockwise: above it.
        assert!((min_x + 0.2).abs() < 1e-6 && (max_x - 0.2).abs() < 1e-6, "{min_x} {max_x}");
        assert!(min_y.abs() < 1e-12 && (max_y - 0.25).abs() < 1e-6, "{min_y} {max_y}");
    }

    /// The heading is the derivative of the position and the curvature that of the heading
    /// (central differences, away from the pieces' joints); position and heading are continuous
    /// across every joint.
    #[test]
    fn heading_and_curvature_are_the_derivatives_of_the_path() {
        let c = sunroof();
        let e = 1e-6;
        for k in 0..997 {
            let s = (k as f64 + 0.5) * c.length_m() / 997.0;
            let (a, p, b) = (c.at(s - e), c.at(s), c.at(s + e));
            if a.piece != b.piece {
                continue;
            }
            let t = [(b.xy_base_m[0] - a.xy_base_m[0]) / (2.0 * e), (b.xy_base_m[1] - a.xy_base_m[1]) / (2.0 * e)];
            assert!(dist(t, p.tangent()) < 1e-8, "s {s}: {t:?} vs {:?}", p.tangent());
            let k_fd = (b.heading_rad - a.heading_rad) / (2.0 * e);
            assert!((k_fd - p.curvature_per_m).abs() < 1e-6, "s {s}: {k_fd} vs {}", p.curvature_per_m);
        }
        for i in 1..c.pieces().len() {
            let s = c.piece_start_m(i);
            let (a, b) = (c.at(s - 1e-12), c.at(s));
            assert!(dist(a.xy_base_m, b.xy_base_m) < 1e-11 && (a.heading_rad - b.heading_rad).abs() < 1e-9, "joint {i}");
        }
    }

    /// A point set off the contour by d along the moving frame's left projects back to the same
    /// arc length with lateral offset d, on lines and arcs, inside and outside the corners (|d|
    /// below the corner radius); a closed contour wraps past its length.
    #[test]
    fn projecting_an_offset_point_gives_back_its_arc_length_and_offset() {
        let c = sunroof();
        for k in 0..500 {
            let s = (k as f64 + 0.3) * c.length_m() / 500.0;
            let p = c.at(s);
            for d in [-0.02, -0.001, 0.0, 0.004, 0.03] {
                let l = p.left();
                let (sp, lat) = c.project([p.xy_base_m[0] + d * l[0], p.xy_base_m[1] + d * l[1]]);
                assert!((sp - s).abs() < 1e-9 && (lat - d).abs() < 1e-12, "s {s} d {d}: ({sp}, {lat})");
            }
        }
        assert!((c.at(c.length_m() + 0.01).s_m - 0.01).abs() < 1e-12);
        assert_eq!(c.at(c.length_m() + 0.01).xy_base_m, c.at(0.01).xy_base_m);
    }

    /// Bad pieces are refused naming the piece: zero length, a radius below the wheel's, a whole
    /// turn; a closed contour that misses its start or meets it at another tangent.
    #[test]
    fn bad_contours_are_refused_naming_the_piece_or_the_closure() {
        let line = |l: f64| Piece::Line { length_m: l };
        let arc = |r: f64, t: f64| Piece::Arc { radius_m: r, turn_rad: t };
        let refused = |pieces: &[Piece], closed: bool| Contour::new([0.9, 0.0], 0.0, pieces, closed, MIN_R).unwrap_err();
        assert_eq!(refused(&[line(0.1), line(0.0)], false).piece, Some(1));
        assert_eq!(refused(&[line(0.1), arc(0.05, 0.0)], false).piece, Some(1));
        let e = refused(&[line(0.1), arc(0.01, 1.0)], false);
        assert_eq!(e.piece, Some(1));
        assert!(e.why.contains("radius 10.0 mm") && e.why.contains("20.0 mm"), "{e}");
        assert_eq!(refused(&[arc(0.05, TAU)], false).piece, Some(0));
        assert_eq!(refused(&[line(f64::NAN)], false).piece, Some(0));
        assert!(refused(&[], false).why.contains("no pieces"));
        let e = refused(&[arc(0.05, PI), line(0.0001), arc(0.05, PI)], true);
        assert_eq!(e.piece, None);
        assert!(e.why.contains("0.100 mm from its start"), "{e}");
        // An alpha: a line, three quarters of a circle of the line's length, the line again, back
        // through the start point but heading across the start's tangent.
        let r = 0.1;
        let e = refused(&[line(r), arc(r, 1.5 * PI), line(r)], true);
        assert!(e.why.contains("tangent jumps by -90.000°"), "{e}");
        assert!(Contour::new([0.9, 0.0], 0.0, &[line(r), arc(r, 1.5 * PI), line(r)], false, MIN_R).is_ok());
        assert!(Contour::new([0.9, 0.0], 0.0, &[arc(r, PI), arc(r, PI)], true, MIN_R).is_ok());
    }

    /// The arm at the default placement's table height over the sunroof's contour.
    fn arm() -> (robot::Robot, f64, robot::Vec6) {
        let s = crate::Scenario::default();
        let tcp_z = s.placement.table_z_m + crate::geometry::STRIP_TOP_HEIGHT_M + s.robot.wheel_radius_mm * 1e-3;
        (crate::geometry::plant_robot(&s), tcp_z, robot::Vec6::from(robot::pose::IK_SEED_TOOL_DOWN))
    }

    /// Round the sunroof (centred at the default strip's spot, started mid long side and closed
    /// with 5 mm of overlap): every sample's TCP is the contour's point and heading (forward
    /// kinematics, an independent path), joint 6 winds through one turn (the heading's 360°),
    /// and the wrist stays clear of its singularity.
    #[test]
    fn the_arm_follows_the_sunroof_and_joint_6_winds_one_turn() {
        let (robot, tcp_z, seed) = arm();
        let c = Contour::rounded_rectangle([0.9, -0.125], 0.0, 0.4, 0.25, 0.05, MIN_R).unwrap();
        let path = c.joints_along(&robot, tcp_z, 0.0, c.length_m() + 0.005, &seed).unwrap();
        for (s, q) in &path {
            let pose = robot.tcp_pose(q);
            let want = c.tcp_pose(*s, tcp_z);
            assert!((pose.translation.vector - want.translation.vector).norm() < 1e-9, "s {s}");
            assert!(pose.rotation.angle_to(&want.rotation) < 1e-9, "s {s}");
        }
        let (q_first, q_last) = (path[0].1, path.last().unwrap().1);
        let wound = (q_last[5] - q_first[5]).abs().to_degrees();
        let min_q5 = path.iter().map(|(_, q)| q[4].abs()).fold(f64::INFINITY, f64::min);
        eprintln!("sunroof: {} samples, joint 6 wound {wound:.1}°, |joint 5| at least {:.1}°", path.len(), min_q5.to_degrees());
        assert!((wound - 360.0).abs() < 5.0, "joint 6 wound {wound}° over one turn");
    }

    /// Refusals name the arc length where the arm fails: a line that runs away from the base
    /// leaves the workspace somewhere between 1.2 and 1.9 m out (the IRB 2400 reaches 1.55 m; here
    /// joint 3 meets its limit at x = 1.52 m); three turns of a circle wind joint 6 past its 400°
    /// where the heading's turn reaches the range left from the start.
    #[test]
    fn leaving_the_reach_or_winding_joint_6_past_its_range_is_refused_at_the_arc_length() {
        let (robot, tcp_z, seed) = arm();
        let away = Contour::new([0.9, 0.0], 0.0, &[Piece::Line { length_m: 1.5 }], false, MIN_R).unwrap();
        let e = away.joints_along(&robot, tcp_z, 0.0, 1.5, &seed).unwrap_err();
        eprintln!("running away: {e}");
        let x = 0.9 + e.s_m;
        assert!(x > 1.2 && x < 1.9, "{e}");
        assert!(e.to_string().starts_with(&format!("at arc length {:.1} mm", e.s_m * 1e3)), "{e}");
        let r = 0.06;
        let circle = Contour::new([0.9, 0.0], 0.0, &[Piece::Arc { radius_m: r, turn_rad: 1.5 * PI }; 4], false, MIN_R).unwrap();
        let e = circle.joints_along(&robot, tcp_z, 0.0, circle.length_m(), &seed).unwrap_err();
        eprintln!("three turns: {e}");
        assert!(e.why.contains("joint 6"), "{e}");
        let q6_0 = robot.ik_tcp(&circle.tcp_pose(0.0, tcp_z), &seed).unwrap()[5];
        // q6 follows the heading one to one (either sense): the limit is reached after
        // 400° − |q6_0| of turn in the direction joint 6 turns.
        let turned = e.s_m / r;
        let left = [400f64.to_radians() - q6_0, 400f64.to_radians() + q6_0];
        assert!(left.iter().any(|l| (turned - l).abs() < 0.05), "{e}: turned {turned} rad, q6 at start {q6_0}");
    }

    /// The time law's limit: v² κ at the limit is the lateral acceleration given; lines have none.
    /// Near the hint the local projection is the full one, bit for bit, at points around the
    /// whole sunroof (on it, inside and outside its corners, 3 mm off), the hint a fraction of a
    /// millimetre behind as in the loop; far from the hint it falls back to the full one.
    #[test]
    fn the_local_projection_is_the_full_one() {
        let c = sunroof();
        for k in 0..2000 {
            let s = k as f64 * c.length_m() / 2000.0;
            let p = c.at(s);
            for off in [-3e-3, 0.0, 3e-3] {
                let [lx, ly] = p.left();
                let xy = [p.xy_base_m[0] + off * lx, p.xy_base_m[1] + off * ly];
                assert_eq!(c.project_near(xy, (s - 2e-4).max(0.0)), c.project(xy), "s {s} off {off}");
            }
        }
        let far = c.at(0.6).xy_base_m;
        assert_eq!(c.project_near(far, 0.0), c.project(far));
    }

    #[test]
    fn the_speed_limit_holds_the_lateral_acceleration() {
        let c = sunroof();
        let in_corner = c.piece_start_m(1) + 0.01;
        let v = c.speed_limit_mps(in_corner, 0.5);
        assert!((v * v / 0.05 - 0.5).abs() < 1e-12, "{v}");
        assert_eq!(c.speed_limit_mps(0.01, 0.5), f64::INFINITY);
    }
}
