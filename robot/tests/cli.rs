//! `rig robot dynamics` JSON I/O, through `robot::cli::run` as the `rig` binary calls it.

use std::path::PathBuf;

use robot::cli::{run, Command};
use robot::{Robot, Vec6};
use serde_json::{json, Value};

const Z6: [f64; 6] = [0.0; 6];

/// A fresh scratch directory per test.
fn scratch_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("robot-cli-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run_on(test: &str, input: &Value) -> (anyhow::Result<()>, PathBuf) {
    let dir = scratch_dir(test);
    let (inp, out) = (dir.join("IN.json"), dir.join("OUT.json"));
    std::fs::write(&inp, serde_json::to_string(input).unwrap()).unwrap();
    (run(Command::Dynamics { input: inp, output: out.clone() }), out)
}

fn vec6(v: &Value) -> Vec6 {
    let a = v.as_array().expect("array");
    assert_eq!(a.len(), 6);
    Vec6::from_fn(|i, _| a[i].as_f64().unwrap())
}

#[test]
fn dynamics_writes_every_output_field() {
    let q = [0.1, -1.2, 0.3, 0.4, 0.9, -0.2];
    let qd = [0.5, -0.2, 0.3, 1.0, -0.5, 0.7];
    let qdd = [1.0, 2.0, -1.0, 3.0, 0.5, -2.0];
    let input = json!({"states": [
        {"name": "abb_zero", "q": Robot::ABB_ZERO_Q, "qd": Z6, "qdd": Z6, "tau_fd": Z6},
        {"name": "moving", "q": q, "qd": qd, "qdd": qdd, "tau_fd": [10.0, 20.0, -5.0, 1.0, 0.5, 0.1], "note": "kept"}
    ]});
    let (result, out) = run_on("fields", &input);
    result.unwrap();
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap();
    let states = doc["states"].as_array().unwrap();
    assert_eq!(states.len(), 2);

    // ABB zero pose: flange at (0.94, 0, 1.455) m, flange z along base x.
    let zero = &states[0];
    assert_eq!(zero["name"], "abb_zero");
    let p: Vec<f64> = zero["flange_position"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert!((p[0] - 0.94).abs() < 1e-12 && p[1].abs() < 1e-12 && (p[2] - 1.455).abs() < 1e-12, "{p:?}");
    let rot = &zero["flange_rotation"];
    assert!((rot[0][2].as_f64().unwrap() - 1.0).abs() < 1e-12, "R[0][2] = {}", rot[0][2]);
    // At rest with zero acceleration, tau is the gravity torque.
    assert_eq!(vec6(&zero["tau"]), vec6(&zero["gravity"]));

    // The moving state: outputs are consistent with each other (RNEA = M qdd + C qd + g) and
    // the extra input field is kept.
    let s = &states[1];
    assert_eq!(s["note"], "kept");
    let m = robot::Mat6::from_fn(|r, c| s["mass_matrix"][r][c].as_f64().unwrap());
    let sum = m * Vec6::from(qdd) + vec6(&s["coriolis"]) + vec6(&s["gravity"]);
    let tau = vec6(&s["tau"]);
    assert!((sum - tau).norm() < 1e-10 * tau.norm(), "{sum:?} vs {tau:?}");
    // qdd_fd solves M qdd_fd + C qd + g = tau_fd.
    let lhs = m * vec6(&s["qdd_fd"]) + vec6(&s["coriolis"]) + vec6(&s["gravity"]);
    assert!((lhs - Vec6::new(10.0, 20.0, -5.0, 1.0, 0.5, 0.1)).norm() < 1e-8, "{lhs:?}");
    // Jacobian rows v then w: the last three rows of column 1 are joint 1's axis, base z.
    let jac = &s["jacobian"];
    assert_eq!((jac[3][0].as_f64(), jac[4][0].as_f64(), jac[5][0].as_f64()), (Some(0.0), Some(0.0), Some(1.0)));
}

fn error_of(test: &str, input: Value) -> String {
    let (result, out) = run_on(test, &input);
    assert!(!out.exists(), "no output on error");
    format!("{:#}", result.expect_err("malformed input must fail"))
}

#[test]
fn missing_field_names_state_and_field() {
    let msg = error_of(
        "missing",
        json!({"states": [
            {"name": "ok", "q": Z6, "qd": Z6, "qdd": Z6, "tau_fd": Z6},
            {"name": "second", "q": Z6, "qd": Z6, "tau_fd": Z6}
        ]}),
    );
    assert!(msg.contains("\"second\"") && msg.contains("\"qdd\"") && msg.contains("missing"), "{msg}");
}

#[test]
fn malformed_field_names_state_field_and_value() {
    let msg = error_of("short", json!({"states": [{"name": "short_q", "q": [0.0, 1.0], "qd": Z6, "qdd": Z6, "tau_fd": Z6}]}));
    assert!(msg.contains("\"short_q\"") && msg.contains("\"q\"") && msg.contains("[0.0,1.0]"), "{msg}");
    let msg = error_of("text", json!({"states": [{"name": "texty", "q": Z6, "qd": [0, 0, "x", 0, 0, 0], "qdd": Z6, "tau_fd": Z6}]}));
    assert!(msg.contains("\"texty\"") && msg.contains("\"qd\""), "{msg}");
    let msg = error_of("noname", json!({"states": [{"q": Z6, "qd": Z6, "qdd": Z6, "tau_fd": Z6}]}));
    assert!(msg.contains("#0") && msg.contains("\"name\""), "{msg}");
    let msg = error_of("nostates", json!({"state": []}));
    assert!(msg.contains("states"), "{msg}");
}

#[test]
fn unreadable_input_names_the_file() {
    let dir = scratch_dir("nofile");
    let inp = dir.join("absent.json");
    let err = run(Command::Dynamics { input: inp, output: dir.join("OUT.json") }).unwrap_err();
    assert!(format!("{err:#}").contains("absent.json"), "{err:#}");
}
