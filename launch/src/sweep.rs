//! `rig sweep`: a parameter study. Each case is the base scenario with some fields overridden
//! (`--set section.field=v1,v2,...`), run in lockstep in process (`in_process.rs`: the plant's
//! tick and the controller's step in one thread, bit-identical to `rig run --mode lockstep` of
//! that scenario), one case per core at a time, its figures from its ticks kept in memory and its
//! recording written only when `--recordings` asks. One `--set` per axis; by default each axis is
//! varied alone around the base scenario (a robustness table), with `--grid` over every
//! combination.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::Context;
use serde::Serialize;

/// One axis of the study: a dotted scenario field and the values it takes.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    pub section: String,
    pub field: String,
    pub values: Vec<toml::Value>,
}

/// Parses `section.field=v1,v2,...`; values are TOML scalars (numbers, booleans, quoted or bare
/// strings).
pub fn parse_axis(s: &str) -> anyhow::Result<Axis> {
    let (key, values) = s.split_once('=').with_context(|| format!("--set {s:?}: expected section.field=v1,v2,..."))?;
    let (section, field) =
        key.split_once('.').with_context(|| format!("--set {s:?}: the field needs its section, e.g. bulge.height_mm"))?;
    anyhow::ensure!(!section.is_empty() && !field.is_empty() && !field.contains('.'), "--set {s:?}: expected section.field");
    let values: Vec<toml::Value> = values
        .split(',')
        .map(|v| {
            let v = v.trim();
            anyhow::ensure!(!v.is_empty(), "--set {s:?}: empty value");
            // a TOML scalar if it parses as one, else a bare string
            Ok(format!("x = {v}")
                .parse::<toml::Table>()
                .ok()
                .and_then(|mut t| t.remove("x"))
                .unwrap_or_else(|| toml::Value::String(v.into())))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(Axis { section: section.into(), field: field.into(), values })
}

/// `--set` as the command line gives it: `parse_axis`, and the field must be one of the
/// scenario's (`scenarios::fields::FIELDS`), so that a typo is refused before anything is written.
pub fn parse_set(s: &str) -> anyhow::Result<Axis> {
    let a = parse_axis(s)?;
    let key = format!("{}.{}", a.section, a.field);
    if scenarios::fields::field(&key).is_none() {
        let names = scenarios::fields::names_in(&a.section);
        if names.is_empty() {
            let sections: Vec<String> = scenarios::fields::sections().iter().filter(|s| !s.is_empty()).map(|s| format!("[{s}]")).collect();
            anyhow::bail!("--set {s:?}: no scenario section [{}]; the sections are {}", a.section, sections.join(", "));
        }
        anyhow::bail!("--set {s:?}: no scenario field {key}; [{}] has {}", a.section, names.join(", "));
    }
    Ok(a)
}

/// A scenario error of a file written from command-line overrides, blamed on the flag that set
/// the field (`flags`: field key and how the command line said it, e.g. ("bulge.height_mm",
/// "--set bulge.height_mm=100")), or on all of them when the bad field is another one that they
/// made invalid (z_end_mm beyond a shortened strip).
pub fn blame_flags(e: scenarios::ScenarioError, flags: &[(String, String)]) -> anyhow::Error {
    let field = e.field().map(|f| f.split(['[', ' ']).next().unwrap_or(f).to_string());
    let culprit = flags.iter().find(|(key, _)| field.as_deref() == Some(key.as_str()));
    let context = match culprit {
        Some((_, flag)) => flag.clone(),
        None if flags.is_empty() => return e.into(),
        None => format!("the scenario with {}", flags.iter().map(|(_, f)| f.as_str()).collect::<Vec<_>>().join(" ")),
    };
    anyhow::Error::new(e).context(context)
}

/// The `--set` flags of a case, for `blame_flags`.
pub fn set_flags(axes: &[Axis], case: &[(usize, usize)]) -> Vec<(String, String)> {
    case.iter()
        .map(|&(a, v)| {
            let key = format!("{}.{}", axes[a].section, axes[a].field);
            let flag = format!("--set {key}={}", axes[a].values[v]);
            (key, flag)
        })
        .collect()
}

/// The cases: each a list of (axis index, value index).
pub fn cases(axes: &[Axis], grid: bool) -> Vec<Vec<(usize, usize)>> {
    if grid {
        let mut out: Vec<Vec<(usize, usize)>> = vec![Vec::new()];
        for (a, axis) in axes.iter().enumerate() {
            out = out.into_iter().flat_map(|c| (0..axis.values.len()).map(move |v| [c.clone(), vec![(a, v)]].concat())).collect();
        }
        out
    } else {
        axes.iter().enumerate().flat_map(|(a, axis)| (0..axis.values.len()).map(move |v| vec![(a, v)])).collect()
    }
}

/// The base scenario's TOML with the case's fields overridden.
pub fn case_scenario(base: &toml::Table, axes: &[Axis], case: &[(usize, usize)]) -> toml::Table {
    let mut doc = base.clone();
    for &(a, v) in case {
        let axis = &axes[a];
        let section = doc.entry(axis.section.clone()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let toml::Value::Table(t) = section {
            t.insert(axis.field.clone(), axis.values[v].clone());
        }
    }
    doc
}

/// A case's Foxglove scene and transforms rate, Hz, unless `--scene-rate` or the base scenario
/// says otherwise. A sweep is read as numbers (the table, `rig compare`); at the scenario default
/// of 100 Hz the scene is about 80 % of a recording's bytes before compression and a third of the
/// sweep's CPU goes to the writers. Every per-tick channel is recorded whatever the rate.
pub const SWEEP_SCENE_RATE_HZ: f64 = 10.0;

/// Sets the case's `recording.scene_rate_hz`: to `flag` when given, else to
/// [`SWEEP_SCENE_RATE_HZ`] unless the base scenario sets its own; never when an axis varies it.
/// Returns the `blame_flags` entry when the flag set it.
pub fn set_scene_rate(doc: &mut toml::Table, axes: &[Axis], flag: Option<f64>) -> Option<(String, String)> {
    const KEY: (&str, &str) = ("recording", "scene_rate_hz");
    if axes.iter().any(|a| (a.section.as_str(), a.field.as_str()) == KEY) {
        return None;
    }
    let section = doc.entry(KEY.0).or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let toml::Value::Table(t) = section else { return None };
    match flag {
        Some(hz) => {
            t.insert(KEY.1.into(), hz.into());
            Some((format!("{}.{}", KEY.0, KEY.1), format!("--scene-rate {hz}")))
        }
        None => {
            t.entry(KEY.1).or_insert(SWEEP_SCENE_RATE_HZ.into());
            None
        }
    }
}

/// What one case measured (from its ticks and the plant's summary).
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub label: String,
    pub scenario: PathBuf,
    /// The case's recording, when written (`--keep`).
    pub recording: Option<PathBuf>,
    /// `rig run`'s exit status for this case (0 clean, 4 reached the end with a safe stop,
    /// reflex, refused torque or an incomplete recording, 2/3 a daemon failed).
    pub exit_code: i32,
    /// Why, when not 0: the summary's last line without its `rig: exit N: ` prefix.
    pub status: String,
    pub misses: Option<u64>,
    pub safe_stops: Option<u64>,
    pub force_error_max_n: Option<f64>,
    pub force_error_rms_n: Option<f64>,
    pub bond_share: Option<f64>,
    pub bond_weakest_pa: Option<f64>,
    pub bond_weakest_z_m: Option<f64>,
}

/// `label` of a case: `section.field=value` joined by spaces.
pub fn label(axes: &[Axis], case: &[(usize, usize)]) -> String {
    case.iter().map(|&(a, v)| format!("{}.{}={}", axes[a].section, axes[a].field, axes[a].values[v])).collect::<Vec<_>>().join(" ")
}

/// The exit column: the status, and for a case that is not clean (4: a safe stop, reflex, refused
/// torque or incomplete recording; 2/3: a daemon failed) what happened.
fn exit_cell(r: &CaseResult) -> String {
    if r.exit_code == 0 || r.status.is_empty() {
        r.exit_code.to_string()
    } else {
        format!("{}: {}", r.exit_code, r.status.replace('|', "/"))
    }
}

/// `rig sweep`'s own exit status: 0 when every case is clean, 4 when every case reached its end
/// but some are not clean (exit 4), 1 when a case failed.
pub fn sweep_exit_code(results: &[CaseResult]) -> i32 {
    if results.iter().all(|r| r.exit_code == 0) {
        0
    } else if results.iter().all(|r| r.exit_code == 0 || r.exit_code == 4) {
        4
    } else {
        1
    }
}

/// The table `rig sweep` prints (markdown).
pub fn table(results: &[CaseResult]) -> String {
    let f = |v: Option<f64>, scale: f64, digits: usize| v.map_or("—".to_string(), |x| format!("{:.*}", digits, x * scale));
    let mut s = String::from("| case | exit | misses | force err max (N) | RMS (N) | bond ≥ 100 kPa | weakest under the wheel |\n| --- | --- | --- | --- | --- | --- | --- |\n");
    for r in results {
        let weakest = match (r.bond_weakest_pa, r.bond_weakest_z_m) {
            (Some(p), Some(z)) => format!("{:.1} kPa at z = {:.1} mm", p * 1e-3, z * 1e3),
            _ => "—".into(),
        };
        s += &format!(
            "| {} | {} | {} | {} | {} | {} % | {} |\n",
            r.label,
            exit_cell(r),
            r.misses.map_or("—".into(), |m| m.to_string()),
            f(r.force_error_max_n, 1.0, 3),
            f(r.force_error_rms_n, 1.0, 3),
            f(r.bond_share, 100.0, 1),
            weakest
        );
    }
    s
}

/// Reads a base scenario as a TOML table (validated as a scenario first, so errors name it).
pub fn load_base(path: &Path) -> anyhow::Result<toml::Table> {
    scenarios::Scenario::load(path)?;
    // Cases are written elsewhere: a contour's pieces file goes inline.
    let text = scenarios::pieces_file::self_contained(path)?;
    text.parse().with_context(|| format!("parsing {}", path.display()))
}

/// `rig run --set ...`: the base scenario with each axis' single value, written to `out` and
/// checked (errors name the written file and the field).
pub fn write_overridden(base_path: &Path, set: &[Axis], out: &Path) -> anyhow::Result<PathBuf> {
    for a in set {
        anyhow::ensure!(a.values.len() == 1, "--set {}.{}: rig run takes one value (rig sweep takes several)", a.section, a.field);
    }
    let base = load_base(base_path)?;
    let case: Vec<(usize, usize)> = (0..set.len()).map(|a| (a, 0)).collect();
    let mut doc = case_scenario(&base, set, &case);
    doc.insert("description".into(), format!("{} with {}", base_path.display(), label(set, &case)).into());
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("--out {}: creating the output directory", dir.display()))?;
    }
    std::fs::write(out, toml::to_string(&doc)?).with_context(|| format!("writing {}", out.display()))?;
    scenarios::Scenario::load(out).map_err(|e| blame_flags(e, &set_flags(set, &case)))?;
    Ok(out.to_path_buf())
}

