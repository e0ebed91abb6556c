//! The study file (TOML): the base scenario, the uncertain parameters with their distributions,
//! the realism seeds that vary, the number of cases and the sampling, the pass criteria. Checked
//! whole before anything runs; every refusal names the file, the line and the field.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::stats;

/// A study as its file gives it, checked.
#[derive(Debug, Clone)]
pub struct Study {
    /// The study file itself.
    pub path: PathBuf,
    /// Its text (copied into the study directory, so the directory alone defines the study).
    pub text: String,
    pub description: String,
    /// The base scenario (relative paths in the file are relative to the study file).
    pub base: PathBuf,
    pub cases: usize,
    pub seed: u64,
    pub sampling: Sampling,
    /// Which recordings to keep (the CLI may override).
    pub recordings: Keep,
    pub parameters: Vec<Parameter>,
    /// Integer scenario fields (the realism models' seeds) given a different value per case.
    pub vary_seeds: Vec<String>,
    pub criteria: Vec<Criterion>,
}

/// How the cases' points in the parameter space are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampling {
    /// Independent uniform draws per case and parameter.
    Random,
    /// Latin hypercube: each parameter's range cut into `cases` strata of equal probability, one
    /// case per stratum, strata paired at random between parameters.
    LatinHypercube,
}

/// Which case recordings a study keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Keep {
    None,
    /// The recordings of failing cases only (the default: 10^4 cases must not keep 10^4 files).
    Failing,
    All,
}

/// One uncertain scenario field.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// `section.field` of the scenario.
    pub field: String,
    pub distribution: Distribution,
    /// The field is a whole number in the scenario (values are rounded).
    pub integer: bool,
}

/// A parameter's distribution; `sample(u)` maps a uniform `u` in [0, 1) to a value (inverse CDF),
/// which is what lets Latin hypercube sampling stratify any of them.
#[derive(Debug, Clone, PartialEq)]
pub enum Distribution {
    Uniform {
        min: f64,
        max: f64,
    },
    /// A normal truncated to [min, max].
    Normal {
        mean: f64,
        sd: f64,
        min: f64,
        max: f64,
    },
    /// exp of a normal: `median` = exp(mu), `sigma` of ln x; truncated to [min, max].
    LogNormal {
        median: f64,
        sigma: f64,
        min: f64,
        max: f64,
    },
    /// One of the values, each equally likely.
    Values(Vec<f64>),
}

impl Distribution {
    /// The value at quantile `u` (0 <= u < 1).
    pub fn sample(&self, u: f64) -> f64 {
        match self {
            Distribution::Uniform { min, max } => min + u * (max - min),
            Distribution::Normal { mean, sd, min, max } => {
                let (a, b) = (stats::normal_cdf((min - mean) / sd), stats::normal_cdf((max - mean) / sd));
                (mean + sd * stats::normal_quantile(a + u * (b - a))).clamp(*min, *max)
            }
            Distribution::LogNormal { median, sigma, min, max } => {
                let mu = median.ln();
                let (a, b) = (stats::normal_cdf((min.ln() - mu) / sigma), stats::normal_cdf((max.ln() - mu) / sigma));
                (mu + sigma * stats::normal_quantile(a + u * (b - a))).exp().clamp(*min, *max)
            }
            Distribution::Values(v) => v[((u * v.len() as f64) as usize).min(v.len() - 1)],
        }
    }
}

/// The metrics a criterion (and the summary) can name: each case's result has them all.
pub const METRICS: &[(&str, &str)] = &[
    ("exit_code", "the case's `rig run` exit status (0 clean, 4 a safe stop, reflex or refused torque)"),
    ("misses", "ticks whose torque was late, missing or refused"),
    ("safe_stops", "entries into the safe stop (a reflex counts)"),
    ("force_error_max_n", "max |true bottom force - set-point| while rolling, N"),
    ("force_error_rms_n", "RMS of the true bottom force error while rolling, N"),
    ("bond_share", "share (0..1) of the rolled length where the bottom pressure reached the bond pressure"),
    ("bond_weakest_pa", "weakest centre-line bottom pressure under the wheel while rolling, Pa"),
];

