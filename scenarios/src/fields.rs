//! The one table of scenario fields: name, type, unit, valid range and meaning of every field a
//! scenario file may set. Loading checks every value against it (`check`), `scenarios/README.md`
//! lists it (`markdown_table`, kept current by a test), and the defaults come from
//! `Scenario::default()` so that they cannot differ from what a file that is silent gets.
//!
//! Values are in the units the file uses (mm where the name says `_mm`, µs for `_us`).

use crate::geometry::STRIP_TOP_HEIGHT_M;
use crate::{Scenario, MAX_CONTOUR_PIECES, MAX_FORCE_POINTS, MAX_SUBSTRATE_FEATURES};

/// What a field holds in the file.
#[derive(Debug, Clone, Copy)]
pub enum Kind {
    /// A number (TOML float or integer).
    Float,
    /// A whole number.
    Int,
    Bool,
    /// Free text.
    Text,
    /// One of these strings.
    Choice(&'static [&'static str]),
    /// An array of exactly this many numbers, each within the field's range.
    Floats(usize),
    /// `[[z_mm, force_n], ...]`: at most `MAX_FORCE_POINTS` points, z strictly ascending.
    Points {
        z: Range,
        force: Range,
    },
    /// `[[a, b, c], ...]`: at most `max_rows` rows of `cols.len()` numbers, column i within
    /// `ranges[i]`; `rows` checks the rows against each other and the other fields.
    Rows {
        max_rows: usize,
        cols: &'static [&'static str],
        ranges: &'static [Range],
        rows: RowsRule,
    },
}

/// A condition across the rows of a `Kind::Rows` field (order, overlap, extent).
#[derive(Debug, Clone, Copy)]
pub struct RowsRule {
    /// What must hold, worded to follow "must" (the README says it).
    pub text: &'static str,
    /// Ok, or the first offending row and column with the message's "why".
    pub check: fn(&Scenario) -> Result<(), RowError>,
}

/// The row, column and value a `RowsRule` refuses, and why.
#[derive(Debug, Clone)]
pub struct RowError {
    pub row: usize,
    pub col: usize,
    pub value: f64,
    pub why: String,
}

/// One end of a valid range, in the field's unit.
#[derive(Debug, Clone, Copy)]
pub enum Limit {
    Num(f64),
    /// `factor` times another field's value (`key`).
    Times(f64, &'static str),
    /// `factor` divided by another field's value (`key`).
    Over(f64, &'static str),
}

impl Limit {
    /// The other field this limit depends on, if any.
    pub fn depends_on(&self) -> Option<&'static str> {
        match *self {
            Limit::Num(_) => None,
            Limit::Times(_, k) | Limit::Over(_, k) => Some(k),
        }
    }
}

/// One end of a range: the limit and whether it belongs to the range.
#[derive(Debug, Clone, Copy)]
pub struct End {
    pub limit: Limit,
    pub inclusive: bool,
}

/// A valid range; a missing end is unbounded (but every number must be finite).
#[derive(Debug, Clone, Copy)]
pub struct Range {
    pub lo: Option<End>,
    pub hi: Option<End>,
}

/// A condition on a field that a range cannot say (it involves several fields).
#[derive(Debug, Clone, Copy)]
pub struct Rule {
    /// What must hold, worded to follow "must be" (the README and the error message say it).
    pub text: &'static str,
    /// Ok, or what the scenario has instead (its numbers, for the message).
    pub check: fn(&Scenario) -> Result<(), String>,
}

/// One scenario field.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// `section.field` as in the file (`description` has no section).
    pub key: &'static str,
    pub kind: Kind,
    /// Unit of the value in the file ("" for none).
    pub unit: &'static str,
    /// Valid range of a number, of each element of `Floats`; unused for other kinds.
    pub range: Range,
    pub rule: Option<Rule>,
    pub meaning: &'static str,
}

impl Field {
    /// The section (`loop`, ...), or "" for top-level fields.
    pub fn section(&self) -> &'static str {
        self.key.rsplit_once('.').map_or("", |(s, _)| s)
    }

    /// The name within the section.
    pub fn name(&self) -> &'static str {
        self.key.rsplit_once('.').map_or(self.key, |(_, n)| n)
    }
}

const fn lo_in(x: f64) -> Option<End> {
    Some(End { limit: Limit::Num(x), inclusive: true })
}
const fn lo_ex(x: f64) -> Option<End> {
    Some(End { limit: Limit::Num(x), inclusive: false })
}
const fn hi_in(x: f64) -> Option<End> {
    Some(End { limit: Limit::Num(x), inclusive: true })
}
const fn hi_ex(x: f64) -> Option<End> {
    Some(End { limit: Limit::Num(x), inclusive: false })
}
const fn of(factor: f64, key: &'static str, inclusive: bool) -> Option<End> {
    Some(End { limit: Limit::Times(factor, key), inclusive })
}
const fn per(factor: f64, key: &'static str, inclusive: bool) -> Option<End> {
    Some(End { limit: Limit::Over(factor, key), inclusive })
}
const fn range(lo: Option<End>, hi: Option<End>) -> Range {
    Range { lo, hi }
}
/// (0, ∞): lengths, durations, stiffnesses, gains that must act.
const POSITIVE: Range = range(lo_ex(0.0), None);
/// [0, ∞): waits that may be skipped, dampings and masses that may vanish.
const NON_NEGATIVE: Range = range(lo_in(0.0), None);
const ANY: Range = range(None, None);

