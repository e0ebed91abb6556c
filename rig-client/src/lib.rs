//! `rig-client`: the rig's controller end with a C ABI (issue 27), for controllers in C or C++.
//!
//! It is the Rust controller's own port code (`rig_process::ports::ControllerPorts`: the rig's
//! iceoryx2 configuration by the state-directory rule, the contract's QoS, the same wait on the
//! plant's event) behind plain C functions, plus the rig's robot model (`robot`, with the
//! scenario's tool), so that a C or C++ program neither builds iceoryx2's C bindings nor
//! re-derives the contract. The header `include/rig_client.h` is generated from this file by
//! cbindgen (`tests/header.rs`; `RIG_CLIENT_BLESS=1` rewrites it).
//!
//! Every function returns a code: 0 and the positive statuses (`RIG_OK`, `RIG_TIMEOUT`, ...) are
//! outcomes, the negative ones (`RIG_ERR_*`) errors; `rig_client_error_message(code)` names a
//! code, `rig_client_last_error()` gives the one-sentence detail of this thread's last error.
//! After `rig_client_open` nothing allocates, locks or logs (`tests/no_alloc.rs`).

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::{Duration, Instant};

use messages::{state_flags, ControllerDiagnostics, JointState, JointTorque, PlantStatus, Wrench, CONTRACT_VERSION};
use rig_process::liveness::{PeerWatch, Watched};
use rig_process::ports::{ControllerPorts, Wake, WithCauses};
use robot::Vec6;

/// The contract version this library speaks (`messages::CONTRACT_VERSION`).
pub const RIG_CONTRACT_VERSION: u32 = 2;
const _: () = assert!(RIG_CONTRACT_VERSION == CONTRACT_VERSION);

/// Number of joints.
pub const RIG_DOF: usize = 6;

// Outcomes (>= 0).
/// A new state and the wrench of its tick were received: answer it.
pub const RIG_OK: i32 = 0;
/// No new state within the timeout; the plant's node is alive (or not known yet).
pub const RIG_TIMEOUT: i32 = 1;
/// The plant's goodbye (`plant_status` 4): the state is its last; exit 0.
pub const RIG_SHUTTING_DOWN: i32 = 2;
/// The plant's iceoryx2 node is dead (killed, crashed): no more states will come; exit non-zero.
pub const RIG_PLANT_GONE: i32 = 3;
/// A new state (and wrench) arrived with the reflex bit set: the plant holds the arm in its
/// latched safe stop until an answer with `RIG_CONTROLLER_STARTING` acknowledges it.
pub const RIG_SAFE_STOP_TO_ACKNOWLEDGE: i32 = 4;

// Errors (< 0).
/// A required pointer argument was NULL.
pub const RIG_ERR_NULL_ARGUMENT: i32 = -1;
/// An argument is out of range (rig name, timeout, a non-UTF-8 string).
pub const RIG_ERR_INVALID_ARGUMENT: i32 = -2;
/// The scenario file could not be read or is invalid.
pub const RIG_ERR_SCENARIO: i32 = -3;
/// The rig's iceoryx2 configuration, node or services could not be set up (host, /dev/shm, QoS).
pub const RIG_ERR_OPEN: i32 = -4;
/// No joint state within the open timeout: no plant runs on this rig.
pub const RIG_ERR_NO_PLANT: i32 = -5;
/// The plant speaks another contract version.
pub const RIG_ERR_CONTRACT_VERSION: i32 = -6;
/// Sending on a service failed.
pub const RIG_ERR_PUBLISH: i32 = -7;
/// A bug inside the library (a Rust panic, caught at the boundary).
pub const RIG_ERR_INTERNAL: i32 = -8;

