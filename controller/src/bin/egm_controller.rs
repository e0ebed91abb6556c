//! `egm-controller --scenario FILE [--rig NAME]`: the thesis' force task as an ABB EGM sensor
//! (`controller::egm_force`). Binds the scenario's `egm.sensor_address` (UDP), answers every
//! `EgmRobot` with an `EgmSensor` joint reference, and exits 0 when the robot ends the session
//! (`MCI_STOPPED`) or goes quiet for `egm.comm_timeout_s` plus 2 s after it started. It links
//! neither the plant nor the strip model: what it knows of the robot is what a real IRB 2400
//! sends.
//!
//! Exit status: 0 the session ended; 1 an error (address taken, bad scenario).

use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use controller::egm_force::{EgmForceLaw, EgmInput};
use egm::pb;
use nalgebra::Vector3;
use prost::Message;
use robot::Vec6;

#[derive(Debug, Parser)]
#[command(
    name = "egm-controller",
    about = "EGM force controller (admittance on the measured force) for the weatherstrip rig's EGM robot or a real IRB 2400"
)]
struct Args {
    /// Scenario TOML file (trajectory, force references, [egm] section).
    #[arg(long)]
    scenario: PathBuf,
    /// Rig name (accepted so `rig run` can start it like any controller; EGM has no rig prefix).
    #[arg(long)]
    rig: Option<String>,
}

fn main() -> ExitCode {
    rig_process::logging::init_stderr();
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            rig_process::host::print_stderr(&format!("egm-controller: error: {e:#}\n"));
            ExitCode::from(1)
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    let s = scenarios::Scenario::load(&args.scenario)?;
    let sock = UdpSocket::bind(&s.egm.sensor_address)
        .map_err(|e| anyhow::anyhow!("binding the EGM sensor address {}: {e}", s.egm.sensor_address))?;
    sock.set_read_timeout(Some(Duration::from_millis(100)))?;
    let mut law = EgmForceLaw::new(&s);
    let d = *law.design();
    tracing::info!(
        "EGM force controller on {}: admittance b = {:.0} N s/m (crossover {:.2} Hz, phase margin {:.1} deg, loop delay {:.2} ms)",
        s.egm.sensor_address,
        d.damping_ns_per_m,
        d.crossover_hz,
        d.phase_margin_deg,
        d.delay_s * 1e3
    );
    let quiet_limit = Duration::from_secs_f64(s.egm.comm_timeout_s + 2.0);
    let mut buf = [0u8; 4096];
    let mut out: Vec<u8> = Vec::with_capacity(1024);
    let mut robot = pb::EgmRobot::default();
    let mut seqno: u32 = 0;
    let mut last_message: Option<Instant> = None;
    let mut cycles: u64 = 0;
    loop {
        let (n, from) = match sock.recv_from(&mut buf) {
            Ok(x) => x,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                if last_message.is_some_and(|t| t.elapsed() > quiet_limit) {
                    tracing::warn!("the robot has been silent for {:.1} s: ending after {cycles} cycles", quiet_limit.as_secs_f64());
                    return Ok(());
                }
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        last_message = Some(Instant::now());
        robot.clear();
        if robot.merge(&buf[..n]).is_err() {
            tracing::warn!("a datagram from {from} is not an EgmRobot message: ignored");
            continue;
        }
        if robot.mci_state.is_some_and(|m| m.state == pb::egm_mci_state::MciStateType::MciStopped as i32) {
            tracing::info!("the robot ended the EGM session (MCI_STOPPED) after {cycles} cycles");
            return Ok(());
        }
        let joints = robot.feed_back.as_ref().and_then(|f| f.joints.as_ref()).map_or(&[][..], |j| j.joints.as_slice());
        if joints.len() != 6 {
            tracing::warn!("an EgmRobot message without 6 feedback joints: ignored");
            continue;
        }
        let deg: [f64; 6] = std::array::from_fn(|i| joints[i]);
        let force = robot.measured_force.as_ref().map_or(&[][..], |f| f.force.as_slice());
        let force_sensor_n = if force.len() >= 3 { Vector3::new(force[0], force[1], force[2]) } else { Vector3::zeros() };
        let t_s = robot.header.as_ref().and_then(|h| h.tm).unwrap_or(0) as f64 * 1e-3;
        let o = law.step(&EgmInput { t_s, q: Vec6::from(egm::axes::dh_from_abb_deg(&deg)), force_sensor_n });
        seqno = seqno.wrapping_add(1);
        let reply = pb::EgmSensor {
            header: Some(pb::EgmHeader {
                seqno: Some(seqno),
                tm: None,
                mtype: Some(pb::egm_header::MessageType::MsgtypeCorrection as i32),
            }),
            planned: Some(pb::EgmPlanned {
                joints: Some(pb::EgmJoints { joints: egm::axes::abb_deg_from_dh(&o.q_ref.into()).to_vec() }),
                ..Default::default()
            }),
            speed_ref: None,
        };
        out.clear();
        reply.encode(&mut out)?;
        sock.send_to(&out, from)?;
        cycles += 1;
    }
}
