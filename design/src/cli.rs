//! `rig design`: the thesis' Chapter 6 analysis from the actual models (issue 6).
//!
//! 1. The strip under the wheel at z_a → its static stiffness k_s and the controller's gains from
//!    the design rule (`controller::gains`), with the wheel's effective mass (the robot's
//!    task-space mass along the strip normal at the start pose).
//! 2. Bode plots (Figures 6.2, 6.3): plant P, plant with velocity loop P_v, loop gain L, S, T,
//!    with crossover, phase margin and sensitivity peak (targets: ~25 Hz, ~90°, < 6 dB).
//! 3. The 1-DOF servo run over the bulge (Figure 6.7) with its max/RMS force error.
//!
//! Figures as PNG + SVG and every number in `design.json` under the output directory.

use std::path::{Path, PathBuf};

use anyhow::Context;
use controller::gains::Gains;
use recording_tools::plots::{save_lines, LinePlot, Series};
use scenarios::geometry::{self, TaskFrame};
use scenarios::Scenario;
use strip::StripModel;

use crate::freq::{log_grid, unwrap_deg, Margins};
use crate::plant1::{Loop1, StripPoint};
use crate::servo::{tracking, Tracking};

/// Arguments of `rig design`.
#[derive(Debug, Clone, clap::Args)]
pub struct DesignArgs {
    /// Scenario TOML file (default: scenarios/default.toml).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Wheel position along the strip for the frequency analysis, mm.
    #[arg(long, default_value_t = 20.0)]
    pub z_a_mm: f64,
    /// Output directory for figures and design.json.
    #[arg(long, default_value = "runs/design")]
    pub out: PathBuf,
    /// Strip model cache directory (default: the strip crate's cache directory).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Design the EGM force controller's loop instead (`egm-controller`: admittance behind ABB's
    /// motion controller, its delay included) and bound its force error over the bulge.
    #[arg(long)]
    pub egm: bool,
}

/// Everything `rig design` computes.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DesignResult {
    pub z_a_mm: f64,
    /// 1/G(0) of the strip under the wheel, N/m, and in series with the contact penalty.
    pub strip_static_stiffness_n_per_m: f64,
    pub series_stiffness_n_per_m: f64,
    /// The value the controller uses (`controller.strip_stiffness_n_per_m`).
    pub controller_strip_stiffness_n_per_m: f64,
    pub effective_mass_kg: f64,
    pub loop1: Loop1,
    pub predicted_phase_margin_deg: f64,
    /// The loop's margins with the scenario's force measurement chain (`[sensor]`'s low-pass and
    /// delay, the controller's force filter: `loop1`'s `sensor_*`, `force_filter_beta`).
    pub margins: Option<Margins>,
    /// The same loop with an ideal sensor (equal to `margins` without `[sensor]` and a filter).
    pub margins_ideal_sensor: Option<Margins>,
    pub servo_1dof_max_error_n: f64,
    pub servo_1dof_rms_error_n: f64,
    pub figures: Vec<PathBuf>,
}

/// The robot's task-space mass along the strip normal at the scenario's start pose (controller model).
pub fn start_pose_effective_mass(s: &Scenario) -> anyhow::Result<f64> {
    let robot = controller::step::controller_robot(s);
    let task = TaskFrame::from_scenario(s);
    let q = robot.ik_tcp(&geometry::start_tcp_pose(s), &robot::ik_seed_tool_down()).context("start pose IK")?;
    let law = controller::law::ControlLaw::new(robot, task, Gains::from_scenario(s, f64::NAN), geometry::tool_down_rotation());
    Ok(controller::daemon::effective_normal_mass(&law, &q))
}

/// Frequency analysis at `z_a_m`: the loop of the scenario's gains on the strip model.
pub fn analyse(
    s: &Scenario,
    model: &StripModel,
    z_a_m: f64,
    m_eff: f64,
) -> (Loop1, StripPoint, Vec<f64>, Vec<crate::plant1::Response>, Option<Margins>) {
    let gains = Gains::from_scenario(s, m_eff);
    let strip = StripPoint::new(model, z_a_m);
    let lp = Loop1 {
        wheel_mass_kg: m_eff,
        contact_stiffness_n_per_m: s.contact.stiffness_n_per_m,
        m_d_kg: gains.force.m_d_kg,
        b_d_nspm: gains.force.b_d_nspm,
        k_i_per_s: gains.force.k_i_per_s,
        period_s: s.loop_.period_s,
        sensor_alpha: 1.0,
        sensor_delay_ticks: 0,
        force_filter_beta: 1.0,
    }
    .with_measurement_of(s);
    let f = log_grid(0.5, 5000.0, 1200);
    let (resp, m) = lp.sweep(&strip, &f);
    (lp, strip, f, resp, m)
}