// Values of the records' fields (messages/README.md).
pub const RIG_PLANT_WAITING_FOR_CONTROLLER: u32 = 0;
pub const RIG_PLANT_RUNNING: u32 = 1;
pub const RIG_PLANT_HOLDING_TORQUE: u32 = 2;
pub const RIG_PLANT_SAFE_STOP: u32 = 3;
pub const RIG_PLANT_SHUTTING_DOWN: u32 = 4;
pub const RIG_CONTROLLER_ACTIVE: u32 = 0;
/// Applied like active; also acknowledges a latched reflex safe stop.
pub const RIG_CONTROLLER_STARTING: u32 = 1;
/// Asks the plant for its safe stop (the torque values are ignored).
pub const RIG_CONTROLLER_FAULT: u32 = 2;
pub const RIG_FLAG_TORQUE_HELD: u32 = 1 << 0;
pub const RIG_FLAG_TORQUE_REFUSED: u32 = 1 << 1;
pub const RIG_FLAG_LOCKSTEP: u32 = 1 << 2;
pub const RIG_FLAG_IN_CONTACT: u32 = 1 << 3;
pub const RIG_FLAG_REFLEX: u32 = 1 << 4;
pub const RIG_FLAG_END_STOP: u32 = 1 << 5;
const _: () = assert!(
    RIG_FLAG_TORQUE_HELD == state_flags::TORQUE_HELD
        && RIG_FLAG_TORQUE_REFUSED == state_flags::TORQUE_REFUSED
        && RIG_FLAG_LOCKSTEP == state_flags::LOCKSTEP
        && RIG_FLAG_IN_CONTACT == state_flags::IN_CONTACT
        && RIG_FLAG_REFLEX == state_flags::REFLEX
        && RIG_FLAG_END_STOP == state_flags::END_STOP
        && RIG_PLANT_SHUTTING_DOWN == PlantStatus::ShuttingDown as u32
        && RIG_PLANT_SAFE_STOP == PlantStatus::SafeStop as u32
);

/// `rig::JointState` (192 bytes), plant → controller; fields as in messages/README.md.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigJointState {
    pub contract_version: u32,
    pub plant_status: u32,
    pub tick: u64,
    pub sim_time_s: f64,
    pub q: [f64; 6],
    pub qd: [f64; 6],
    pub tau_applied: [f64; 6],
    pub period_s: f64,
    pub flags: u32,
    pub consecutive_misses: u32,
    pub total_misses: u64,
}

/// `rig::Wrench` (64 bytes): the wrench the strip exerts ON the tool, in `frame`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigWrench {
    pub contract_version: u32,
    pub frame: u32,
    pub tick: u64,
    pub force: [f64; 3],
    pub torque: [f64; 3],
}

/// `rig::JointTorque` (72 bytes), controller → plant.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigJointTorque {
    pub contract_version: u32,
    pub controller_status: u32,
    pub tick: u64,
    pub controller_id: u64,
    pub tau: [f64; 6],
}

/// `rig::ControllerDiagnostics` (144 bytes), controller → plant (optional).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigControllerDiagnostics {
    pub contract_version: u32,
    pub force_control_active: u32,
    pub tick: u64,
    pub force_ref_n: f64,
    pub force_meas_n: f64,
    pub pos_ref_task_m: [f64; 3],
    pub pos_err_task_m: [f64; 3],
    pub rot_err_task_rad: [f64; 3],
    pub force_integral_ns: f64,
    pub compute_time_ns: u64,
    pub woke_mono_ns: u64,
    pub computed_mono_ns: u64,
    pub published_mono_ns: u64,
}

/// The C records mirror `messages`' (cbindgen cannot read that crate, see cbindgen.toml): same
/// fields in the same order under `#[repr(C)]`, checked here field by field at compile time,
/// so the two convert by reinterpreting the bytes.
macro_rules! same_layout {
    ($c:ty, $contract:ty, [$($field:ident),*]) => {
        const _: () = {
            use core::mem::{offset_of, size_of};
            assert!(size_of::<$c>() == size_of::<$contract>());
            $(assert!(offset_of!($c, $field) == offset_of!($contract, $field));)*
        };
    };
}
same_layout!(
    RigJointState,
    JointState,
    [contract_version, plant_status, tick, sim_time_s, q, qd, tau_applied, period_s, flags, consecutive_misses, total_misses]
);
same_layout!(RigWrench, Wrench, [contract_version, frame, tick, force, torque]);
same_layout!(RigJointTorque, JointTorque, [contract_version, controller_status, tick, controller_id, tau]);
same_layout!(
    RigControllerDiagnostics,
    ControllerDiagnostics,
    [
        contract_version,
        force_control_active,
        tick,
        force_ref_n,
        force_meas_n,
        pos_ref_task_m,
        pos_err_task_m,
        rot_err_task_rad,
        force_integral_ns,
        compute_time_ns,
        woke_mono_ns,
        computed_mono_ns,
        published_mono_ns
    ]
);

fn c_state(s: &JointState) -> RigJointState {
    // SAFETY: identical layouts (same_layout! above), plain old data: every bit pattern is valid.
    unsafe { core::mem::transmute::<JointState, RigJointState>(*s) }
}

fn c_wrench(w: &Wrench) -> RigWrench {
    // SAFETY: identical layouts (same_layout! above), plain old data.
    unsafe { core::mem::transmute::<Wrench, RigWrench>(*w) }
}