const fn num(key: &'static str, unit: &'static str, range: Range, meaning: &'static str) -> Field {
    Field { key, kind: Kind::Float, unit, range, rule: None, meaning }
}
const fn int(key: &'static str, unit: &'static str, range: Range, meaning: &'static str) -> Field {
    Field { key, kind: Kind::Int, unit, range, rule: None, meaning }
}
const fn flag(key: &'static str, meaning: &'static str) -> Field {
    Field { key, kind: Kind::Bool, unit: "", range: ANY, rule: None, meaning }
}
const fn choice(key: &'static str, names: &'static [&'static str], meaning: &'static str) -> Field {
    Field { key, kind: Kind::Choice(names), unit: "", range: ANY, rule: None, meaning }
}
const fn with_rule(f: Field, text: &'static str, check: fn(&Scenario) -> Result<(), String>) -> Field {
    Field { rule: Some(Rule { text, check }), ..f }
}

/// A peak speed (mm/s) against the TCP speed reflex.
fn below_tcp_limit(what: &str, peak_mm_s: f64, s: &Scenario) -> Result<(), String> {
    let limit = 1e3 * s.safety.max_tcp_speed_mps;
    if peak_mm_s < limit {
        Ok(())
    } else {
        Err(format!("the {what} peaks at {} mm/s, the limit is {} mm/s", fmt_num(peak_mm_s), fmt_num(limit)))
    }
}

/// The strip's height at its centre line, mm: a bulge may not reach it.
const STRIP_TOP_MM: f64 = STRIP_TOP_HEIGHT_M * 1e3;
/// Placement limit, m: beyond the IRB 2400's 1.55 m reach with margin.
const REACH_M: f64 = 2.0;
/// Peak speed of the rolling phase's cosine velocity profile (twice the mean), mm/s.
/// Along a contour the time law's cruise speed is the peak (`contour.speed_mm_s`, checked there).
fn roll_peak_speed_mm_s(s: &Scenario) -> f64 {
    let t = &s.trajectory;
    if s.contour.is_given() {
        return 0.0;
    }
    2.0 * (t.z_end_mm - t.z_start_mm) / t.roll_s
}
/// Peak speed of the lift-off's cosine blend over `lift_mm` (π/2 times the mean), mm/s.
fn lift_peak_speed_mm_s(s: &Scenario) -> f64 {
    let t = &s.trajectory;
    std::f64::consts::FRAC_PI_2 * t.lift_mm / t.lift_s
}

/// Longest windowed strip, mm: a door opening is 3-4 m (issue 25).
const MAX_STRIP_MM: f64 = 5000.0;

/// Whether `x` is a whole number of `unit` (to a millionth of it).
fn whole(x: f64, unit: f64) -> bool {
    (x / unit - (x / unit).round()).abs() < 1e-6
}

const BUMP_RANGES: [Range; 3] =
    [range(lo_in(0.0), of(1.0, "strip.length_mm", true)), POSITIVE, range(lo_ex(-STRIP_TOP_MM), hi_ex(STRIP_TOP_MM))];
const SEAM_RANGES: [Range; 3] =
    [range(lo_in(0.0), of(1.0, "strip.length_mm", true)), range(lo_ex(-STRIP_TOP_MM), hi_ex(STRIP_TOP_MM)), POSITIVE];

const PIECE_RANGES: [Range; 3] = [NON_NEGATIVE, NON_NEGATIVE, range(lo_ex(-360.0), hi_ex(360.0))];

/// How far a closed contour's strip may run past its start, mm: a few millimetres of overlap
/// closes the seal, a second lap is not a seal.
pub const CONTOUR_OVERLAP_MAX_MM: f64 = 50.0;

/// The contour's rows: each a line or an arc, the contour built (`contour::Contour::new`'s
/// refusals name the piece: the row), the strip's run on it and the arm able to follow it
/// (`contour::Contour::joints_along`, refused at the row holding the arc length).
fn contour_pieces(s: &Scenario) -> Result<(), RowError> {
    let c = &s.contour;
    if !c.is_given() {
        return Ok(());
    }
    if s.egm.enabled {
        return Err(RowError {
            row: 0,
            col: 0,
            value: f64::NAN,
            why: "must be empty with egm.enabled: the EGM force controller rolls a straight strip".into(),
        });
    }
    for (i, &[line, radius, turn]) in c.pieces.iter().enumerate() {
        let arc = line == 0.0 && radius > 0.0 && turn != 0.0;
        let straight = line > 0.0 && radius == 0.0 && turn == 0.0;
        if !(arc || straight) {
            let col = if line > 0.0 { 1 } else { 0 };
            return Err(RowError {
                row: i,
                col,
                value: c.pieces[i][col],
                why: "must be a line [length_mm, 0, 0] or an arc [0, radius_mm, turn_deg], each of positive length".into(),
            });
        }
    }
    let contour = crate::contour::Contour::from_scenario(s).map_err(|e| {
        let row = e.piece.unwrap_or(c.pieces.len() - 1);
        let col = if e.piece.is_some() && c.pieces[row][0] == 0.0 { 1 } else { 0 };
        RowError { row, col, value: c.pieces[row][col], why: format!("must make a contour that can be rolled: {e}") }
    })?;
    let length_mm = contour.length_m() * 1e3;
    let last = c.pieces.len() - 1;
    let most = if c.closed { length_mm + CONTOUR_OVERLAP_MAX_MM } else { length_mm };
    if s.strip.length_mm > most + 1e-6 {
        return Err(RowError {
            row: last,
            col: 0,
            value: c.pieces[last][0],
            why: format!(
                "must carry the whole strip: strip.length_mm is {} mm, the contour {:.1} mm long{}",
                fmt_num(s.strip.length_mm),
                length_mm,
                if c.closed {
                    format!(" (a closed one takes at most {} mm of overlap)", fmt_num(CONTOUR_OVERLAP_MAX_MM))
                } else {
                    String::new()
                }
            ),
        });
    }
    if let Err(e) = crate::path::reach_along(s, &contour) {
        let row = contour.at(e.s_m).piece;
        let col = if c.pieces[row][0] == 0.0 { 1 } else { 0 };
        return Err(RowError { row, col, value: c.pieces[row][col], why: format!("must stay where the arm can follow it: {e}") });
    }
    Ok(())
}

/// Substrate features need a windowed strip: the single model has its one `[bulge]`.
fn windowed(s: &Scenario, rows: usize) -> Result<(), RowError> {
    if rows > 0 && s.strip.window_mm == 0.0 {
        return Err(RowError {
            row: 0,
            col: 0,
            value: f64::NAN,
            why: "must come with a windowed strip (strip.window_mm > 0): a single-model strip has its one [bulge]".into(),
        });
    }
    Ok(())
}

fn bumps_on_the_strip(s: &Scenario) -> Result<(), RowError> {
    windowed(s, s.substrate.bumps.len())?;
    let l = s.strip.length_mm;
    for (i, &[c, hw, _]) in s.substrate.bumps.iter().enumerate() {
        if c - hw < 0.0 || c + hw > l {
            return Err(RowError {
                row: i,
                col: 0,
                value: c,
                why: format!(
                    "must lie on the strip: the bump spans {} to {} mm, beyond [0, {}] mm",
                    fmt_num(c - hw),
                    fmt_num(c + hw),
                    fmt_num(l)
                ),
            });
        }
    }
    Ok(())
}

fn seams_apart(s: &Scenario) -> Result<(), RowError> {
    windowed(s, s.substrate.seams.len())?;
    let l = s.strip.length_mm;
    let mut previous: Option<(usize, f64)> = None;
    for (i, &[p, _, sm]) in s.substrate.seams.iter().enumerate() {
        let (a, b) = (p - 0.5 * sm, p + 0.5 * sm);
        if a < 0.0 || b > l {
            return Err(RowError {
                row: i,
                col: 0,
                value: p,
                why: format!(
                    "must lie on the strip: the seam's ramp spans {} to {} mm, beyond [0, {}] mm",
                    fmt_num(a),
                    fmt_num(b),
                    fmt_num(l)
                ),
            });
        }
        if let Some((j, end)) = previous {
            if a < end {
                return Err(RowError { row: i, col: 0, value: p, why: format!("must not overlap the seam before it: its ramp starts at {} mm, seam {j}'s ends at {} mm (seams ascend along the strip)", fmt_num(a), fmt_num(end)) });
            }
        }
        previous = Some((i, b));
    }
    Ok(())
}

/// Every field a scenario file may set, in the order of `scenarios/README.md`.
pub static FIELDS: &[Field] = &[
    Field { key: "description", kind: Kind::Text, unit: "", range: ANY, rule: None, meaning: "Free text shown in summaries and recorded in the MCAP metadata." },
    // [loop]
    choice("loop.mode", &["realtime", "lockstep"], "`realtime`: absolute deadlines, a torque budget per tick, misses held and counted. `lockstep`: the plant waits for every torque (with a watchdog), as fast as both processes allow; deterministic."),
    num("loop.period_s", "s", range(lo_ex(0.0), hi_in(0.1)), "Control period."),
    num("loop.torque_budget_us", "µs", range(lo_ex(0.0), of(1e6, "loop.period_s", false)), "Real-time mode: how long after publishing the state the plant waits for the torque."),
    int("loop.max_consecutive_misses", "ticks", range(lo_in(1.0), hi_in(1000.0)), "Consecutive misses that trigger the safe stop (libfranka stops after 20)."),
    num("loop.lockstep_watchdog_s", "s", range(lo_ex(0.0), hi_in(3600.0)), "Lockstep mode: how long the plant waits for one torque before declaring the controller dead; not for the first answer: tick 0 is republished until a controller answers (`loop.connect_timeout_s` covers one that never does)."),
    with_rule(
        num("loop.duration_s", "s", NON_NEGATIVE, "Run length (`rig run --duration` overrides it); 0 = until the trajectory ends plus 0.2 s."),
        "0 or at least loop.period_s",
        |s| {
            let l = &s.loop_;
            if l.duration_s == 0.0 || l.duration_s >= l.period_s { Ok(()) } else { Err(format!("the period is {} s", fmt_num(l.period_s))) }
        },
    ),
    int("loop.substeps", "", range(lo_in(1.0), hi_in(1000.0)), "Plant integration substeps per tick (robot integrator and strip ZOH steps)."),
    choice("loop.integrator", &["midpoint", "rk4"], "Robot integrator per substep: explicit midpoint (2 forward-dynamics calls) or classic fourth-order Runge–Kutta (4 calls)."),
    num("loop.safe_stop_damping_nms", "N m s/rad", POSITIVE, "Joint damping of the compliant hold, before the first answer and after a reflex (gravity compensation plus this damping), capped at 0.3 M_ii/T per joint."),
    num("loop.hold_bandwidth_hz", "Hz", range(lo_in(0.0), per(0.024, "loop.period_s", true)), "The plant's position hold (a safe stop after misses, a controller fault or a lost controller): each joint critically damped at this bandwidth about the position where the hold began; 0 = a compliant hold (gravity compensation plus `loop.safe_stop_damping_nms`, the arm coasts)."),
    num("loop.takeover_blend_s", "s", NON_NEGATIVE, "How long the torque is blended from the held value to a new controller's value (0 = at once)."),
    int("loop.takeover_after_misses", "ticks", range(lo_in(1.0), hi_in(1000.0)), "Consecutive missed ticks of the active controller after which another controller that is publishing may take over."),
    num("loop.peer_stall_timeout_s", "s", range(lo_ex(0.0), hi_in(3600.0)), "How long a peer that is alive but silent is waited for before it is treated as dead (a stalled host or SIGSTOP is not a death)."),
    num("loop.connect_timeout_s", "s", range(lo_ex(0.0), hi_in(3600.0)), "How long `rig` waits, from the plant's first state, for the controller process it started to answer one (lockstep: tick 0); a controller alive but silent that long is named with what `rig` saw of it (no iceoryx2 node of the rig, a node but no torque publisher, torques of another contract version), both daemons are stopped and `rig` exits 3."),
    num("loop.spin_wait_us", "µs", range(lo_in(0.0), of(1.0, "loop.torque_budget_us", true)), "Real-time mode: the plant busy-polls for the torque this long after publishing before it sleeps on the event (0 = never spin)."),
    num("loop.controller_spin_us", "µs", range(lo_in(0.0), of(0.5e6, "loop.period_s", false)), "Real-time mode: the controller busy-polls from this long before the state is due until this long after (0 = always sleep on the event)."),
    flag("loop.idle_poll", "Hold the kernel's PM QoS CPU latency request at 0 while the plant runs, either mode (needs root; refused requests are logged; without a cpuidle driver the kernel ignores it, and the log says so)."),
    // [robot]
    num("robot.tool_mass_kg", "kg", range(lo_in(0.0), hi_in(20.0)), "Mass of the applicator tool (bracket and wheel); at most the IRB 2400's 20 kg payload class."),
    num("robot.tool_offset_m", "m", range(lo_ex(0.0), hi_in(0.5)), "Tool centre point (wheel centre) offset from the flange along the flange z axis."),
    num("robot.wheel_radius_mm", "mm", range(lo_ex(0.0), hi_in(100.0)), "Applicator wheel radius."),
    Field { key: "robot.armature_kgm2", kind: Kind::Floats(6), unit: "kg m²", range: NON_NEGATIVE, rule: None, meaning: "Reflected motor inertia per joint (6 values)." },
    Field { key: "robot.viscous_nms", kind: Kind::Floats(6), unit: "N m s/rad", range: NON_NEGATIVE, rule: None, meaning: "Viscous joint friction per joint (6 values)." },
    num("robot.plant_inertia_scale", "", range(lo_ex(0.0), hi_in(10.0)), "Scale of every link and tool mass and inertia in the plant against the controller's model (1 = exact model; robustness studies)."),
    // [strip]
    flag("strip.enabled", "`false` runs the robot alone (no strip, no contact)."),
    with_rule(
        num("strip.length_mm", "mm", range(lo_in(8.0), hi_in(MAX_STRIP_MM)), "Strip length along task z (at least two of the largest elements; a single model under 1 m, a windowed strip up to 5 m)."),
        "under 1000 mm unless strip.window_mm > 0 (one reduced model of a longer strip grows with its length)",
        |s| if s.strip.window_mm > 0.0 || s.strip.length_mm < 1000.0 { Ok(()) } else { Err(format!("strip.window_mm is 0 and the strip {} mm long", fmt_num(s.strip.length_mm))) },
    ),
    num("strip.element_mm", "mm", range(lo_in(0.2), hi_in(4.0)), "Target hexahedron edge of the mesh."),
    num("strip.youngs_modulus_pa", "Pa", POSITIVE, "Young's modulus (the linearised Ogden fit of Section 4.1)."),
    num("strip.poisson", "", range(lo_ex(0.0), hi_ex(0.5)), "Poisson's ratio (0.4999 as in the thesis works: mean dilatation)."),
    num("strip.density_kg_m3", "kg/m³", POSITIVE, "Density (EPDM datasheet value)."),
    int("strip.order", "states", range(lo_in(2.0), hi_in(10000.0)), "Reduced model order (balanced truncation; dense, so thousands of states are already slow to build)."),
    choice("strip.boundary", &["bonded", "sliding"], "How the substrate holds the bottom face: `bonded` (all DOFs fixed) or `sliding` (normal fixed, frictionless in-plane)."),
    num("strip.cutoff_hz", "Hz", POSITIVE, "Craig–Bampton fixed-interface mode cut-off."),
    num("strip.damping_alpha", "1/s", NON_NEGATIVE, "Rayleigh damping B = alpha M + beta K (5.24): the mass factor."),
    with_rule(
        num("strip.damping_beta", "s", NON_NEGATIVE, "Rayleigh damping B = alpha M + beta K (5.24): the stiffness factor."),
        "> 0 when strip.damping_alpha = 0 (balanced truncation needs a damped system)",
        |s| if s.strip.damping_alpha > 0.0 || s.strip.damping_beta > 0.0 { Ok(()) } else { Err("strip.damping_alpha is 0 too".into()) },
    ),
    with_rule(
        num("strip.window_mm", "mm", range(lo_in(0.0), of(1.0, "strip.length_mm", true)), "Length of one window of a long strip (issue 25): a chain of overlapping windows, each the reduced model of a strip this long, carries the strip; 0 = one model of the whole strip. No longer than the strip."),
        "0 or a whole number of strip.element_mm (window nodes fall on the strip's)",
        |s| {
            let (w, h) = (s.strip.window_mm, s.strip.element_mm);
            if w == 0.0 || whole(w, h) { Ok(()) } else { Err(format!("{} mm with {} mm elements", fmt_num(w), fmt_num(h))) }
        },
    ),
    with_rule(
        num("strip.window_spacing_mm", "mm", POSITIVE, "Distance between neighbouring windows' starts; the wheel's load hands over between window centres this far apart."),
        "at most strip.window_mm / 4 and a whole number of strip.element_mm, when strip.window_mm > 0",
        |s| {
            let (w, sp, h) = (s.strip.window_mm, s.strip.window_spacing_mm, s.strip.element_mm);
            if w == 0.0 || (sp <= 0.25 * w + 1e-9 && whole(sp, h) && whole(s.strip.length_mm - w, h)) {
                Ok(())
            } else {
                Err(format!("window {} mm, spacing {} mm, strip {} mm, elements {} mm", fmt_num(w), fmt_num(sp), fmt_num(s.strip.length_mm), fmt_num(h)))
            }
        },
    ),
    // [bulge]
    num("bulge.height_mm", "mm", range(lo_ex(-STRIP_TOP_MM), hi_ex(STRIP_TOP_MM)), "Peak height of the raised-cosine bump of the substrate under the strip (negative: a dip); less than the strip's 8 mm height at its centre."),
    num("bulge.half_width_mm", "mm", POSITIVE, "Half the bump's full width along the strip."),
    with_rule(
        num("bulge.center_mm", "mm", range(lo_in(0.0), of(1.0, "strip.length_mm", true)), "Position of the bump's peak along the strip."),
        "with bulge.half_width_mm within [0, strip.length_mm] on a windowed strip (strip.window_mm > 0) when bulge.height_mm is not 0: the chain carries it as one of the substrate's bumps",
        |s| {
            let (b, l) = (&s.bulge, s.strip.length_mm);
            if s.strip.window_mm == 0.0 || b.height_mm == 0.0 || (b.center_mm - b.half_width_mm >= 0.0 && b.center_mm + b.half_width_mm <= l) {
                Ok(())
            } else {
                Err(format!("the bump spans {} to {} mm, beyond [0, {}] mm", fmt_num(b.center_mm - b.half_width_mm), fmt_num(b.center_mm + b.half_width_mm), fmt_num(l)))
            }
        },
    ),
    // [substrate]
    Field {
        key: "substrate.bumps",
        kind: Kind::Rows { max_rows: MAX_SUBSTRATE_FEATURES, cols: &["center_mm", "half_width_mm", "height_mm"], ranges: &BUMP_RANGES, rows: RowsRule { text: "lie on the strip (center_mm ± half_width_mm within [0, strip.length_mm]); only with strip.window_mm > 0", check: bumps_on_the_strip } },
        unit: "mm",
        range: ANY,
        rule: None,
        meaning: "Bumps and dips of the substrate along a windowed strip: raised cosines of this centre, half width and peak height (negative: a dip).",
    },
    Field {
        key: "substrate.seams",
        kind: Kind::Rows { max_rows: MAX_SUBSTRATE_FEATURES, cols: &["position_mm", "step_mm", "smoothing_mm"], ranges: &SEAM_RANGES, rows: RowsRule { text: "lie on the strip with their ramps (position_mm ± smoothing_mm / 2), ascending and not overlapping; only with strip.window_mm > 0", check: seams_apart } },
        unit: "mm",
        range: ANY,
        rule: None,
        meaning: "Seams between substrate panels along a windowed strip: the substrate steps by step_mm (negative: down) along a raised-cosine ramp smoothing_mm long centred on position_mm.",
    },
    // [placement]
    num("placement.table_z_m", "m", range(lo_in(-REACH_M), hi_in(REACH_M)), "Base z of the table top (strip bottom); within 2 m of the base (the arm reaches 1.55 m)."),
    num("placement.strip_start_x_m", "m", range(lo_in(-REACH_M), hi_in(REACH_M)), "Base x of the strip's start (task z = 0)."),
    num("placement.strip_y_m", "m", range(lo_in(-REACH_M), hi_in(REACH_M)), "Base y of the strip's centre line (task x = 0)."),
    // [contact]
    num("contact.stiffness_n_per_m", "N/m", POSITIVE, "Wheel–strip penalty stiffness (unilateral)."),
    num("contact.damping_ns_per_m", "N s/m", NON_NEGATIVE, "Wheel–strip penalty damping."),
    // [trajectory]
    num("trajectory.approach_height_mm", "mm", range(lo_ex(0.0), hi_in(100.0)), "Start height of the wheel's lowest point above the undeformed strip top."),
    num("trajectory.settle_s", "s", NON_NEGATIVE, "Time to hold the start pose before moving (`rig timing` holds for the whole run with 1e6)."),
    num("trajectory.approach_speed_mm_s", "mm/s", range(lo_ex(0.0), of(1e3, "safety.max_tcp_speed_mps", false)), "Approach speed towards the strip until contact is detected; below the TCP speed reflex."),
    num("trajectory.contact_threshold_n", "N", range(lo_ex(0.0), of(1.0, "safety.max_contact_force_n", false)), "Contact detection threshold on the force magnitude."),
    num("trajectory.force_ref_n", "N", range(of(-1.0, "safety.max_contact_force_n", false), hi_ex(0.0)), "Force set-point on the strip while rolling (negative = pressing, thesis sign); inside the contact force reflex."),
    Field {
        key: "trajectory.force_ref_along_z",
        kind: Kind::Points {
            z: range(lo_in(0.0), of(1.0, "strip.length_mm", true)),
            force: range(of(-1.0, "safety.max_contact_force_n", false), hi_ex(0.0)),
        },
        unit: "mm, N",
        range: ANY,
        rule: None,
        meaning: "Optional force set-point along the strip, cosine-blended between knots ((1 - cos pi x)/2: slope continuous, zero at each knot) and held beyond the ends; replaces force_ref_n from the force ramp to the ramp-down.",
    },
    num("trajectory.force_ramp_s", "s", POSITIVE, "Force ramp time (cosine blend from the contact force to the set-point)."),
    num("trajectory.dwell_s", "s", NON_NEGATIVE, "Dwell at full force before rolling."),
    num("trajectory.z_start_mm", "mm", range(lo_in(0.0), of(1.0, "trajectory.z_end_mm", false)), "Wheel position along the strip where rolling starts."),
    num("trajectory.z_end_mm", "mm", range(of(1.0, "trajectory.z_start_mm", false), of(1.0, "strip.length_mm", true)), "Wheel position along the strip where rolling ends."),
    with_rule(
        num("trajectory.roll_s", "s", POSITIVE, "Rolling time with the cosine velocity profile (not used along a `[contour]`: its time law sets the roll's speed)."),
        "long enough for a peak rolling speed 2 (z_end_mm - z_start_mm) / roll_s below 1e3 safety.max_tcp_speed_mps (mm/s)",
        |s| below_tcp_limit("roll", roll_peak_speed_mm_s(s), s),
    ),
    num("trajectory.ramp_down_s", "s", POSITIVE, "Force ramp-down time after rolling."),
    num("trajectory.lift_mm", "mm", range(lo_ex(0.0), hi_in(100.0)), "Lift-off height above the strip after the ramp-down."),
    with_rule(
        num("trajectory.lift_s", "s", POSITIVE, "Lift-off time (cosine blend)."),
        "long enough for a peak lift-off speed π lift_mm / (2 lift_s) below 1e3 safety.max_tcp_speed_mps (mm/s)",
        |s| below_tcp_limit("lift-off", lift_peak_speed_mm_s(s), s),
    ),
    // [controller]
    num("controller.force_crossover_hz", "Hz", range(lo_ex(0.0), per(0.5, "loop.period_s", false)), "Desired crossover of the force loop (Section 6.2: about 25 Hz); below the Nyquist frequency."),
    flag("controller.force_integral", "Integral action on the force error (the thesis has none)."),
    num("controller.force_integral_ratio", "", range(lo_ex(0.0), hi_in(1.0)), "Integral gain relative to the crossover: ki = ratio 2π f_c (at most 1: the integral costs at most 45° of phase margin)."),
    num("controller.force_integral_limit_n", "N", range(lo_ex(0.0), of(1.0, "safety.max_contact_force_n", true)), "Anti-windup clamp on the integral's contribution."),
    flag("controller.force_rate_feedforward", "Feed the force set-point's rate forward as the wheel velocity the strip's stiffness asks for (the thesis has none)."),
    num("controller.motion_bandwidth_hz", "Hz", range(lo_ex(0.0), per(0.5, "loop.period_s", false)), "Translational PD bandwidth (the five motion directions); below the Nyquist frequency."),
    num("controller.motion_damping_ratio", "", range(lo_ex(0.0), hi_in(10.0)), "Damping ratio of the translational and rotational PD."),
    num("controller.rotation_bandwidth_hz", "Hz", range(lo_ex(0.0), per(0.5, "loop.period_s", false)), "Rotational PD bandwidth; below the Nyquist frequency."),
    num("controller.joint_damping_nms", "N m s/rad", NON_NEGATIVE, "Joint-space damping added to the control torque (small, for the wrist)."),
    num("controller.strip_stiffness_n_per_m", "N/m", POSITIVE, "Driving-point stiffness of the strip under the wheel, the force-loop design rule's plant (`rig design` reports it for a model)."),
    with_rule(
        num("controller.tare_s", "s", range(lo_in(0.0), hi_in(10.0)), "Tare in free air: for this long from its first state (at rest in the start pose) the controller averages the measured wrench less the tool's nominal load and subtracts the mean from then on (0: no tare)."),
        "at most trajectory.settle_s (the tare ends before the approach)",
        |s| if s.controller.tare_s <= s.trajectory.settle_s { Ok(()) } else { Err(format!("trajectory.settle_s is {} s", fmt_num(s.trajectory.settle_s))) },
    ),
    flag("controller.tool_load_compensation", "Subtract the tool's nominal gravity load (its mass and centre as the controller believes them, rotating with the tool) from the measured wrench."),
    num("controller.force_filter_hz", "Hz", range(lo_in(0.0), per(0.5, "loop.period_s", false)), "First-order low-pass on the measured wrench (0: none); below the Nyquist frequency."),
    // [recording]
    flag("recording.enabled", "Record the run to MCAP."),
    int("recording.queue_capacity", "records", range(lo_in(16.0), hi_in(1048576.0)), "Bounded queue between the loop thread and the writer thread (in lockstep at most 1024: the loop waits for room instead)."),
    int("recording.chunk_size_bytes", "bytes", range(lo_in(1024.0), hi_in(1073741824.0)), "MCAP chunk size bound (a killed run loses at most the open chunk)."),
    num("recording.scene_rate_hz", "Hz", range(lo_ex(0.0), per(1.0, "loop.period_s", true)), "Rate of the Foxglove channels `/tf` (`foxglove.FrameTransforms`) and `/strip_scene` (`foxglove.SceneUpdate`): every round(1 / (rate period))-th tick; at most one per tick."),
    // [safety]
    num("safety.max_tcp_speed_mps", "m/s", POSITIVE, "Reflex: TCP speed limit (ISO 10218-1's reduced speed, 0.25 m/s, by default); crossing it stops the plant at once."),
    num("safety.max_contact_force_n", "N", POSITIVE, "Reflex: limit on the magnitude of the wheel–strip force; crossing it stops the plant at once."),
    // [egm]
    flag("egm.enabled", "Make the plant an ABB robot controller speaking EGM (UDP, protobuf) to the sensor at `egm.sensor_address` instead of taking joint torques over iceoryx2."),
    with_rule(
        Field { key: "egm.sensor_address", kind: Kind::Text, unit: "", range: ANY, rule: None, meaning: "UDP address `host:port` of the EGM sensor (the client program: it binds this port, the plant sends `EgmRobot` there)." },
        "an IP socket address such as 127.0.0.1:6510",
        |s| s.egm.sensor_address.parse::<std::net::SocketAddr>().map(|_| ()).map_err(|e| e.to_string()),
    ),
    with_rule(
        num("egm.cycle_s", "s", range(lo_ex(0.0), hi_in(0.1)), "EGM cycle: one `EgmRobot` sent and one `EgmSensor` taken per cycle (ABB: typically 4 ms)."),
        "a whole number of loop.period_s",
        |s| {
            let n = s.egm.cycle_s / s.loop_.period_s;
            if n >= 1.0 && (n - n.round()).abs() < 1e-9 { Ok(()) } else { Err(format!("the period is {} s", fmt_num(s.loop_.period_s))) }
        },
    ),
    num("egm.comm_timeout_s", "s", range(of(1.0, "egm.cycle_s", false), hi_in(3600.0)), "No valid sensor message for this long ends the EGM session: the robot holds its position, an `/events` entry says why (ABB's CommTimeout)."),
    with_rule(
        num("egm.lag_s", "s", range(lo_in(0.0), hi_in(1.0)), "Total lag of the emulated motion controller: from a joint reference to the joint following it on a ramp (pure delay, the position correction's low-pass and the joint servo's half tick; 12 ms default)."),
        "at least the position correction's own lag 1/(egm.pos_corr_gain 2π egm.lowpass_hz) plus half of loop.period_s (the joint servo's)",
        |s| {
            let own = s.egm.lag_s - s.egm.delay_s(s.loop_.period_s);
            if s.egm.delay_s(s.loop_.period_s) >= -1e-12 { Ok(()) } else { Err(format!("that lag is {} s", fmt_num(own))) }
        },
    ),
    num("egm.lowpass_hz", "Hz", range(lo_ex(0.0), per(0.5, "loop.period_s", false)), "Bandwidth of the position correction's first-order low-pass on the references (ABB's EGM low-pass filter; 20 Hz by default here)."),
    num("egm.pos_corr_gain", "", range(lo_in(0.0), hi_in(1.0)), "EGM position-correction gain (ABB's PosCorrGain): 1 follows the position references, 0 only the speed references."),
    num("egm.servo_bandwidth_hz", "Hz", range(lo_ex(0.0), per(0.5, "loop.period_s", false)), "Natural frequency of the emulated joint position/velocity servo (with model feed-forward)."),
    num("egm.servo_damping_ratio", "", range(lo_ex(0.0), hi_in(10.0)), "Damping ratio of that servo."),
    num("egm.force_phase_margin_deg", "°", range(lo_ex(0.0), hi_ex(90.0)), "The EGM force controller (`egm-controller`): phase margin its admittance is designed for, with the motion controller's delay and low-pass in the loop."),
    // [sensor]
    flag("sensor.enabled", "Model the six-axis force/torque sensor between flange and tool bracket (`false`: the exact contact wrench)."),
    int("sensor.seed", "", range(lo_in(0.0), hi_in(4294967295.0)), "Seed of every random draw of the cell (bias, drift, noise); same seed, bit-identical lockstep run."),
    Field { key: "sensor.bias_range", kind: Kind::Floats(6), unit: "N, N m", range: NON_NEGATIVE, rule: None, meaning: "Power-on bias per axis [Fx, Fy, Fz, Tx, Ty, Tz], drawn uniformly within ± this." },
    Field { key: "sensor.drift_per_sqrt_s", kind: Kind::Floats(6), unit: "N/√s, N m/√s", range: NON_NEGATIVE, rule: None, meaning: "Drift per axis: a random walk whose standard deviation grows by this per √s." },
    Field { key: "sensor.noise_sd", kind: Kind::Floats(6), unit: "N, N m", range: NON_NEGATIVE, rule: None, meaning: "White noise per axis, standard deviation of one sample." },
    num("sensor.lowpass_hz", "Hz", range(lo_in(0.0), per(0.5, "loop.period_s", false)), "First-order low-pass of the sensor (0: none); below the Nyquist frequency."),
    int("sensor.delay_ticks", "ticks", range(lo_in(0.0), hi_in(100.0)), "Sample delay: the wrench of tick k is published at tick k + this."),
    Field { key: "sensor.resolution", kind: Kind::Floats(6), unit: "N, N m", range: NON_NEGATIVE, rule: None, meaning: "Quantisation step per axis (0: none)." },
    Field { key: "sensor.range", kind: Kind::Floats(6), unit: "N, N m", range: NON_NEGATIVE, rule: None, meaning: "Calibrated range per axis: the output clips at ± this, the state's SENSOR_SATURATED flag is set and `/events` says so (0: none)." },
    // [drives]
    flag("drives.enabled", "Model the joint drives and encoders: friction with stiction, torque-constant errors, encoder quantisation, a filtered velocity (`false`: ideal)."),
    Field { key: "drives.coulomb_nm", kind: Kind::Floats(6), unit: "N m", range: NON_NEGATIVE, rule: None, meaning: "Coulomb (kinetic) friction per joint." },
    with_rule(
        Field { key: "drives.breakaway_nm", kind: Kind::Floats(6), unit: "N m", range: NON_NEGATIVE, rule: None, meaning: "Breakaway (static) friction per joint: a joint sticks under less." },
        "at least drives.coulomb_nm, joint by joint",
        |s| match (0..6).find(|&i| s.drives.breakaway_nm[i] < s.drives.coulomb_nm[i]) {
            None => Ok(()),
            Some(i) => Err(format!("joint {} has breakaway {} N m < Coulomb {} N m", i + 1, fmt_num(s.drives.breakaway_nm[i]), fmt_num(s.drives.coulomb_nm[i]))),
        },
    ),
    Field { key: "drives.stribeck_radps", kind: Kind::Floats(6), unit: "rad/s", range: NON_NEGATIVE, rule: None, meaning: "Stribeck velocity per joint: friction falls from breakaway to Coulomb as exp(-(q̇/v_s)²) (0: at once, Coulomb at any speed, breakaway only to start)." },
    Field { key: "drives.viscous_nms", kind: Kind::Floats(6), unit: "N m s/rad", range: NON_NEGATIVE, rule: None, meaning: "Viscous friction per joint that the controller's model does not know (on top of `robot.viscous_nms`)." },
    Field { key: "drives.torque_constant_error", kind: Kind::Floats(6), unit: "", range: range(lo_in(-0.5), hi_in(0.5)), rule: None, meaning: "Torque-constant error per joint: the drive applies (1 + this) times the command." },
    Field { key: "drives.encoder_counts_per_rev", kind: Kind::Floats(6), unit: "counts", range: NON_NEGATIVE, rule: None, meaning: "Encoder counts per joint revolution: the state's q is quantised to 2π/counts (0: exact)." },
    num("drives.velocity_filter_hz", "Hz", range(lo_in(0.0), per(0.5, "loop.period_s", false)), "The state's q̇: the encoder's difference quotient through a first-order low-pass at this cut-off (0: the exact q̇)."),
    // [mismatch]
    num("mismatch.tool_mass_error", "", range(lo_ex(-1.0), hi_in(1.0)), "Relative error of the tool mass the controller believes: (1 + this) robot.tool_mass_kg."),
    Field { key: "mismatch.tool_com_error_m", kind: Kind::Floats(3), unit: "m", range: range(lo_in(-0.5), hi_in(0.5)), rule: None, meaning: "Error of the tool's centre of mass the controller believes, flange axes." },
    num("mismatch.tool_inertia_error", "", range(lo_ex(-1.0), hi_in(1.0)), "Relative error of the tool inertia the controller believes."),
    Field { key: "mismatch.link_inertia_scale", kind: Kind::Floats(6), unit: "", range: range(lo_ex(0.0), hi_in(10.0)), rule: None, meaning: "Per link, the plant's mass and inertia against the controller's model (1 = exact; multiplies robot.plant_inertia_scale)." },    // [contour]
    Field {
        key: "contour.pieces",
        kind: Kind::Rows { max_rows: MAX_CONTOUR_PIECES, cols: &["line_mm", "radius_mm", "turn_deg"], ranges: &PIECE_RANGES, rows: RowsRule { text: "each be a line [length, 0, 0] or an arc [0, radius, turn], the radius at least 20 mm and the turn under 360°, a closed contour meeting its start with its tangent (contour::MIN_RADIUS_M, CLOSURE_TOLERANCE_M); the strip's run z_start_mm to z_end_mm must lie on it (strip.length_mm at most the contour's length plus 50 mm of overlap when closed, its length when open) and within the arm's reach, joint ranges and 10° of the wrist singularity (path::reach_along, contour::Contour::joints_along)", check: contour_pieces } },
        unit: "mm, mm, °",
        range: ANY,
        rule: None,
        meaning: "A contour on the substrate (issue 26): pieces from the strip's start ([placement]) on, each continuing the tangent before it; the strip lies along it, its arc length the strip's z. Empty: the straight strip along base +x.",
    },
    Field { key: "contour.pieces_file", kind: Kind::Text, unit: "", range: ANY, rule: None, meaning: "A file of segments giving contour.pieces instead, for long contours: one `line_mm, radius_mm, turn_deg` row per line, `#` comments; relative to the scenario file. Its rows are checked as contour.pieces' and refusals name its line; copies of the scenario (recordings, sweep and study cases) carry the rows inline." },
    num("contour.heading_deg", "°", range(lo_in(-360.0), hi_in(360.0)), "Heading of the contour at its start, from base +x towards base +y."),
    flag("contour.closed", "The contour closes on its start (a sunroof's opening)."),
    with_rule(
        num("contour.speed_mm_s", "mm/s", POSITIVE, "Rolling speed along a contour's lines (the time law's cruise)."),
        "below 1e3 safety.max_tcp_speed_mps",
        |s| below_tcp_limit("contour's roll", s.contour.speed_mm_s, s),
    ),
    num("contour.accel_mm_s2", "mm/s²", POSITIVE, "Tangential acceleration of the contour's time law (speeding up from and slowing down to rest, and into and out of arcs)."),
    num("contour.lateral_accel_mm_s2", "mm/s²", POSITIVE, "The time law's rule in arcs: the rolling speed stays at or below sqrt(lateral_accel radius)."),
];

/// The field called `key` (`section.field`).
pub fn field(key: &str) -> Option<&'static Field> {
    FIELDS.iter().find(|f| f.key == key)
}