/// The strips of a sweep's cases: each strip's contact tables loaded from the table cache (or
/// built from its model and cached) once, shared (`Arc`) by every case with the same strip and substep. The bump's height is
/// not part of it: a case scales the reference bump's offsets to its height
/// (`strip::StripParams::bulge_scale`), exactly as its daemon run does.
pub struct SharedStrips {
    cache_dir: PathBuf,
    tables: Mutex<Vec<(strip::StripParams, u64, Arc<plant_sim::contact::StripTables>)>>,
}

impl SharedStrips {
    pub fn new(cache_dir: &Path) -> SharedStrips {
        SharedStrips { cache_dir: cache_dir.to_path_buf(), tables: Mutex::new(Vec::new()) }
    }

    /// The plant's physics of `s`, its strip tables shared. Cases with the same strip wait for
    /// the first to build them instead of building them twice.
    pub fn physics(&self, s: &scenarios::Scenario) -> anyhow::Result<plant_sim::physics::Physics> {
        if !s.strip.enabled {
            return plant_sim::physics::Physics::with_strip_tables(s, None, &self.cache_dir);
        }
        let params = plant_sim::contact::strip_params(s).with_reference_bulge();
        let h = plant_sim::physics::substep_s(s);
        let tables = {
            let mut all = self.tables.lock().unwrap_or_else(|e| e.into_inner());
            match all.iter().find(|(p, hb, _)| *p == params && *hb == h.to_bits()) {
                Some((_, _, t)) => t.clone(),
                None => {
                    // From the table cache (a daemon run's too), else built and cached.
                    let t = plant_sim::physics::strip_tables(s, &self.cache_dir)?.context("the scenario's strip is enabled")?;
                    all.push((params, h.to_bits(), t.clone()));
                    t
                }
            }
        };
        plant_sim::physics::Physics::with_strip_tables(s, Some(tables), &self.cache_dir)
    }
}