/// A pass criterion: the case's `metric` within [min, max] (either may be absent).
#[derive(Debug, Clone, PartialEq)]
pub struct Criterion {
    pub metric: String,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

impl Criterion {
    pub fn holds(&self, x: Option<f64>) -> bool {
        x.is_some_and(|x| x.is_finite() && self.min.is_none_or(|m| x >= m) && self.max.is_none_or(|m| x <= m))
    }

    /// `force_error_max_n <= 0.45`, `0.9 <= bond_share`, ...
    pub fn text(&self) -> String {
        match (self.min, self.max) {
            (Some(lo), Some(hi)) => format!("{lo} <= {} <= {hi}", self.metric),
            (Some(lo), None) => format!("{} >= {lo}", self.metric),
            (None, Some(hi)) => format!("{} <= {hi}", self.metric),
            (None, None) => self.metric.clone(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStudy {
    description: Option<String>,
    base: Spanned<String>,
    cases: Spanned<i64>,
    seed: Option<Spanned<i64>>,
    sampling: Option<Spanned<String>>,
    recordings: Option<Spanned<String>>,
    #[serde(default)]
    vary_seeds: Vec<Spanned<String>>,
    #[serde(default)]
    parameter: Vec<Spanned<RawParameter>>,
    #[serde(default)]
    criterion: Vec<Spanned<RawCriterion>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParameter {
    field: Spanned<String>,
    distribution: Spanned<String>,
    min: Option<Spanned<f64>>,
    max: Option<Spanned<f64>>,
    mean: Option<Spanned<f64>>,
    sd: Option<Spanned<f64>>,
    median: Option<Spanned<f64>>,
    sigma: Option<Spanned<f64>>,
    values: Option<Spanned<Vec<f64>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCriterion {
    metric: Spanned<String>,
    min: Option<Spanned<f64>>,
    max: Option<Spanned<f64>>,
}

/// A study file's refusal: file, line, field and why.
#[derive(Debug, thiserror::Error)]
#[error("study file {}, line {line}: {field}: {why}", path.display())]
pub struct StudyError {
    pub path: PathBuf,
    pub line: usize,
    pub field: String,
    pub why: String,
}

/// Distributions and the fields each needs.
const DISTRIBUTIONS: &[(&str, &[&str])] = &[
    ("uniform", &["min", "max"]),
    ("normal", &["mean", "sd", "min", "max"]),
    ("lognormal", &["median", "sigma", "min", "max"]),
    ("values", &["values"]),
];

impl Study {
    /// Reads and checks a study file (and that its base scenario loads).
    pub fn load(path: &Path) -> anyhow::Result<Study> {
        let text = std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("cannot read study file {}: {e}", path.display()))?;
        Ok(Study::parse(path, &text)?)
    }

    pub fn parse(path: &Path, text: &str) -> Result<Study, StudyError> {
        let line = |span: std::ops::Range<usize>| text[..span.start.min(text.len())].matches('\n').count() + 1;
        let err = |span: std::ops::Range<usize>, field: &str, why: String| StudyError {
            path: path.into(),
            line: line(span),
            field: field.into(),
            why,
        };
        let raw: RawStudy = toml::from_str(text).map_err(|e| {
            let span = e.span().unwrap_or(0..0);
            let at = text.get(span.clone()).map(str::trim).filter(|t| !t.is_empty() && t.len() <= 40 && !t.contains('\n'));
            let field = at.map_or("file".to_string(), |t| format!("`{t}`"));
            err(span, &field, e.message().trim().to_string())
        })?;
        let base_text = raw.base.get_ref();
        let base = path.parent().unwrap_or(Path::new(".")).join(base_text);
        if let Err(e) = scenarios::Scenario::load(&base) {
            return Err(err(raw.base.span(), "base", format!("{base_text}: {e}")));
        }
        let cases = *raw.cases.get_ref();
        if !(1..=10_000_000).contains(&cases) {
            return Err(err(raw.cases.span(), "cases", format!("{cases}: must be at least 1 (and at most 10^7)")));
        }
        let seed = raw
            .seed
            .as_ref()
            .map_or(Ok(1), |s| u64::try_from(*s.get_ref()).map_err(|_| err(s.span(), "seed", format!("{}: must be >= 0", s.get_ref()))))?;
        let sampling = match raw.sampling.as_ref().map(|s| (s.get_ref().as_str(), s.span())) {
            None | Some(("latin-hypercube", _)) => Sampling::LatinHypercube,
            Some(("random", _)) => Sampling::Random,
            Some((other, span)) => return Err(err(span, "sampling", format!("{other:?}: must be \"random\" or \"latin-hypercube\""))),
        };
        let recordings = match raw.recordings.as_ref().map(|s| (s.get_ref().as_str(), s.span())) {
            None | Some(("failing", _)) => Keep::Failing,
            Some(("none", _)) => Keep::None,
            Some(("all", _)) => Keep::All,
            Some((other, span)) => return Err(err(span, "recordings", format!("{other:?}: must be \"none\", \"failing\" or \"all\""))),
        };
        let mut parameters = Vec::new();
        for (i, p) in raw.parameter.iter().enumerate() {
            let here = format!("parameter[{i}]");
            let p_span = p.span();
            let p = p.get_ref();
            let key = p.field.get_ref();
            let f = scenarios::fields::field(key)
                .ok_or_else(|| err(p.field.span(), &format!("{here}.field"), format!("{key:?}: no such scenario field")))?;
            let integer = match f.kind {
                scenarios::fields::Kind::Float => false,
                scenarios::fields::Kind::Int => true,
                _ => {
                    return Err(err(
                        p.field.span(),
                        &format!("{here}.field"),
                        format!("{key}: not a number field; only numbers can be uncertain"),
                    ))
                }
            };
            if parameters.iter().any(|q: &Parameter| q.field == *key) {
                return Err(err(p.field.span(), &format!("{here}.field"), format!("{key} is already a parameter")));
            }
            let dist = p.distribution.get_ref().as_str();
            let Some((_, needs)) = DISTRIBUTIONS.iter().find(|(d, _)| *d == dist) else {
                let names: Vec<_> = DISTRIBUTIONS.iter().map(|(d, _)| *d).collect();
                return Err(err(
                    p.distribution.span(),
                    &format!("{here}.distribution"),
                    format!("{dist:?}: must be one of {}", names.join(", ")),
                ));
            };
            let given: [(&str, Option<std::ops::Range<usize>>); 7] = [
                ("min", p.min.as_ref().map(Spanned::span)),
                ("max", p.max.as_ref().map(Spanned::span)),
                ("mean", p.mean.as_ref().map(Spanned::span)),
                ("sd", p.sd.as_ref().map(Spanned::span)),
                ("median", p.median.as_ref().map(Spanned::span)),
                ("sigma", p.sigma.as_ref().map(Spanned::span)),
                ("values", p.values.as_ref().map(Spanned::span)),
            ];
            for (name, span) in &given {
                match (needs.contains(name), span) {
                    (false, Some(span)) => {
                        return Err(err(
                            span.clone(),
                            &format!("{here}.{name}"),
                            format!("a {dist} distribution has no {name} (it takes {})", needs.join(", ")),
                        ))
                    }
                    (true, None) => return Err(err(p_span.clone(), &here, format!("a {dist} distribution needs {}", needs.join(", ")))),
                    _ => {}
                }
            }
            let num = |s: &Option<Spanned<f64>>| s.as_ref().map_or(f64::NAN, |s| *s.get_ref());
            let bad = |name: &str, why: String| {
                let span = given.iter().find(|(n, _)| *n == name).and_then(|(_, s)| s.clone()).unwrap_or(p_span.clone());
                err(span, &format!("{here}.{name}"), why)
            };
            for (name, s) in
                [("min", &p.min), ("max", &p.max), ("mean", &p.mean), ("sd", &p.sd), ("median", &p.median), ("sigma", &p.sigma)]
            {
                if s.as_ref().is_some_and(|s| !s.get_ref().is_finite()) {
                    return Err(bad(name, "must be a finite number".into()));
                }
            }
            let (min, max) = (num(&p.min), num(&p.max));
            if needs.contains(&"min") && min >= max {
                return Err(bad("max", format!("{max}: must be greater than min = {min}")));
            }
            let distribution = match dist {
                "uniform" => Distribution::Uniform { min, max },
                "normal" => {
                    let (mean, sd) = (num(&p.mean), num(&p.sd));
                    if sd <= 0.0 {
                        return Err(bad("sd", format!("{sd}: must be > 0")));
                    }
                    if !(min..=max).contains(&mean) {
                        return Err(bad("mean", format!("{mean}: must lie within [min, max] = [{min}, {max}]")));
                    }
                    Distribution::Normal { mean, sd, min, max }
                }
                "lognormal" => {
                    let (median, sigma) = (num(&p.median), num(&p.sigma));
                    if median <= 0.0 || sigma <= 0.0 || min <= 0.0 {
                        return Err(bad(
                            if median <= 0.0 {
                                "median"
                            } else if sigma <= 0.0 {
                                "sigma"
                            } else {
                                "min"
                            },
                            "must be > 0 for a log-normal".into(),
                        ));
                    }
                    Distribution::LogNormal { median, sigma, min, max }
                }
                _ => {
                    let v = p.values.as_ref().map(|v| v.get_ref().clone()).unwrap_or_default();
                    if v.is_empty() || v.iter().any(|x| !x.is_finite()) {
                        return Err(bad("values", "must be a non-empty list of finite numbers".into()));
                    }
                    Distribution::Values(v)
                }
            };
            parameters.push(Parameter { field: key.clone(), distribution, integer });
        }
        let mut vary_seeds = Vec::new();
        for (i, s) in raw.vary_seeds.iter().enumerate() {
            let key = s.get_ref();
            match scenarios::fields::field(key).map(|f| f.kind) {
                Some(scenarios::fields::Kind::Int) if key.ends_with("seed") => vary_seeds.push(key.clone()),
                _ => {
                    return Err(err(
                        s.span(),
                        &format!("vary_seeds[{i}]"),
                        format!("{key:?}: not a seed field of the scenario (an integer field named ...seed)"),
                    ))
                }
            }
        }
        let mut criteria = Vec::new();
        for (i, c) in raw.criterion.iter().enumerate() {
            let here = format!("criterion[{i}]");
            let (c_span, c) = (c.span(), c.get_ref());
            let metric = c.metric.get_ref();
            if !METRICS.iter().any(|(m, _)| m == metric) {
                let names: Vec<_> = METRICS.iter().map(|(m, _)| *m).collect();
                return Err(err(
                    c.metric.span(),
                    &format!("{here}.metric"),
                    format!("{metric:?}: no such metric; the metrics are {}", names.join(", ")),
                ));
            }
            let (min, max) = (c.min.as_ref().map(|s| *s.get_ref()), c.max.as_ref().map(|s| *s.get_ref()));
            if min.is_none() && max.is_none() {
                return Err(err(c_span, &here, "needs min, max or both".into()));
            }
            if let (Some(lo), Some(hi)) = (min, max) {
                if lo > hi {
                    return Err(err(
                        c.max.as_ref().map_or(c_span, Spanned::span),
                        &format!("{here}.max"),
                        format!("{hi}: below min = {lo}"),
                    ));
                }
            }
            criteria.push(Criterion { metric: metric.clone(), min, max });
        }
        Ok(Study {
            path: path.to_path_buf(),
            text: text.to_string(),
            description: raw.description.unwrap_or_default(),
            base,
            cases: cases as usize,
            seed,
            sampling,
            recordings,
            parameters,
            vary_seeds,
            criteria,
        })
    }

    /// Every case's parameter values (`[case][parameter]`), from the seed alone: the same file
    /// gives the same cases on every machine and in every Slurm task.
    pub fn points(&self) -> Vec<Vec<f64>> {
        let u = stats::unit_samples(self.seed, self.cases, self.parameters.len(), self.sampling == Sampling::LatinHypercube);
        u.iter()
            .map(|row| {
                row.iter()
                    .zip(&self.parameters)
                    .map(|(&u, p)| {
                        let x = p.distribution.sample(u);
                        if p.integer {
                            x.round()
                        } else {
                            x
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Case `n`'s seed of the realism field `key`: a hash of the study seed, the field and the case.
    pub fn case_seed(&self, key: &str, n: usize) -> i64 {
        let h = key.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
        (stats::splitmix64(self.seed ^ h ^ (n as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)) >> 33) as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> String {
        format!("base = {:?}\n", scenarios::Scenario::default_file().display().to_string())
    }

    fn parse(body: &str) -> Result<Study, StudyError> {
        Study::parse(Path::new("/tmp/s.toml"), &(base() + body))
    }

    #[test]
    fn bad_study_files_name_line_and_field() {
        for (body, line, field, why) in [
            ("cases = 0\n", 2, "cases", "must be at least 1"),
            ("cases = 5\n[[parameter]]\nfield = \"bulge.heigth_mm\"\ndistribution = \"uniform\"\nmin = 0.1\nmax = 0.4\n", 4, "parameter[0].field", "no such scenario field"),
            ("cases = 5\n[[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"uniform\"\nmin = 0.4\nmax = 0.1\n", 7, "parameter[0].max", "must be greater than min"),
            ("cases = 5\n[[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"normal\"\nmean = 0.2\nsd = -1\nmin = 0.1\nmax = 0.4\n", 7, "parameter[0].sd", "must be > 0"),
            ("cases = 5\n[[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"uniform\"\nmin = 0.1\nmax = 0.4\nsd = 1\n", 8, "parameter[0].sd", "has no sd"),
            ("cases = 5\n[[criterion]]\nmetric = \"force_error_p99_n\"\nmax = 1\n", 4, "criterion[0].metric", "no such metric"),
            ("cases = 5\nsampling = \"sobol\"\n", 3, "sampling", "must be \"random\""),
            ("cases = 5\nbogus = 1\n", 3, "`bogus`", "unknown field"),
        ] {
            let e = parse(body).unwrap_err();
            assert_eq!((e.line, e.field.as_str()), (line, field), "{body}: {e}");
            assert!(e.why.contains(why) && e.to_string().starts_with("study file /tmp/s.toml, line "), "{body}: {e}");
        }
    }

    #[test]
    fn the_shipped_studies_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../studies");
        for name in ["default_mc.toml", "cell_mc.toml"] {
            let s = Study::load(&dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e:#}"));
            assert_eq!(s.points().len(), s.cases, "{name}");
        }
    }

    #[test]
    fn points_follow_the_distributions_and_the_seed() {
        let body = "cases = 400\nseed = 3\n[[parameter]]\nfield = \"bulge.height_mm\"\ndistribution = \"uniform\"\nmin = 0.1\nmax = 0.4\n\
                    [[parameter]]\nfield = \"robot.tool_mass_kg\"\ndistribution = \"normal\"\nmean = 2.0\nsd = 0.1\nmin = 1.8\nmax = 2.2\n\
                    [[parameter]]\nfield = \"strip.youngs_modulus_pa\"\ndistribution = \"values\"\nvalues = [1.0, 2.0]\n";
        let s = parse(body).unwrap();
        let p = s.points();
        assert_eq!(p, parse(body).unwrap().points(), "same seed, same cases");
        assert_eq!(p.len(), 400);
        // Latin hypercube: exactly one case in each of the 400 strata of the uniform parameter
        let mut strata: Vec<usize> = p.iter().map(|c| ((c[0] - 0.1) / 0.3 * 400.0) as usize).collect();
        strata.sort();
        assert_eq!(strata, (0..400).collect::<Vec<_>>());
        // the normal truncated at ±2 sd: within its bounds, mean 2 by symmetry, and the truncated
        // sd's closed form 0.1 sqrt(1 - 4 φ(2) / (Φ(2) - Φ(-2))) = 0.0879625
        let m: Vec<f64> = p.iter().map(|c| c[1]).collect();
        let mean = m.iter().sum::<f64>() / 400.0;
        let sd = (m.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 399.0).sqrt();
        assert!(m.iter().all(|x| (1.8..=2.2).contains(x)) && (mean - 2.0).abs() < 1e-3 && (sd - 0.0879625).abs() < 1e-3, "{mean} {sd}");
        assert_eq!(p.iter().filter(|c| c[2] == 1.0).count(), 200, "each listed value equally often");
        let other = parse(&body.replace("seed = 3", "seed = 4")).unwrap().points();
        assert_ne!(p, other);
    }
}