fn contract_diagnostics(d: &RigControllerDiagnostics) -> ControllerDiagnostics {
    // SAFETY: identical layouts (same_layout! above), plain old data.
    unsafe { core::mem::transmute::<RigControllerDiagnostics, ControllerDiagnostics>(*d) }
}

thread_local! {
    /// The detail of this thread's last error (allocated on errors only, never per tick).
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn fail(code: i32, msg: String) -> i32 {
    let c = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
    code
}

/// Run `f` with panics turned into `RIG_ERR_INTERNAL` (a panic must not unwind into C).
fn guard(f: impl FnOnce() -> i32) -> i32 {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(c) => c,
        Err(_) => fail(RIG_ERR_INTERNAL, "rig-client: internal error (a panic inside the library)".into()),
    }
}

/// # Safety
/// `p` is NULL or a NUL-terminated string.
unsafe fn str_arg<'a>(p: *const c_char, what: &str) -> Result<Option<&'a str>, i32> {
    if p.is_null() {
        return Ok(None);
    }
    // SAFETY: the caller passes a NUL-terminated string (the C API's contract).
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str().map(Some).map_err(|_| fail(RIG_ERR_INVALID_ARGUMENT, format!("rig-client: {what} is not UTF-8")))
}

/// The scenario at `path` (None: the built-in default scenario).
fn scenario(path: Option<&str>) -> Result<scenarios::Scenario, i32> {
    match path {
        None => Ok(scenarios::Scenario::default()),
        Some(p) => scenarios::Scenario::load(Path::new(p)).map_err(|e| fail(RIG_ERR_SCENARIO, format!("rig-client: scenario {p}: {e}"))),
    }
}

/// One controller's connection to one rig. Opaque to C; single-threaded (iceoryx2's IPC ports
/// belong to the thread that opened them).
pub struct RigClient {
    ports: ControllerPorts,
    watch: PeerWatch,
    controller_id: u64,
    /// Real-time busy poll around the due time (`loop.controller_spin_us`), as the Rust controller.
    spin: Duration,
    /// The plant this client answers (publisher id of its joint state).
    plant: Option<u128>,
    /// The last tick published (a state of this tick or older is not new).
    last_published: Option<u64>,
    /// The tick of the last state handed out, and when it woke for it.
    current_tick: u64,
    woke: Instant,
    woke_mono_ns: u64,
    next_due: Option<Instant>,
    wrench: Wrench,
    /// `wrench` is the plant's only once one came (its tick 0 says nothing before).
    wrench_seen: bool,
}

/// How long a wait looks at the plant's node between checks (the liveness watcher's period).
const GONE_CHECK: Duration = rig_process::liveness::WATCH_PERIOD;
/// Longest wait for the wrench of the tick whose state arrived (the Rust controller's).
const WRENCH_WAIT: Duration = Duration::from_micros(50);

/// Open rig `rig` as a controller: load the rig's iceoryx2 configuration (the state-directory
/// rule of messages/README.md), open its services with the contract's QoS under the node
/// `<node_role>/<rig>` (NULL: `rig-client`), read `scenario_path` (NULL: the default scenario)
/// for the loop settings, and wait up to `timeout_s` for the plant's first state (which stays
/// unread for `rig_client_wait`). On success `*out` is the client (free it with
/// `rig_client_close`); on error `*out` is NULL and `rig_client_last_error()` says why.
///
/// # Safety
/// `rig` and `out` are valid; `node_role` and `scenario_path` NULL or NUL-terminated strings.
#[no_mangle]
pub unsafe extern "C" fn rig_client_open(
    rig: *const c_char,
    node_role: *const c_char,
    scenario_path: *const c_char,
    timeout_s: f64,
    out: *mut *mut RigClient,
) -> i32 {
    guard(|| {
        if out.is_null() {
            return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: rig_client_open: out is NULL".into());
        }
        // SAFETY: `out` is valid (checked non-NULL; the caller's contract).
        unsafe { *out = std::ptr::null_mut() };
        // SAFETY: the caller's contract on the string arguments.
        let args = unsafe { (str_arg(rig, "rig"), str_arg(node_role, "node_role"), str_arg(scenario_path, "scenario_path")) };
        let (rig, role, path) = match args {
            (Ok(Some(r)), Ok(role), Ok(p)) => (r, role.unwrap_or("rig-client"), p),
            (Ok(None), _, _) => return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: rig_client_open: rig is NULL".into()),
            (Err(c), _, _) | (_, Err(c), _) | (_, _, Err(c)) => return c,
        };
        if !(timeout_s.is_finite() && timeout_s >= 0.0) {
            return fail(RIG_ERR_INVALID_ARGUMENT, format!("rig-client: timeout {timeout_s} s is not a finite, non-negative number"));
        }
        match open(rig, role, path, Duration::from_secs_f64(timeout_s)) {
            Ok(c) => {
                // SAFETY: `out` is valid (checked above).
                unsafe { *out = Box::into_raw(Box::new(c)) };
                RIG_OK
            }
            Err(code) => code,
        }
    })
}

