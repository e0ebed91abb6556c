//! The run's description: what the plant hands the recorder and the writer puts in the MCAP
//! metadata record `rig` at the start, and what the tools read back from it. MCAP metadata is a
//! map of strings; this is its one typed form, so writer and reader agree on every key.
//!
//! Reading: a required key that is missing is an error naming it, never a default. A key that is
//! absent on purpose is an `Option` here: the scenario (not in synthetic recordings), the
//! transport (only an in-process run names one), the EGM servo lag (only EGM runs, which then
//! have `/egm`), the centre line (only with a single-model strip). Numbers are written so that
//! they read back to the same `f64` (shortest round-trip form; the centre line as a JSON array).
//!
//! The writer adds its own keys to the record (`start_wall_ns`, `created_wall_ns`,
//! `recording_format`, `contract_version`); they are not part of the run's description.

use std::collections::BTreeMap;

use scenarios::{Integrator, Mode};

/// Name of the MCAP metadata record that holds the run's description.
pub const RECORD_NAME: &str = "rig";

/// The metadata key of an EGM run (its value: the motion controller's lag, s); with it the
/// recording has the `/egm` channel.
pub const EGM_METADATA_KEY: &str = "egm_servo_lag_s";

/// Key of the centre-line nodes' z (a JSON array, m).
pub const CENTRELINE_Z_KEY: &str = "centreline_z_m";

/// The run as its recording describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct RunMetadata {
    /// The rig's name.
    pub rig: String,
    pub mode: Mode,
    /// The scenario the run was made from; None: not from a scenario (a synthetic recording).
    pub scenario: Option<ScenarioSource>,
    /// Control period T, s.
    pub period_s: f64,
    /// Plant substeps per period.
    pub substeps: u32,
    pub integrator: Integrator,
    /// `in-process` for a run without daemons; None: the plant's own (iceoryx2 or EGM).
    pub transport: Option<String>,
    /// An EGM run (the plant acting as the ABB controller); None: a torque run.
    pub egm: Option<EgmRun>,
    /// z of the centre-line bottom nodes in the order of the recorded pressures, m (also in every
    /// `/strip` message); None: no single-model strip.
    pub centreline_z_m: Option<Vec<f64>>,
}

/// The scenario file of a run, as read when the run started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScenarioSource {
    /// Its path as given to the plant.
    pub path: String,
    /// Its whole text.
    pub toml: String,
}

/// What an EGM run records about its motion controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgmRun {
    /// The motion controller's lag from reference to joints, s.
    pub servo_lag_s: f64,
}