/// The sections of the table, in order ("" for top-level fields).
pub fn sections() -> Vec<&'static str> {
    let mut out: Vec<&'static str> = Vec::new();
    for f in FIELDS {
        if !out.contains(&f.section()) {
            out.push(f.section());
        }
    }
    out
}

/// The field names of one section, for "did you mean" lists.
pub fn names_in(section: &str) -> Vec<&'static str> {
    FIELDS.iter().filter(|f| f.section() == section).map(|f| f.name()).collect()
}

/// A number as the messages and the README print it: plain, or with an exponent where that is
/// shorter for a very large or small number (1e6, 3e-6; but 1000, 0.001, 524288).
pub fn fmt_num(x: f64) -> String {
    let plain = format!("{x}");
    let exp = format!("{x:e}");
    if x.is_finite() && (x.abs() >= 1e5 || (x != 0.0 && x.abs() < 1e-3)) && exp.len() < plain.len() {
        exp
    } else {
        plain
    }
}

fn fmt_limit(l: Limit) -> String {
    match l {
        Limit::Num(x) => fmt_num(x),
        Limit::Times(1.0, k) => k.to_string(),
        Limit::Times(-1.0, k) => format!("-{k}"),
        Limit::Times(f, k) => format!("{} {k}", fmt_num(f)),
        Limit::Over(f, k) => format!("{} / {k}", fmt_num(f)),
    }
}