fn open(rig: &str, role: &str, scenario_path: Option<&str>, timeout: Duration) -> Result<RigClient, i32> {
    let s = scenario(scenario_path)?;
    messages::services::validate_rig_name(rig).map_err(|e| fail(RIG_ERR_INVALID_ARGUMENT, format!("rig-client: {e}")))?;
    // A killed peer leaves its shared memory behind.
    rig_process::ports::clean_dead_nodes();
    let ports = ControllerPorts::open(rig, role).map_err(|e| fail(RIG_ERR_OPEN, format!("rig-client: {}", WithCauses(&e))))?;
    let watch = PeerWatch::spawn(rig, &format!("{role}-watch"), Watched::Plant)
        .map_err(|e| fail(RIG_ERR_OPEN, format!("rig-client: {}", WithCauses(&e))))?;
    let until = Instant::now() + timeout;
    while !ports.state_pending() {
        if Instant::now() >= until {
            return Err(fail(
                RIG_ERR_NO_PLANT,
                format!(
                    "rig-client: no joint state on rig {rig:?} within {:.1} s: is plant-sim running on this rig (iceoryx2 configuration {})?",
                    timeout.as_secs_f64(),
                    rig_process::host::config_path().display()
                ),
            ));
        }
        let _ = ports.wait_state(Instant::now() + GONE_CHECK);
    }
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    Ok(RigClient {
        ports,
        watch,
        controller_id: (u64::from(std::process::id()) << 32) | u64::from(nanos),
        spin: Duration::from_secs_f64(s.loop_.controller_spin_us.max(0.0) * 1e-6),
        plant: None,
        last_published: None,
        current_tick: 0,
        woke: Instant::now(),
        woke_mono_ns: 0,
        next_due: None,
        wrench: Wrench { contract_version: CONTRACT_VERSION, frame: 0, tick: 0, force: [0.0; 3], torque: [0.0; 3] },
        wrench_seen: false,
    })
}

/// Close the client (NULL is ignored): its ports and node go, the plant sees the controller leave.
///
/// # Safety
/// `client` is NULL or a pointer from `rig_client_open` not closed before.
#[no_mangle]
pub unsafe extern "C" fn rig_client_close(client: *mut RigClient) {
    if !client.is_null() {
        // SAFETY: from Box::into_raw in rig_client_open, closed once (the caller's contract).
        let c = unsafe { Box::from_raw(client) };
        let _ = catch_unwind(AssertUnwindSafe(move || drop(c)));
    }
}

/// Wait up to `timeout_s` for the next state not yet answered and the wrench of the same tick.
/// Returns `RIG_OK` (answer it), `RIG_SAFE_STOP_TO_ACKNOWLEDGE` (answer it with
/// `RIG_CONTROLLER_STARTING` to leave the reflex hold), `RIG_SHUTTING_DOWN` (the plant's last
/// state: exit 0), `RIG_TIMEOUT`, `RIG_PLANT_GONE`, or `RIG_ERR_CONTRACT_VERSION`. `state` and
/// `wrench` are written on OK, SAFE_STOP_TO_ACKNOWLEDGE and SHUTTING_DOWN. Allocation-free.
///
/// # Safety
/// `client` from `rig_client_open`; `state` and `wrench` valid for writes.
#[no_mangle]
pub unsafe extern "C" fn rig_client_wait(client: *mut RigClient, timeout_s: f64, state: *mut RigJointState, wrench: *mut RigWrench) -> i32 {
    if client.is_null() || state.is_null() || wrench.is_null() {
        return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: rig_client_wait: a NULL argument".into());
    }
    guard(|| {
        // SAFETY: valid, exclusive pointers (the caller's contract).
        let (c, state, wrench) = unsafe { (&mut *client, &mut *state, &mut *wrench) };
        let timeout = if timeout_s.is_finite() && timeout_s > 0.0 { Duration::from_secs_f64(timeout_s) } else { Duration::ZERO };
        c.wait(Instant::now() + timeout, state, wrench)
    })
}