fn db(x: f64) -> f64 {
    20.0 * x.log10()
}

/// Run `rig design`.
pub fn run(args: DesignArgs) -> anyhow::Result<()> {
    let path = args.scenario.clone().unwrap_or_else(Scenario::default_file);
    let s = Scenario::load(&path)?;
    let params = plant_sim::contact::strip_params(&s);
    let model = match &args.cache_dir {
        Some(d) => StripModel::load_or_build_in(d, &params),
        None => StripModel::load_or_build(&params),
    }
    .context("strip model")?;
    if args.egm {
        let r = crate::egm::design_egm(&s, &model, args.z_a_mm * 1e-3);
        std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
        std::fs::write(args.out.join("design_egm.json"), serde_json::to_string_pretty(&r)?)?;
        println!("{}", crate::egm::summary_text(&r));
        return Ok(());
    }
    let result = design(&s, &model, args.z_a_mm * 1e-3, &args.out)?;
    println!("{}", summary_text(&result));
    Ok(())
}

/// The whole analysis; writes figures and design.json into `out`.
pub fn design(s: &Scenario, model: &StripModel, z_a_m: f64, out: &Path) -> anyhow::Result<DesignResult> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let m_eff = start_pose_effective_mass(s)?;
    let (lp, strip, f, resp, m) = analyse(s, model, z_a_m, m_eff);
    let k_s = strip.static_stiffness();
    let series = 1.0 / (1.0 / k_s + 1.0 / s.contact.stiffness_n_per_m);
    let gains = Gains::from_scenario(s, m_eff);
    let lf: Vec<f64> = f.iter().map(|x| x.log10()).collect();
    let series_of = |label: &str, g: &dyn Fn(&crate::plant1::Response) -> f64| Series {
        label: label.into(),
        points: lf.iter().zip(&resp).map(|(x, r)| (*x, g(r))).collect(),
    };
    let mut figures = Vec::new();
    figures.extend(save_lines(
        &LinePlot {
            title: format!("Bode magnitude at z_a = {:.1} mm (Figure 6.2)", z_a_m * 1e3),
            x_label: "log10 frequency (Hz)".into(),
            y_label: "magnitude (dB)".into(),
            series: vec![
                series_of("plant P = F_e/u", &|r| db(r.plant.norm())),
                series_of("with velocity loop P_v = F_e/e", &|r| db(r.plant_velocity_loop.norm())),
                series_of("loop gain L", &|r| db(r.loop_gain.norm())),
            ],
            hlines: vec![(0.0, "0 dB".into())],
            vlines: Vec::new(),
        },
        &out.join("bode_magnitude"),
    )?);
    let mut ph_l: Vec<f64> = resp.iter().map(|r| r.loop_gain.arg().to_degrees()).collect();
    unwrap_deg(&mut ph_l);
    let mut ph_p: Vec<f64> = resp.iter().map(|r| r.plant.arg().to_degrees()).collect();
    unwrap_deg(&mut ph_p);
    figures.extend(save_lines(
        &LinePlot {
            title: "Bode phase (Figure 6.2)".into(),
            x_label: "log10 frequency (Hz)".into(),
            y_label: "phase (deg)".into(),
            series: vec![
                Series { label: "plant P".into(), points: lf.iter().cloned().zip(ph_p).collect() },
                Series { label: "loop gain L".into(), points: lf.iter().cloned().zip(ph_l).collect() },
            ],
            hlines: vec![(-180.0, "-180 deg".into())],
            vlines: Vec::new(),
        },
        &out.join("bode_phase"),
    )?);
    figures.extend(save_lines(
        &LinePlot {
            title: "Sensitivity S and complementary sensitivity T (Figure 6.3)".into(),
            x_label: "log10 frequency (Hz)".into(),
            y_label: "magnitude (dB)".into(),
            series: vec![series_of("S", &|r| db(r.sensitivity.norm())), series_of("T", &|r| db(r.complementary.norm()))],
            hlines: vec![(6.0, "6 dB".into()), (0.0, "0 dB".into())],
            vlines: Vec::new(),
        },
        &out.join("sensitivity"),
    )?);
    // 1-DOF servo run (Figure 6.7).
    let samples = crate::sim1::run_1dof(s, model, &gains, m_eff);
    let tr: Tracking = tracking(&samples);
    figures.extend(save_lines(
        &LinePlot {
            title: format!("1-DOF servo run over the bulge (Figure 6.7): max error {:.3} N, RMS {:.3} N", tr.max_n, tr.rms_n),
            x_label: "time (s)".into(),
            y_label: "force (N)".into(),
            series: vec![
                Series { label: "force reference".into(), points: samples.iter().map(|x| (x.t_s, x.force_ref_n)).collect() },
                Series { label: "bottom force".into(), points: samples.iter().map(|x| (x.t_s, x.bottom_force_n)).collect() },
                Series { label: "contact force".into(), points: samples.iter().map(|x| (x.t_s, x.contact_force_n)).collect() },
            ],
            hlines: vec![],
            vlines: Vec::new(),
        },
        &out.join("servo_1dof"),
    )?);
    figures.extend(save_lines(
        &LinePlot {
            title: "1-DOF servo run: force error over the roll, |F_bottom| - |F_ref|".into(),
            x_label: "time (s)".into(),
            y_label: "force error (N)".into(),
            series: vec![Series {
                label: "|bottom force| - |reference|".into(),
                points: samples
                    .iter()
                    .filter(|x| x.phase == controller::reference::Phase::Roll)
                    .map(|x| (x.t_s, x.bottom_force_n.abs() - x.force_ref_n.abs()))
                    .collect(),
            }],
            hlines: vec![(0.0, "0".into())],
            vlines: Vec::new(),
        },
        &out.join("servo_1dof_error"),
    )?);
    let result = DesignResult {
        z_a_mm: z_a_m * 1e3,
        strip_static_stiffness_n_per_m: k_s,
        series_stiffness_n_per_m: series,
        controller_strip_stiffness_n_per_m: s.controller.strip_stiffness_n_per_m,
        effective_mass_kg: m_eff,
        loop1: lp,
        predicted_phase_margin_deg: gains.force.predicted_phase_margin_deg,
        margins: m,
        margins_ideal_sensor: lp.ideal_sensor().sweep(&strip, &f).1,
        servo_1dof_max_error_n: tr.max_n,
        servo_1dof_rms_error_n: tr.rms_n,
        figures,
    };
    let json = serde_json::to_string_pretty(&result)?;
    std::fs::write(out.join("design.json"), json).with_context(|| format!("writing {}", out.join("design.json").display()))?;
    Ok(result)
}