impl Range {
    /// `(0, 0.1]`, `[0, ∞)`, `(0, 1e6 loop.period_s)`: the README's and the messages' form.
    pub fn text(&self) -> String {
        self.render(fmt_limit)
    }

    fn render(&self, limit: impl Fn(Limit) -> String) -> String {
        let lo = match self.lo {
            Some(e) => format!("{}{}", if e.inclusive { "[" } else { "(" }, limit(e.limit)),
            None => "(-∞".into(),
        };
        let hi = match self.hi {
            Some(e) => format!("{}{}", limit(e.limit), if e.inclusive { "]" } else { ")" }),
            None => "∞)".into(),
        };
        format!("{lo}, {hi}")
    }

    /// Whether any end depends on another field.
    pub fn is_relative(&self) -> bool {
        [self.lo, self.hi].iter().flatten().any(|e| e.limit.depends_on().is_some())
    }

    /// The range with every limit evaluated (`value` gives another field's value).
    pub fn resolved_text(&self, value: &dyn Fn(&str) -> f64) -> String {
        self.render(|l| fmt_num(resolve(l, value)))
    }

    /// Whether `x` lies in the range. Only the constant ends are checked when `value` is None
    /// (the first pass, before the fields that other ranges depend on are known to be valid).
    pub fn contains(&self, x: f64, value: Option<&dyn Fn(&str) -> f64>) -> bool {
        let end = |e: &Option<End>, above: bool| match e {
            None => true,
            Some(e) => {
                let b = match (e.limit, value) {
                    (Limit::Num(b), _) => b,
                    (l, Some(v)) => resolve(l, v),
                    (_, None) => return true,
                };
                match (above, e.inclusive) {
                    (true, true) => x >= b,
                    (true, false) => x > b,
                    (false, true) => x <= b,
                    (false, false) => x < b,
                }
            }
        };
        x.is_finite() && end(&self.lo, true) && end(&self.hi, false)
    }
}