impl RigClient {
    /// The wait of `rig_client_wait`: the Rust controller's wait (`wait_state_spinning`), in
    /// slices of [`GONE_CHECK`] so that a dead plant is told within one.
    pub fn wait(&mut self, deadline: Instant, state: &mut RigJointState, wrench: &mut RigWrench) -> i32 {
        loop {
            let slice = deadline.min(Instant::now() + GONE_CHECK);
            let wake = self.ports.wait_state_spinning(self.next_due.map(|d| (d, self.spin)), slice);
            let woke = Instant::now();
            let woke_mono_ns = rig_process::clock::now_mono_ns();
            let Some((st, origin)) = self.ports.receive_state_with_origin() else {
                if wake == Wake::Timeout {
                    if self.plant.is_some_and(|p| self.watch.is_gone(p)) {
                        return RIG_PLANT_GONE;
                    }
                    if woke >= deadline {
                        return RIG_TIMEOUT;
                    }
                }
                continue;
            };
            match self.plant {
                Some(p) if p != origin => {
                    if !self.watch.is_gone(p) {
                        continue; // another plant's state: not ours
                    }
                    // Ours is gone and a new plant runs: a new connection.
                    self.last_published = None;
                    self.plant = Some(origin);
                    self.watch.follow(origin);
                }
                None => {
                    self.plant = Some(origin);
                    self.watch.follow(origin);
                }
                _ => {}
            }
            if st.contract_version != CONTRACT_VERSION {
                let e = messages::check_version(CONTRACT_VERSION, st.contract_version, "joint state").unwrap_err();
                return fail(RIG_ERR_CONTRACT_VERSION, format!("rig-client: {e}"));
            }
            let lockstep = st.flags & state_flags::LOCKSTEP != 0;
            self.next_due = (!lockstep && !self.spin.is_zero()).then(|| woke + Duration::from_secs_f64(st.period_s));
            if st.plant_status == PlantStatus::ShuttingDown as u32 {
                *state = c_state(&st);
                *wrench = c_wrench(&self.wrench);
                return RIG_SHUTTING_DOWN;
            }
            if self.last_published.is_some_and(|t| st.tick <= t) {
                continue; // answered already (lockstep republishes tick 0 until answered)
            }
            // The wrench of this very tick (plant-sim sends it first; another plant may not).
            let until = Instant::now() + WRENCH_WAIT;
            loop {
                if let Some(w) = self.ports.receive_wrench() {
                    if w.contract_version != CONTRACT_VERSION {
                        let e = messages::check_version(CONTRACT_VERSION, w.contract_version, "wrench").unwrap_err();
                        return fail(RIG_ERR_CONTRACT_VERSION, format!("rig-client: {e}"));
                    }
                    self.wrench = w;
                    self.wrench_seen = true;
                }
                if (self.wrench_seen && self.wrench.tick >= st.tick) || Instant::now() >= until {
                    break;
                }
                std::hint::spin_loop();
            }
            if !self.wrench_seen {
                // No wrench yet: this subscriber connected after the plant sent this tick's, and
                // iceoryx2 hands a late subscriber the history only at the publisher's next send;
                // the plant sends both again (lockstep republishes tick 0 every 5 ms). A zero
                // wrench handed out now is not the plant's (the controller daemon's rule).
                continue;
            }
            self.current_tick = st.tick;
            self.woke = woke;
            self.woke_mono_ns = woke_mono_ns;
            *state = c_state(&st);
            *wrench = c_wrench(&self.wrench);
            return if st.flags & state_flags::REFLEX != 0 { RIG_SAFE_STOP_TO_ACKNOWLEDGE } else { RIG_OK };
        }
    }

    /// The publish of `rig_client_publish`.
    pub fn publish(&mut self, tick: u64, controller_status: u32, tau: &[f64; 6], diag: Option<&RigControllerDiagnostics>) -> i32 {
        let computed_mono_ns = rig_process::clock::now_mono_ns();
        let t = JointTorque { contract_version: CONTRACT_VERSION, controller_status, tick, controller_id: self.controller_id, tau: *tau };
        let mut d = diag.map_or(ControllerDiagnostics::zeroed(CONTRACT_VERSION), contract_diagnostics);
        d.contract_version = CONTRACT_VERSION;
        d.tick = tick;
        if tick == self.current_tick {
            d.woke_mono_ns = self.woke_mono_ns;
            d.compute_time_ns = self.woke.elapsed().as_nanos() as u64;
        }
        d.computed_mono_ns = computed_mono_ns;
        d.published_mono_ns = rig_process::clock::now_mono_ns();
        match self.ports.publish(&t, Some(&d)) {
            Ok(()) => {
                self.last_published = Some(self.last_published.map_or(tick, |l| l.max(tick)));
                RIG_OK
            }
            Err(e) => fail(RIG_ERR_PUBLISH, format!("rig-client: {}", WithCauses(&e))),
        }
    }