/// Run `case` over `cases` on one thread per core (std::thread::scope, each thread taking the
/// next case until none is left); the results in the cases' order.
pub fn run_cases<C: Sync, R: Send>(cases: &[C], case: impl Fn(usize, &C) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(cases.len()).max(1);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Mutex<Vec<Option<R>>> = Mutex::new((0..cases.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let n = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(c) = cases.get(n) else { break };
                let r = case(n, c);
                results.lock().unwrap_or_else(|e| e.into_inner())[n] = Some(r);
            });
        }
    });
    results.into_inner().unwrap_or_else(|e| e.into_inner()).into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_rate_is_the_flags_else_the_bases_else_the_sweeps_and_never_an_axis() {
        let rate = |doc: &toml::Table| doc.get("recording").and_then(|r| r.get("scene_rate_hz")).and_then(toml::Value::as_float);
        let bare: toml::Table = "[bulge]\nheight_mm = 0.2\n".parse().unwrap();
        let own: toml::Table = "[recording]\nscene_rate_hz = 50.0\n".parse().unwrap();
        let height = [parse_axis("bulge.height_mm=0.1").unwrap()];
        for (base, flag, want, blamed) in [
            (&bare, None, SWEEP_SCENE_RATE_HZ, false),
            (&own, None, 50.0, false),
            (&bare, Some(4.0), 4.0, true),
            (&own, Some(4.0), 4.0, true),
        ] {
            let mut doc = base.clone();
            let blame = set_scene_rate(&mut doc, &height, flag);
            assert_eq!((rate(&doc), blame.is_some()), (Some(want), blamed), "base {base:?}, flag {flag:?}");
        }
        // An axis over the rate decides it for each case.
        let axis = [parse_axis("recording.scene_rate_hz=20").unwrap()];
        let mut doc = bare.clone();
        assert_eq!(set_scene_rate(&mut doc, &axis, Some(4.0)), None);
        assert_eq!(rate(&doc), None);
    }

    #[test]
    fn axes_parse_scalars_and_name_bad_input() {
        let a = parse_axis("bulge.height_mm=0.1,0.4").unwrap();
        assert_eq!((a.section.as_str(), a.field.as_str()), ("bulge", "height_mm"));
        assert_eq!(a.values, vec![toml::Value::Float(0.1), toml::Value::Float(0.4)]);
        let b = parse_axis("controller.force_integral=true,false").unwrap();
        assert_eq!(b.values, vec![toml::Value::Boolean(true), toml::Value::Boolean(false)]);
        let c = parse_axis("strip.boundary=bonded,\"sliding\"").unwrap();
        assert_eq!(c.values, vec![toml::Value::String("bonded".into()), toml::Value::String("sliding".into())]);
        for bad in ["height_mm=1", "bulge.height_mm", "bulge.height_mm=1,,2", ".x=1"] {
            let e = parse_axis(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn set_names_only_scenario_fields() {
        assert_eq!(parse_set("bulge.height_mm=0.1").unwrap(), parse_axis("bulge.height_mm=0.1").unwrap());
        let e = parse_set("bulge.heigth_mm=1").unwrap_err().to_string();
        assert!(
            e.contains("--set \"bulge.heigth_mm=1\": no scenario field bulge.heigth_mm; [bulge] has height_mm, half_width_mm, center_mm"),
            "{e}"
        );
        let e = parse_set("loops.period_s=1").unwrap_err().to_string();
        assert!(e.contains("no scenario section [loops]; the sections are [loop],"), "{e}");
        // the syntax errors of parse_axis stay
        assert!(parse_set("bulge.height_mm").is_err());
    }

    #[test]
    fn one_at_a_time_and_grid_counts() {
        let axes = vec![parse_axis("a.x=1,2,3").unwrap(), parse_axis("b.y=4,5").unwrap()];
        assert_eq!(cases(&axes, false).len(), 3 + 2);
        let g = cases(&axes, true);
        assert_eq!(g.len(), 3 * 2);
        assert!(g.iter().all(|c| c.len() == 2 && c[0].0 == 0 && c[1].0 == 1));
        let mut seen: Vec<_> = g.iter().map(|c| (c[0].1, c[1].1)).collect();
        seen.dedup();
        assert_eq!(seen.len(), 6, "every combination once");
    }

    #[test]
    fn a_case_overrides_only_its_fields() {
        let base: toml::Table = "[bulge]\nheight_mm = 0.2\ncenter_mm = 20\n[loop]\nmode = \"realtime\"\n".parse().unwrap();
        let axes = vec![parse_axis("bulge.height_mm=0.4").unwrap(), parse_axis("trajectory.roll_s=1").unwrap()];
        let doc = case_scenario(&base, &axes, &[(0, 0), (1, 0)]);
        assert_eq!(doc["bulge"]["height_mm"].as_float(), Some(0.4));
        assert_eq!(doc["bulge"]["center_mm"].as_integer(), Some(20));
        assert_eq!(doc["trajectory"]["roll_s"].as_integer(), Some(1));
        assert_eq!(doc["loop"]["mode"].as_str(), Some("realtime"));
        assert_eq!(label(&axes, &[(0, 0), (1, 0)]), "bulge.height_mm=0.4 trajectory.roll_s=1");
    }

    fn result(label: &str, exit_code: i32, status: &str) -> CaseResult {
        CaseResult {
            label: label.into(),
            scenario: PathBuf::new(),
            recording: None,
            exit_code,
            status: status.into(),
            misses: Some(0),
            safe_stops: Some(0),
            force_error_max_n: None,
            force_error_rms_n: None,
            bond_share: None,
            bond_weakest_pa: None,
            bond_weakest_z_m: None,
        }
    }

    #[test]
    fn a_case_with_exit_4_says_so_in_the_table_and_in_the_sweep_status() {
        let clean = result("a.x=1", 0, "reached the end; no safe stop, reflex or refused torque; recording complete");
        let stopped = result("a.x=2", 4, "1 reflex (first at tick 512), 1 safe stop (first at tick 512)");
        let t = table(&[clean.clone(), stopped.clone()]);
        assert!(t.contains("| a.x=1 | 0 | 0 |"), "{t}");
        assert!(t.contains("| a.x=2 | 4: 1 reflex (first at tick 512), 1 safe stop (first at tick 512) | 0 |"), "{t}");
        assert_eq!(sweep_exit_code(std::slice::from_ref(&clean)), 0);
        assert_eq!(sweep_exit_code(&[clean.clone(), stopped.clone()]), 4);
        assert_eq!(sweep_exit_code(&[stopped, result("a.x=3", 3, "controller failed: x")]), 1);
    }

    #[test]
    fn rig_run_overrides_are_written_and_checked() {
        let base = scenarios::Scenario::default_file();
        let dir = std::env::temp_dir().join(format!("rig-run-set-{}", std::process::id()));
        let out = dir.join("scenario.toml");
        let set = vec![parse_axis("trajectory.force_ref_n=-12.5").unwrap(), parse_axis("controller.force_integral=false").unwrap()];
        let p = write_overridden(&base, &set, &out).unwrap();
        let s = scenarios::Scenario::load(&p).unwrap();
        assert_eq!((s.trajectory.force_ref_n, s.controller.force_integral), (-12.5, false));
        // everything else is the base scenario's
        let b = scenarios::Scenario::load(&base).unwrap();
        assert_eq!((s.bulge, s.loop_.substeps, s.trajectory.roll_s), (b.bulge, b.loop_.substeps, b.trajectory.roll_s));
        let e = write_overridden(&base, &[parse_axis("bulge.height_mm=0.1,0.2").unwrap()], &out).unwrap_err().to_string();
        assert!(e.contains("bulge.height_mm") && e.contains("one value"), "{e}");
        let e = format!("{:#}", write_overridden(&base, &[parse_axis("trajectory.roll_s=-1").unwrap()], &out).unwrap_err());
        let at = format!("--set trajectory.roll_s=-1: scenario file {}, line ", out.display());
        assert!(e.starts_with(&at) && e.contains(": field trajectory.roll_s = -1: must be in (0, ∞) s"), "{e}");
        // a field the override made invalid: blamed on the overrides
        let e = format!("{:#}", write_overridden(&base, &[parse_axis("strip.length_mm=20").unwrap()], &out).unwrap_err());
        assert!(
            e.starts_with("the scenario with --set strip.length_mm=20: scenario file ") && e.contains("field trajectory.z_end_mm = 38"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