fn resolve(l: Limit, value: &dyn Fn(&str) -> f64) -> f64 {
    match l {
        Limit::Num(x) => x,
        Limit::Times(f, k) => f * value(k),
        Limit::Over(f, k) => f / value(k),
    }
}

impl Kind {
    /// What the README's type column says.
    pub fn text(&self) -> String {
        match self {
            Kind::Float => "number".into(),
            Kind::Int => "whole number".into(),
            Kind::Bool => "true or false".into(),
            Kind::Text => "string".into(),
            Kind::Choice(_) => "string".into(),
            Kind::Floats(n) => format!("{n} numbers"),
            Kind::Points { .. } => "`[[z_mm, force_n], ...]`".into(),
            Kind::Rows { cols, .. } => format!("`[[{}], ...]`", cols.join(", ")),
        }
    }
}

impl Field {
    /// The valid range as the README says it (rule included).
    pub fn valid_text(&self) -> String {
        let base = match self.kind {
            Kind::Float | Kind::Int => self.range.text(),
            Kind::Floats(_) => format!("each in {}", self.range.text()),
            Kind::Bool | Kind::Text => "any".into(),
            Kind::Choice(names) => format!("one of {}", names.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")),
            Kind::Points { z, force } => {
                format!("at most {MAX_FORCE_POINTS} points; z_mm in {}, strictly ascending; force_n in {}", z.text(), force.text())
            }
            Kind::Rows { max_rows, cols, ranges, rows } => {
                let each = cols.iter().zip(ranges).map(|(c, r)| format!("{c} in {}", r.text())).collect::<Vec<_>>().join("; ");
                format!("at most {max_rows} rows; {each}; {}", rows.text)
            }
        };
        match self.rule {
            Some(r) => format!("{base}; {}", r.text),
            None => base,
        }
    }
}

/// The value at `key` (`section.field` or a top-level name, the keys of [`FIELDS`]) of a TOML table.
pub(crate) fn lookup<'a>(doc: &'a toml::Table, key: &str) -> Option<&'a toml::Value> {
    match key.split_once('.') {
        Some((section, name)) => doc.get(section)?.as_table()?.get(name),
        None => doc.get(key),
    }
}

/// The README's field table (markdown), defaults from `Scenario::default()`.
pub fn markdown_table() -> String {
    let defaults = toml::Table::try_from(Scenario::default()).expect("the default scenario serialises");
    let mut s = String::from("| field | type | unit | default | valid range | meaning |\n| --- | --- | --- | --- | --- | --- |\n");
    for f in FIELDS {
        let default = lookup(&defaults, f.key).map_or_else(|| "—".into(), fmt_value);
        let unit = if f.unit.is_empty() { "—" } else { f.unit };
        s += &format!("| `{}` | {} | {unit} | `{default}` | {} | {} |\n", f.key, f.kind.text(), f.valid_text(), f.meaning);
    }
    s
}

/// A TOML value as the README and the messages print it.
pub fn fmt_value(v: &toml::Value) -> String {
    match v {
        toml::Value::Float(x) => fmt_num(*x),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::String(s) => format!("{s:?}"),
        toml::Value::Boolean(b) => b.to_string(),
        toml::Value::Array(a) => format!("[{}]", a.iter().map(fmt_value).collect::<Vec<_>>().join(", ")),
        other => other.to_string(),
    }
}