    /// When the last wait woke for the state it handed out (the benchmark's reference).
    pub fn last_woke(&self) -> Instant {
        self.woke
    }

    /// The id this client puts in every torque (`pid << 32 | nanoseconds`).
    pub fn controller_id(&self) -> u64 {
        self.controller_id
    }
}

/// Publish the torque `tau` (6 values, N m) answering tick `tick` with `controller_status`
/// (`RIG_CONTROLLER_*`), then wake the plant. Diagnostics go with it: `diag` (NULL: all zero)
/// with `contract_version`, `tick`, `compute_time_ns` and the three stage stamps filled in by the
/// library (woke: when `rig_client_wait` woke for that tick; computed: the call; published: just
/// before sending). Allocation-free.
///
/// # Safety
/// `client` from `rig_client_open`; `tau` points to 6 doubles; `diag` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn rig_client_publish(
    client: *mut RigClient,
    tick: u64,
    controller_status: u32,
    tau: *const f64,
    diag: *const RigControllerDiagnostics,
) -> i32 {
    if client.is_null() || tau.is_null() {
        return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: rig_client_publish: a NULL argument".into());
    }
    guard(|| {
        // SAFETY: valid pointers (the caller's contract): tau holds 6 doubles, diag is NULL or valid.
        let (c, tau, diag) = unsafe { (&mut *client, &*(tau as *const [f64; 6]), diag.as_ref()) };
        c.publish(tick, controller_status, tau, diag)
    })
}

/// The id the client puts in its torques (a change tells the plant another controller took over).
///
/// # Safety
/// `client` NULL or from `rig_client_open`.
#[no_mangle]
pub unsafe extern "C" fn rig_client_controller_id(client: *const RigClient) -> u64 {
    // SAFETY: NULL or valid (the caller's contract).
    unsafe { client.as_ref() }.map_or(0, RigClient::controller_id)
}

/// A static, NUL-terminated name of `code` (never NULL).
#[no_mangle]
pub extern "C" fn rig_client_error_message(code: i32) -> *const c_char {
    let s: &'static CStr = match code {
        RIG_OK => c"ok",
        RIG_TIMEOUT => c"timeout: no new state within the timeout",
        RIG_SHUTTING_DOWN => c"the plant is shutting down (its last state): exit 0",
        RIG_PLANT_GONE => c"the plant is gone (its iceoryx2 node is dead)",
        RIG_SAFE_STOP_TO_ACKNOWLEDGE => c"a reflex safe stop is latched: answer with RIG_CONTROLLER_STARTING to acknowledge it",
        RIG_ERR_NULL_ARGUMENT => c"a required argument is NULL",
        RIG_ERR_INVALID_ARGUMENT => c"an argument is invalid",
        RIG_ERR_SCENARIO => c"the scenario file could not be read or is invalid",
        RIG_ERR_OPEN => c"the rig's iceoryx2 configuration, node or services could not be set up",
        RIG_ERR_NO_PLANT => c"no plant answered on this rig within the timeout",
        RIG_ERR_CONTRACT_VERSION => c"the plant speaks another contract version",
        RIG_ERR_PUBLISH => c"sending to the plant failed",
        RIG_ERR_INTERNAL => c"internal error of the library",
        _ => c"unknown code",
    };
    s.as_ptr()
}

/// The one-sentence detail of this thread's last error ("" if none); valid until this thread's
/// next failing call.
#[no_mangle]
pub extern "C" fn rig_client_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// The rig's robot model for a scenario (libfranka's `Model`): the IRB 2400 with the scenario's
/// tool, armature and viscous friction, as the plant and the Rust controllers build it. Opaque.
pub struct RigModel {
    robot: robot::Robot,
}

impl RigModel {
    /// The model of scenario `s`.
    pub fn from_scenario(s: &scenarios::Scenario) -> RigModel {
        RigModel { robot: scenarios::geometry::nominal_robot(s) }
    }
}