/// Human-readable summary.
pub fn summary_text(r: &DesignResult) -> String {
    let text = |m: Option<Margins>| {
        m.map_or("no crossover".to_string(), |m| {
            format!(
                "crossover {:.1} Hz, phase margin {:.1} deg, |S| peak {:.2} dB at {:.1} Hz",
                m.crossover_hz, m.phase_margin_deg, m.sensitivity_peak_db, m.sensitivity_peak_hz
            )
        })
    };
    let mut m = text(r.margins);
    let l = &r.loop1;
    if l.sensor_alpha != 1.0 || l.sensor_delay_ticks != 0 || l.force_filter_beta != 1.0 {
        m = format!(
            "{m}\n      with the force measurement (sensor low-pass alpha {:.4}, delay {} ticks, controller filter beta {:.4}); \
             with an ideal sensor: {}",
            l.sensor_alpha,
            l.sensor_delay_ticks,
            l.force_filter_beta,
            text(r.margins_ideal_sensor)
        );
    }
    format!(
        "strip under the wheel at z_a = {:.1} mm: k_s = {:.4e} N/m (with contact penalty {:.4e} N/m); controller uses {:.4e} N/m\n\
         effective mass {:.2} kg; m_d = {:.4} kg, b_d = {:.2} N s/m, k_i = {:.2} 1/s (rule predicts PM {:.1} deg)\n\
         loop: {m}\n\
         1-DOF servo run: max |F_bottom - F_ref| {:.4} N, RMS {:.4} N\n\
         figures: {}",
        r.z_a_mm,
        r.strip_static_stiffness_n_per_m,
        r.series_stiffness_n_per_m,
        r.controller_strip_stiffness_n_per_m,
        r.effective_mass_kg,
        r.loop1.m_d_kg,
        r.loop1.b_d_nspm,
        r.loop1.k_i_per_s,
        r.predicted_phase_margin_deg,
        r.servo_1dof_max_error_n,
        r.servo_1dof_rms_error_n,
        r.figures.len()
    )
}
