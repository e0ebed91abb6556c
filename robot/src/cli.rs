//! `rig robot ...`: command-line checks of the model against the user's own tools.
//!
//! `rig robot dynamics --input IN.json --output OUT.json` evaluates the bare arm (no tool, no
//! armature, no friction) at each state of IN.json, `{"states": [{"name", "q", "qd", "qdd",
//! "tau_fd"}, ...]}`, and writes the same states with `flange_position`, `flange_rotation`,
//! `jacobian` (flange origin, base axes, rows v then w), `mass_matrix`, `gravity`, `coriolis`
//! (`C(q, qd) qd`), `tau` (RNEA at `qdd`) and `qdd_fd` (forward dynamics at `tau_fd`) added.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::{json, Map, Value};

use crate::{Mat6, Robot, Vec6};

/// Subcommands of `rig robot`.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Evaluate kinematics and dynamics of the bare arm (no tool, armature or friction) at the
    /// states of a JSON file and write them back with the results added.
    Dynamics {
        /// JSON file `{"states": [{"name": s, "q": [6], "qd": [6], "qdd": [6], "tau_fd": [6]}, ...]}`.
        #[arg(long)]
        input: PathBuf,
        /// JSON file to write: the input states with the model's outputs added.
        #[arg(long)]
        output: PathBuf,
    },
}

/// A malformed input file, naming the state and field at fault.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum InputError {
    #[error("top level: expected an object with a \"states\" array")]
    NoStates,
    #[error("state {state}: expected a JSON object")]
    NotAnObject { state: String },
    #[error("state {state}: field \"{field}\" is missing")]
    MissingField { state: String, field: &'static str },
    #[error("state {state}: field \"{field}\" must be {expected}, got {got}")]
    BadField { state: String, field: &'static str, expected: &'static str, got: String },
}

/// One evaluated state's inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct StateIn {
    pub name: String,
    pub q: Vec6,
    pub qd: Vec6,
    pub qdd: Vec6,
    pub tau_fd: Vec6,
}

/// Run one `rig robot` subcommand.
pub fn run(cmd: Command) -> anyhow::Result<()> {
    match cmd {
        Command::Dynamics { input, output } => dynamics_file(&input, &output),
    }
}

fn dynamics_file(input: &Path, output: &Path) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(input).with_context(|| format!("reading {}", input.display()))?;
    let doc: Value = serde_json::from_str(&text).with_context(|| format!("parsing {} as JSON", input.display()))?;
    let out = dynamics_json(&doc).with_context(|| format!("in {}", input.display()))?;
    let text = serde_json::to_string_pretty(&out)?;
    std::fs::write(output, text + "\n").with_context(|| format!("writing {}", output.display()))?;
    Ok(())
}

/// Evaluate a parsed IN.json document; returns the OUT.json document.
pub fn dynamics_json(doc: &Value) -> Result<Value, InputError> {
    let states = doc.get("states").and_then(Value::as_array).ok_or(InputError::NoStates)?;
    let robot = Robot::irb2400();
    let mut out = Vec::with_capacity(states.len());
    for (index, state) in states.iter().enumerate() {
        let parsed = parse_state(index, state)?;
        let mut obj = state.as_object().cloned().unwrap_or_default();
        for (key, value) in evaluate(&robot, &parsed) {
            obj.insert(key.to_string(), value);
        }
        out.push(Value::Object(obj));
    }
    let mut top = doc.as_object().cloned().unwrap_or_default();
    top.insert("states".into(), Value::Array(out));
    Ok(Value::Object(top))
}

/// Parse state number `index` (0-based), naming it by its `name` or, without one, by index.
pub fn parse_state(index: usize, state: &Value) -> Result<StateIn, InputError> {
    let label = match state.get("name").and_then(Value::as_str) {
        Some(name) => format!("\"{name}\" (#{index})"),
        None => format!("#{index}"),
    };
    let obj: &Map<String, Value> = state.as_object().ok_or_else(|| InputError::NotAnObject { state: label.clone() })?;
    let name = match obj.get("name") {
        None => return Err(InputError::MissingField { state: label, field: "name" }),
        Some(Value::String(s)) => s.clone(),
        Some(other) => return Err(InputError::BadField { state: label, field: "name", expected: "a string", got: other.to_string() }),
    };
    let vec = |field: &'static str| -> Result<Vec6, InputError> {
        let value = obj.get(field).ok_or_else(|| InputError::MissingField { state: label.clone(), field })?;
        let bad = || InputError::BadField { state: label.clone(), field, expected: "an array of 6 finite numbers", got: value.to_string() };
        let items = value.as_array().filter(|a| a.len() == 6).ok_or_else(bad)?;
        let mut v = Vec6::zeros();
        for (k, item) in items.iter().enumerate() {
            v[k] = item.as_f64().filter(|x| x.is_finite()).ok_or_else(bad)?;
        }
        Ok(v)
    };
    Ok(StateIn { name, q: vec("q")?, qd: vec("qd")?, qdd: vec("qdd")?, tau_fd: vec("tau_fd")? })
}

fn rows(m: &Mat6) -> Value {
    json!((0..6).map(|r| (0..6).map(|c| m[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>())
}

fn list(v: &Vec6) -> Value {
    json!(v.iter().copied().collect::<Vec<_>>())
}

/// The model outputs for one state, as `(field, value)` pairs.
pub fn evaluate(robot: &Robot, s: &StateIn) -> Vec<(&'static str, Value)> {
    let frames = robot.frames(&s.q);
    let rot = frames.rot[6];
    let pos = frames.pos[6];
    vec![
        ("flange_position", json!([pos.x, pos.y, pos.z])),
        ("flange_rotation", json!((0..3).map(|r| (0..3).map(|c| rot[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>())),
        ("jacobian", rows(&robot.jacobian_flange(&s.q))),
        ("mass_matrix", rows(&robot.mass_matrix(&s.q))),
        ("gravity", list(&robot.gravity_torque(&s.q))),
        ("coriolis", list(&robot.coriolis_times_qd(&s.q, &s.qd))),
        ("tau", list(&robot.rnea(&s.q, &s.qd, &s.qdd))),
        ("qdd_fd", list(&robot.forward_dynamics(&s.q, &s.qd, &s.tau_fd))),
    ]
}