/// Build the robot model of the scenario at `scenario_path` (NULL: the default scenario).
///
/// # Safety
/// `out` valid; `scenario_path` NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rig_model_open(scenario_path: *const c_char, out: *mut *mut RigModel) -> i32 {
    guard(|| {
        if out.is_null() {
            return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: rig_model_open: out is NULL".into());
        }
        // SAFETY: `out` valid (the caller's contract).
        unsafe { *out = std::ptr::null_mut() };
        // SAFETY: the caller's contract on the string.
        let path = match unsafe { str_arg(scenario_path, "scenario_path") } {
            Ok(p) => p,
            Err(c) => return c,
        };
        match scenario(path) {
            Ok(s) => {
                // SAFETY: `out` valid (the caller's contract).
                unsafe { *out = Box::into_raw(Box::new(RigModel::from_scenario(&s))) };
                RIG_OK
            }
            Err(c) => c,
        }
    })
}

/// Free a model (NULL is ignored).
///
/// # Safety
/// `model` NULL or from `rig_model_open`, freed once.
#[no_mangle]
pub unsafe extern "C" fn rig_model_close(model: *mut RigModel) {
    if !model.is_null() {
        // SAFETY: from Box::into_raw in rig_model_open, freed once (the caller's contract).
        drop(unsafe { Box::from_raw(model) });
    }
}

/// # Safety
/// `p` points to 6 doubles.
unsafe fn vec6(p: *const f64) -> Vec6 {
    // SAFETY: 6 readable doubles (the caller's contract).
    Vec6::from(unsafe { *(p as *const [f64; 6]) })
}

/// Write a 6x6 matrix row-major into 36 doubles.
///
/// # Safety
/// `out` points to 36 writable doubles.
unsafe fn put_mat6(m: &robot::Mat6, out: *mut f64) {
    for r in 0..6 {
        for c in 0..6 {
            // SAFETY: index < 36 (the caller's contract).
            unsafe { *out.add(r * 6 + c) = m[(r, c)] };
        }
    }
}

/// # Safety
/// `out` points to 6 writable doubles.
unsafe fn put_vec6(v: &Vec6, out: *mut f64) {
    for (i, x) in v.iter().enumerate() {
        // SAFETY: i < 6 (the caller's contract).
        unsafe { *out.add(i) = *x };
    }
}

fn model_call(model: *const RigModel, ptrs: &[*const f64], f: impl FnOnce(&RigModel) -> i32) -> i32 {
    if model.is_null() || ptrs.iter().any(|p| p.is_null()) {
        return fail(RIG_ERR_NULL_ARGUMENT, "rig-client: a model function got a NULL argument".into());
    }
    // SAFETY: checked non-NULL; valid (the caller's contract).
    guard(|| f(unsafe { &*model }))
}

/// Pose of the TCP (`robot.tool_offset_m` along the flange z) in the base frame at `q`: a 4x4
/// homogeneous transform, row-major, m.
///
/// # Safety
/// `model` from `rig_model_open`; `q` 6 doubles; `pose` 16 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_tcp_pose(model: *const RigModel, q: *const f64, pose: *mut f64) -> i32 {
    model_call(model, &[q, pose], |m| {
        // SAFETY: the caller's contract on `q` and `pose`.
        let t = m.robot.tcp_pose(&unsafe { vec6(q) }).to_homogeneous();
        for r in 0..4 {
            for c in 0..4 {
                // SAFETY: index < 16.
                unsafe { *pose.add(r * 4 + c) = t[(r, c)] };
            }
        }
        RIG_OK
    })
}

/// Geometric Jacobian of the TCP at `q`, base axes, rows vx vy vz wx wy wz: 6x6 row-major.
///
/// # Safety
/// `model` from `rig_model_open`; `q` 6 doubles; `jacobian` 36 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_jacobian_tcp(model: *const RigModel, q: *const f64, jacobian: *mut f64) -> i32 {
    // SAFETY: the caller's contract on the arrays.
    model_call(model, &[q, jacobian], |m| unsafe {
        put_mat6(&m.robot.jacobian_tcp(&vec6(q)), jacobian);
        RIG_OK
    })
}

/// Joint-space mass matrix M(q) (armature included), kg m², 6x6 row-major.
///
/// # Safety
/// `model` from `rig_model_open`; `q` 6 doubles; `mass` 36 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_mass_matrix(model: *const RigModel, q: *const f64, mass: *mut f64) -> i32 {
    // SAFETY: the caller's contract on the arrays.
    model_call(model, &[q, mass], |m| unsafe {
        put_mat6(&m.robot.mass_matrix(&vec6(q)), mass);
        RIG_OK
    })
}