/// Metadata that does not read as a [`RunMetadata`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetadataError {
    #[error("the recording has no `{RECORD_NAME}` metadata record (not written by this rig?)")]
    NoRecord,
    #[error("the recording's `{RECORD_NAME}` metadata has no `{key}`")]
    Missing { key: &'static str },
    #[error("the recording's `{RECORD_NAME}` metadata `{key}` = {value:?} does not read: {why}")]
    Invalid { key: &'static str, value: String, why: String },
}

impl RunMetadata {
    /// The record's entries, key to value, in key order.
    pub fn to_entries(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        let mut put = |k: &str, v: String| m.insert(k.to_string(), v);
        put("rig", self.rig.clone());
        put("mode", self.mode.name().to_string());
        if let Some(s) = &self.scenario {
            put("scenario_path", s.path.clone());
            put("scenario_toml", s.toml.clone());
        }
        // `Display` of an f64 is its shortest form that reads back to the same value.
        put("period_s", self.period_s.to_string());
        put("substeps", self.substeps.to_string());
        put("integrator", self.integrator.name().to_string());
        if let Some(t) = &self.transport {
            put("transport", t.clone());
        }
        if let Some(e) = &self.egm {
            put(EGM_METADATA_KEY, e.servo_lag_s.to_string());
        }
        if let Some(z) = &self.centreline_z_m {
            put(CENTRELINE_Z_KEY, serde_json::to_string(z).expect("a list of numbers serialises"));
        }
        m
    }

    /// Reads the record's entries; a missing required key or a value that does not read is an
    /// error naming the key. Keys it does not know (the writer's own) are left alone.
    pub fn from_entries(m: &BTreeMap<String, String>) -> Result<Self, MetadataError> {
        let get = |key: &'static str| m.get(key).map(String::as_str);
        let need = |key: &'static str| get(key).ok_or(MetadataError::Missing { key });
        let invalid = |key: &'static str, value: &str, why: String| MetadataError::Invalid { key, value: value.to_string(), why };
        let num = |key: &'static str, v: &str| v.parse::<f64>().map_err(|e| invalid(key, v, e.to_string()));
        let mode = need("mode")?;
        let mode = mode.parse::<Mode>().map_err(|e| invalid("mode", mode, e))?;
        let scenario = match (get("scenario_path"), get("scenario_toml")) {
            (Some(path), Some(toml)) => Some(ScenarioSource { path: path.to_string(), toml: toml.to_string() }),
            (None, None) => None,
            (Some(_), None) => return Err(MetadataError::Missing { key: "scenario_toml" }),
            (None, Some(_)) => return Err(MetadataError::Missing { key: "scenario_path" }),
        };
        let substeps = need("substeps")?;
        let substeps = substeps.parse::<u32>().map_err(|e| invalid("substeps", substeps, e.to_string()))?;
        let integrator = need("integrator")?;
        let integrator = [Integrator::Midpoint, Integrator::Rk4]
            .into_iter()
            .find(|i| i.name() == integrator)
            .ok_or_else(|| invalid("integrator", integrator, "expected midpoint or rk4".into()))?;
        let egm = match get(EGM_METADATA_KEY) {
            Some(v) => Some(EgmRun { servo_lag_s: num(EGM_METADATA_KEY, v)? }),
            None => None,
        };
        let centreline_z_m = match get(CENTRELINE_Z_KEY) {
            Some(v) => Some(crate::schema::parse_f64_list(v).map_err(|e| invalid(CENTRELINE_Z_KEY, v, e))?),
            None => None,
        };
        Ok(RunMetadata {
            rig: need("rig")?.to_string(),
            mode,
            scenario,
            period_s: num("period_s", need("period_s")?)?,
            substeps,
            integrator,
            transport: get("transport").map(str::to_string),
            egm,
            centreline_z_m,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> RunMetadata {
        RunMetadata {
            rig: "r".into(),
            mode: Mode::Lockstep,
            scenario: Some(ScenarioSource { path: "s.toml".into(), toml: "[loop]\nperiod_s = 0.001\n".into() }),
            period_s: 0.001,
            substeps: 4,
            integrator: Integrator::Rk4,
            transport: Some("in-process".into()),
            egm: Some(EgmRun { servo_lag_s: 0.1 + 0.2 }),
            centreline_z_m: Some(vec![-0.02, 1.0 / 3.0, 1e-7, 0.0]),
        }
    }

    #[test]
    fn metadata_reads_back_bit_for_bit() {
        let m = example();
        let back = RunMetadata::from_entries(&m.to_entries()).unwrap();
        assert_eq!(back, m);
        assert_eq!(back.egm.unwrap().servo_lag_s.to_bits(), (0.1f64 + 0.2).to_bits());
        let torque = RunMetadata { scenario: None, transport: None, egm: None, centreline_z_m: None, ..example() };
        let entries = torque.to_entries();
        assert!(!entries.contains_key(EGM_METADATA_KEY) && !entries.contains_key("transport"), "{entries:?}");
        assert_eq!(RunMetadata::from_entries(&entries).unwrap(), torque);
    }

    #[test]
    fn the_centre_line_is_a_json_array() {
        let z = &example().to_entries()[CENTRELINE_Z_KEY];
        let parsed: Vec<f64> = serde_json::from_str(z).unwrap();
        assert_eq!(parsed, example().centreline_z_m.unwrap());
    }

    #[test]
    fn a_missing_or_unreadable_key_is_named() {
        for key in ["rig", "mode", "period_s", "substeps", "integrator", "scenario_toml"] {
            let mut e = example().to_entries();
            e.remove(key);
            assert_eq!(RunMetadata::from_entries(&e), Err(MetadataError::Missing { key }), "{key}");
        }
        let mut e = example().to_entries();
        e.insert("period_s".into(), "1 ms".into());
        let err = RunMetadata::from_entries(&e).unwrap_err().to_string();
        assert!(err.contains("`period_s` = \"1 ms\" does not read"), "{err}");
    }
}
