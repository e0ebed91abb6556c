//! What a tick allocates: the C API's wait + publish (`rig_client_wait`, `rig_client_publish`)
//! and, below it, the Rust controller's own port calls (`ControllerPorts::wait_state`,
//! `receive_state_with_origin`, `receive_wrench`, `publish`), each over 1000 ticks after a
//! warm-up against a stand-in plant on another thread over real iceoryx2. A counting global
//! allocator counts the controller thread's allocations only.
//!
//! Waiting and receiving allocate nothing, and neither does the library's own code. Sending does:
//! iceoryx2 0.10 boxes a 48-byte `Rc` of shared state for every loaned sample
//! (`SampleMutUninit::new`, sample_mut_uninit.rs:327 → chunk_mut_shared_state.rs:102), and
//! `Publisher::send_copy` loans one; every iceoryx2 send API goes through it. So a tick that
//! sends torque + diagnostics allocates exactly 2 times (glibc serves them from its per-thread
//! cache: no lock, no system call), in the Rust controller and the plant alike. The tests pin
//! that number, so a change of either side shows.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::{Duration, Instant};

use messages::{ControllerDiagnostics, JointTorque, CONTRACT_VERSION};
use rig_client::*;
use rig_process::ports::ControllerPorts;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every method forwards to System, which upholds the GlobalAlloc contract.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const WARM_UP: u64 = 50;
const COUNTED: u64 = 1000;
/// iceoryx2 0.10's one allocation per sample sent (see above), times the torque and diagnostics.
const ICEORYX2_LOANS_PER_TICK: usize = 2;

#[test]
fn the_c_api_allocates_only_iceoryx2s_two_loans_per_tick() {
    let rig = loopback::unique_rig("alloc-c");
    let plant = loopback::spawn(&rig, WARM_UP + COUNTED);
    let name = std::ffi::CString::new(rig).unwrap();
    let mut client: *mut RigClient = std::ptr::null_mut();
    // SAFETY: valid strings and out pointer.
    assert_eq!(unsafe { rig_client_open(name.as_ptr(), std::ptr::null(), std::ptr::null(), 30.0, &mut client) }, RIG_OK);
    let (mut st, mut w) = (RigJointState::default(), RigWrench::default());
    let (mut ticks, mut before) = (0, 0);
    loop {
        // SAFETY: a client from rig_client_open, valid out pointers.
        let rc = unsafe { rig_client_wait(client, 10.0, &mut st, &mut w) };
        if rc == RIG_SHUTTING_DOWN {
            break;
        }
        assert_eq!(rc, RIG_OK, "tick {ticks}");
        assert_eq!(w.tick, st.tick, "the wrench of the state's tick");
        let tau = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        // SAFETY: as above; tau holds 6 doubles.
        assert_eq!(unsafe { rig_client_publish(client, st.tick, RIG_CONTROLLER_ACTIVE, tau.as_ptr(), std::ptr::null()) }, RIG_OK);
        ticks += 1;
        if ticks == WARM_UP {
            before = allocations();
        }
    }
    let counted = allocations() - before;
    // SAFETY: from rig_client_open, closed once.
    unsafe { rig_client_close(client) };
    assert_eq!(ticks, WARM_UP + COUNTED);
    assert_eq!(plant.join().unwrap(), WARM_UP + COUNTED, "the plant got every answer");
    assert_eq!(
        counted,
        ICEORYX2_LOANS_PER_TICK * COUNTED as usize,
        "allocations in {COUNTED} ticks of rig_client_wait + rig_client_publish: only iceoryx2's two loans per tick expected"
    );
}

#[test]
fn the_rust_port_calls_allocate_only_iceoryx2s_two_loans_per_tick() {
    let rig = loopback::unique_rig("alloc-rs");
    let plant = loopback::spawn(&rig, WARM_UP + COUNTED);
    let ports = ControllerPorts::open(&rig, "alloc-test").unwrap();
    let (mut ticks, mut before) = (0, 0);
    let until = Instant::now() + Duration::from_secs(60);
    while Instant::now() < until {
        let _ = ports.wait_state(Instant::now() + Duration::from_millis(100));
        let Some((st, _origin)) = ports.receive_state_with_origin() else { continue };
        let _ = ports.receive_wrench();
        if st.plant_status == messages::PlantStatus::ShuttingDown as u32 {
            break;
        }
        if ticks > 0 && st.tick < ticks {
            continue; // a repeated tick 0
        }
        let t = JointTorque { contract_version: CONTRACT_VERSION, controller_status: 0, tick: st.tick, controller_id: 7, tau: [0.5; 6] };
        let d = ControllerDiagnostics { tick: st.tick, ..ControllerDiagnostics::zeroed(CONTRACT_VERSION) };
        ports.publish(&t, Some(&d)).unwrap();
        ticks += 1;
        if ticks == WARM_UP {
            before = allocations();
        }
    }
    let counted = allocations() - before;
    assert_eq!(ticks, WARM_UP + COUNTED);
    assert_eq!(plant.join().unwrap(), WARM_UP + COUNTED);
    assert_eq!(
        counted,
        ICEORYX2_LOANS_PER_TICK * COUNTED as usize,
        "allocations in {COUNTED} ticks of the Rust port calls: only iceoryx2's two loans per tick expected"
    );
}
