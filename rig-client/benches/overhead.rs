//! Per-tick cost of the C client library against the Rust controller's own port code:
//! `cargo bench -p rig-client --bench overhead`.
//!
//! A stand-in plant thread (`rig_client::loopback`) publishes state + wrench and waits for the
//! answer, in lockstep, over real iceoryx2; the controller thread answers with either the Rust
//! port calls the `controller` daemon makes (wait, receive state, receive wrench, publish torque +
//! diagnostics) or the C API (`rig_client_wait`, `rig_client_publish`, through the C ABI). Printed
//! per variant: the controller's time per tick from waking to having published (p50, p99, mean),
//! i.e. the CPU cost a controller pays per tick on top of its law, and the round trip per tick.

use std::time::{Duration, Instant};

use messages::{ControllerDiagnostics, JointTorque, PlantStatus, CONTRACT_VERSION};
use rig_client::*;
use rig_process::ports::ControllerPorts;

const TICKS: u64 = 20_000;

fn report(name: &str, mut per_tick_ns: Vec<u64>, total: Duration) {
    per_tick_ns.sort_unstable();
    let n = per_tick_ns.len();
    let mean = per_tick_ns.iter().sum::<u64>() as f64 / n as f64;
    println!(
        "{name:<28} {n} ticks: woke->published p50 {:>6.2} us, p99 {:>6.2} us, mean {:>6.2} us; round trip {:>6.2} us/tick",
        per_tick_ns[n / 2] as f64 * 1e-3,
        per_tick_ns[n * 99 / 100] as f64 * 1e-3,
        mean * 1e-3,
        total.as_secs_f64() * 1e6 / n as f64
    );
}

fn rust_ports() {
    let rig = loopback::unique_rig("bench-rs");
    let plant = loopback::spawn(&rig, TICKS);
    let ports = ControllerPorts::open(&rig, "bench-rust").unwrap();
    let mut samples = Vec::with_capacity(TICKS as usize);
    let mut next = 0;
    let t0 = Instant::now();
    loop {
        let _ = ports.wait_state(Instant::now() + Duration::from_secs(1));
        let woke = Instant::now();
        let Some((st, _)) = ports.receive_state_with_origin() else { continue };
        let _ = ports.receive_wrench();
        if st.plant_status == PlantStatus::ShuttingDown as u32 {
            break;
        }
        if st.tick < next {
            continue;
        }
        let t = JointTorque { contract_version: CONTRACT_VERSION, controller_status: 0, tick: st.tick, controller_id: 1, tau: [0.5; 6] };
        let d = ControllerDiagnostics {
            tick: st.tick,
            woke_mono_ns: rig_process::clock::now_mono_ns(),
            computed_mono_ns: rig_process::clock::now_mono_ns(),
            published_mono_ns: rig_process::clock::now_mono_ns(),
            ..ControllerDiagnostics::zeroed(CONTRACT_VERSION)
        };
        ports.publish(&t, Some(&d)).unwrap();
        samples.push(woke.elapsed().as_nanos() as u64);
        next = st.tick + 1;
    }
    let total = t0.elapsed();
    plant.join().unwrap();
    report("Rust ControllerPorts", samples, total);
}

fn c_api() {
    let rig = loopback::unique_rig("bench-c");
    let plant = loopback::spawn(&rig, TICKS);
    let name = std::ffi::CString::new(rig).unwrap();
    let mut c: *mut RigClient = std::ptr::null_mut();
    // SAFETY: valid strings and out pointer.
    assert_eq!(unsafe { rig_client_open(name.as_ptr(), std::ptr::null(), std::ptr::null(), 30.0, &mut c) }, RIG_OK);
    let (mut st, mut w) = (RigJointState::default(), RigWrench::default());
    let mut samples = Vec::with_capacity(TICKS as usize);
    let tau = [0.5; 6];
    let t0 = Instant::now();
    loop {
        // SAFETY: a client from rig_client_open, valid out pointers.
        let rc = unsafe { rig_client_wait(c, 1.0, &mut st, &mut w) };
        if rc == RIG_SHUTTING_DOWN {
            break;
        }
        assert_eq!(rc, RIG_OK);
        // SAFETY: as above; tau holds 6 doubles.
        assert_eq!(unsafe { rig_client_publish(c, st.tick, 0, tau.as_ptr(), std::ptr::null()) }, RIG_OK);
        // SAFETY: the client is valid; read only.
        samples.push(unsafe { &*c }.last_woke().elapsed().as_nanos() as u64);
    }
    let total = t0.elapsed();
    // SAFETY: from rig_client_open, closed once.
    unsafe { rig_client_close(c) };
    plant.join().unwrap();
    report("C API (rig_client_*)", samples, total);
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // cargo test --benches asks for the list
    }
    println!("load: {}", std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim());
    rust_ports();
    c_api();
    rust_ports();
    c_api();
}