/// Gravity torque g(q), N m.
///
/// # Safety
/// `model` from `rig_model_open`; `q` 6 doubles; `tau` 6 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_gravity(model: *const RigModel, q: *const f64, tau: *mut f64) -> i32 {
    // SAFETY: the caller's contract on the arrays.
    model_call(model, &[q, tau], |m| unsafe {
        put_vec6(&m.robot.gravity_torque(&vec6(q)), tau);
        RIG_OK
    })
}

/// Coriolis and centrifugal torque C(q, q̇) q̇ (the vector, not the matrix), N m.
///
/// # Safety
/// `model` from `rig_model_open`; `q`, `qd` 6 doubles; `tau` 6 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_coriolis(model: *const RigModel, q: *const f64, qd: *const f64, tau: *mut f64) -> i32 {
    // SAFETY: the caller's contract on the arrays.
    model_call(model, &[q, qd, tau], |m| unsafe {
        put_vec6(&m.robot.coriolis_times_qd(&vec6(q), &vec6(qd)), tau);
        RIG_OK
    })
}

/// Inverse dynamics without external wrench (RNEA): M q̈ + C q̇ + g + armature q̈ + viscous q̇, N m.
///
/// # Safety
/// `model` from `rig_model_open`; `q`, `qd`, `qdd` 6 doubles; `tau` 6 writable doubles.
#[no_mangle]
pub unsafe extern "C" fn rig_model_inverse_dynamics(
    model: *const RigModel,
    q: *const f64,
    qd: *const f64,
    qdd: *const f64,
    tau: *mut f64,
) -> i32 {
    // SAFETY: the caller's contract on the arrays.
    model_call(model, &[q, qd, qdd, tau], |m| unsafe {
        put_vec6(&m.robot.rnea(&vec6(q), &vec6(qd), &vec6(qdd)), tau);
        RIG_OK
    })
}

/// A stand-in plant on its own thread for the allocation test and the overhead benchmark: it
/// publishes state + wrench of ticks 0..`ticks` in lockstep (the next tick once the torque of this
/// one arrived, or after 1 s) and then the goodbye. Not part of the C API.
#[doc(hidden)]
pub mod loopback {
    use messages::{JointState, PlantStatus, Wrench, CONTRACT_VERSION};
    use rig_process::ports::PlantPorts;
    use std::time::{Duration, Instant};

    /// A rig name unique to this process and call.
    pub fn unique_rig(tag: &str) -> String {
        let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        format!("rc-{tag}-{}-{}", std::process::id(), n % 1_000_000_000)
    }

    /// Start the plant thread. Like a lockstep plant it repeats tick 0 every 5 ms until answered.
    pub fn spawn(rig: &str, ticks: u64) -> std::thread::JoinHandle<u64> {
        let rig = rig.to_string();
        std::thread::spawn(move || {
            let plant = PlantPorts::open(&rig, "loopback-plant").expect("plant ports");
            let mut answered = 0;
            let q = [0.0, -1.2, 0.4, 0.0, 0.8, 0.0];
            for tick in 0..=ticks {
                let status = if tick == ticks { PlantStatus::ShuttingDown } else { PlantStatus::Running };
                let mut st = JointState::at_rest(tick, status, q);
                st.flags = messages::state_flags::LOCKSTEP;
                let w = Wrench { contract_version: CONTRACT_VERSION, frame: 0, tick, force: [0.0, 0.0, -10.0], torque: [0.0; 3] };
                // The controller may not have subscribed yet: repeat tick 0 until answered.
                loop {
                    plant.publish(&st, &w).expect("publish");
                    if tick == ticks {
                        break;
                    }
                    // Wait until this tick's torque or the deadline: a wake-up may bring another
                    // sample (the diagnostics) or none, and a plant that moved on then ran ahead
                    // of the controller (7 of 1050 ticks unanswered, seen in CI on 2026-12-06).
                    let deadline = Instant::now() + Duration::from_millis(if tick == 0 { 5 } else { 1000 });
                    let got = loop {
                        if plant.receive_torque_for(tick).is_some() {
                            break true;
                        }
                        if Instant::now() >= deadline {
                            break false;
                        }
                        let _ = plant.wait_torque(deadline);
                    };
                    if got {
                        answered += 1;
                        break;
                    }
                    if tick > 0 {
                        break;
                    }
                }
            }
            answered
        })
    }
}
