//! The two ends of a rig's services, opened with the QoS of [`messages::qos`].
//!
//! [`PlantPorts`] is what the plant (or the replay tool acting as a plant) opens;
//! [`ControllerPorts`] is what a controller opens. Both wake on an iceoryx2 event whose listener
//! file descriptor is waited on with `ppoll` against an absolute deadline: iceoryx2's own timed
//! waits resolve only whole milliseconds on this platform, too coarse for a 500 µs torque budget.
//!
//! Everything after `open` is allocation-free and lock-free (`ipc::Service` ports are
//! single-threaded), so these calls may sit on the 1 kHz path.

use iceoryx2::prelude::*;
use messages::{qos, services, ControllerDiagnostics, JointState, JointTorque, Wrench};
use std::time::{Duration, Instant};

type Pub<T> = iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>;
type Sub<T> = iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>;
type Notifier = iceoryx2::port::notifier::Notifier<ipc::Service>;
type Listener = iceoryx2::port::listener::Listener<ipc::Service>;

/// Failure to open or use a rig's services. The message names the rig and the step; the
/// iceoryx2 (or OS) error behind it is its `source()`, so that `{:#}` chains (or
/// [`WithCauses`]) print it once.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// The rig name cannot name services.
    #[error(transparent)]
    RigName(#[from] services::RigNameError),
    /// The host is not fit for a rig (its iceoryx2 configuration, shared memory).
    #[error(transparent)]
    Host(#[from] crate::host::HostError),
    /// iceoryx2 could not create the rig's node.
    #[error(
        "rig {rig:?}: iceoryx2 could not create its node: check that {} has room and is writable and that {} is yours; if the rig's files vanish while it runs, systemd-logind removes a user's IPC at logout (set RemoveIPC=no)",
        crate::host::SHM_DIR,
        .state_dir.display()
    )]
    Node { rig: String, state_dir: std::path::PathBuf, source: iceoryx2::node::NodeCreationFailure },
    /// iceoryx2 refused one step (`what`: "open service joint_state", "send wrench", ...).
    #[error("rig {rig:?}: {what}")]
    Iceoryx2 { rig: String, what: String, source: Box<dyn std::error::Error + Send + Sync> },
    /// A watcher thread (`watcher`: "peer", "connect") could not be started.
    #[error("rig {rig:?}: start the {watcher} watcher")]
    Spawn { rig: String, watcher: &'static str, source: std::io::Error },
    /// A watcher thread ended before it said whether its set-up worked.
    #[error("rig {rig:?}: the {watcher} watcher ended at start-up")]
    WatcherEnded { rig: String, watcher: &'static str },
}

/// iceoryx2 refused step `what` of rig `rig`.
pub(crate) fn err(rig: &str, what: &str, e: impl std::error::Error + Send + Sync + 'static) -> PortError {
    PortError::Iceoryx2 { rig: rig.to_string(), what: what.to_string(), source: Box::new(e) }
}

/// An error and its causes on one line, `error: cause: cause` (as anyhow's `{:#}` prints them),
/// for the places that print an error without anyhow.
pub struct WithCauses<'a>(pub &'a (dyn std::error::Error + 'static));

impl std::fmt::Display for WithCauses<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)?;
        let mut cause = self.0.source();
        while let Some(c) = cause {
            write!(f, ": {c}")?;
            cause = c.source();
        }
        Ok(())
    }
}

/// Remove the shared-memory resources of iceoryx2 nodes whose process died (a killed plant or
/// controller leaves them behind). Returns how many dead nodes were cleaned.
pub fn clean_dead_nodes() -> usize {
    let Ok(cfg) = crate::host::iceoryx2_config() else { return 0 };
    let mut cleaned = 0;
    let _ = Node::<ipc::Service>::list(cfg, |state| {
        if let NodeState::<ipc::Service>::Dead(view) = state {
            if view.try_remove_stale_resources().is_ok() {
                cleaned += 1;
            }
        }
        CallbackProgression::Continue
    });
    cleaned
}

/// The iceoryx2 node of one role on one rig (`<role>/<rig>`), as every port of this crate opens it.
pub(crate) fn node(rig: &str, role: &str) -> Result<Node<ipc::Service>, PortError> {
    // The rig's own configuration (messages/iceoryx2.toml, per user; it also sets iceoryx2's log
    // level to errors unless IOX2_LOG_LEVEL asks for more).
    let cfg = crate::host::iceoryx2_config()?;
    let name = format!("{role}/{rig}");
    let name: NodeName = name.as_str().try_into().map_err(|e| err(rig, "node name", e))?;
    // Our daemons handle SIGINT/SIGTERM themselves (finalise the recording, say goodbye).
    let node = NodeBuilder::new()
        .name(&name)
        .config(cfg)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|source| PortError::Node { rig: rig.to_string(), state_dir: crate::host::state_dir(), source })?;
    crate::host::lock_down_global_mgmt(cfg)?;
    Ok(node)
}

fn service_name(rig: &str, svc: &str) -> Result<ServiceName, PortError> {
    services::validate_rig_name(rig)?;
    services::service_name(rig, svc).as_str().try_into().map_err(|e| err(rig, svc, e))
}

/// Open (or create) publish-subscribe service `svc` of rig `rig` with the contract's QoS, one
/// setting a line as iceoryx2's examples write it (every peer must ask for the same values).
pub(crate) fn pubsub<T: core::fmt::Debug + ZeroCopySend + Copy>(
    node: &Node<ipc::Service>,
    rig: &str,
    svc: &str,
) -> Result<PsFactory<T>, PortError> {
    let name = service_name(rig, svc)?;
    let builder = || {
        node.service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(qos::MAX_PUBLISHERS)
            .max_subscribers(qos::MAX_SUBSCRIBERS)
            .max_nodes(qos::MAX_NODES)
            .subscriber_max_buffer_size(qos::SUBSCRIBER_BUFFER)
            .subscriber_max_borrowed_samples(qos::MAX_BORROWED_SAMPLES)
            .history_size(qos::HISTORY)
            .enable_safe_overflow(qos::SAFE_OVERFLOW)
    };
    open_or_create_quickly(|| builder().open(), || builder().create(), || builder().open_or_create())
        .map_err(|e| err(rig, &format!("open service {svc}"), e))
}

/// How long [`open_or_create_quickly`] retries before it leaves the port to iceoryx2, and how
/// long it sleeps between two tries.
const QUICK_OPEN_WINDOW: Duration = Duration::from_millis(50);
const QUICK_OPEN_RETRY: Duration = Duration::from_micros(200);

/// An iceoryx2 open error that may only mean "nobody has created it yet".
trait OpenError {
    fn does_not_exist(&self) -> bool;
}

/// An iceoryx2 create error that may only mean "another process created it, or is creating it".
trait CreateError {
    fn created_elsewhere(&self) -> bool;
}

use iceoryx2::service::builder::{event as ev, publish_subscribe as ps};

impl OpenError for ps::PublishSubscribeOpenError {
    fn does_not_exist(&self) -> bool {
        *self == Self::DoesNotExist
    }
}

impl OpenError for ev::EventOpenError {
    fn does_not_exist(&self) -> bool {
        *self == Self::DoesNotExist
    }
}

impl CreateError for ps::PublishSubscribeCreateError {
    fn created_elsewhere(&self) -> bool {
        matches!(self, Self::AlreadyExists | Self::IsBeingCreatedByAnotherInstance)
    }
}

impl CreateError for ev::EventCreateError {
    fn created_elsewhere(&self) -> bool {
        matches!(self, Self::AlreadyExists | Self::IsBeingCreatedByAnotherInstance)
    }
}

/// Open a service, or create it, retrying every [`QUICK_OPEN_RETRY`] while another process is
/// creating it; when that does not settle within [`QUICK_OPEN_WINDOW`] or either call fails
/// otherwise, iceoryx2's `open_or_create` decides, and its outcome and error are the ones
/// reported. Why: iceoryx2 0.10's `open_or_create` sleeps a fixed 25 ms (its `IO_TICK_TIME`)
/// whenever it finds the service in creation by another process, and a run starts the plant,
/// `rig`'s connect watch and the controller at once, all opening the same services: that sleep
/// was most of the plant's 15-37 ms `ports_ms` and delayed the controller's first answer to
/// 29-53 ms after launch (2026-12-06).
fn open_or_create_quickly<S, OE: OpenError, CE: CreateError, E>(
    open: impl Fn() -> Result<S, OE>,
    create: impl Fn() -> Result<S, CE>,
    open_or_create: impl FnOnce() -> Result<S, E>,
) -> Result<S, E> {
    let until = Instant::now() + QUICK_OPEN_WINDOW;
    loop {
        match open() {
            Ok(s) => return Ok(s),
            Err(e) if e.does_not_exist() => {}
            Err(_) => break,
        }
        match create() {
            Ok(s) => return Ok(s),
            Err(e) if e.created_elsewhere() => {}
            Err(_) => break,
        }
        if Instant::now() >= until {
            break;
        }
        std::thread::sleep(QUICK_OPEN_RETRY);
    }
    open_or_create()
}

fn event(
    node: &Node<ipc::Service>,
    rig: &str,
    svc: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, PortError> {
    let name = service_name(rig, svc)?;
    let builder = || {
        node.service_builder(&name)
            .event()
            .max_notifiers(qos::MAX_NOTIFIERS)
            .max_listeners(qos::MAX_LISTENERS)
            .max_nodes(qos::MAX_NODES)
            .event_id_max_value(qos::EVENT_ID_MAX)
    };
    open_or_create_quickly(|| builder().open(), || builder().create(), || builder().open_or_create()).map_err(|e| err(rig, svc, e))
}

fn publisher<T: core::fmt::Debug + ZeroCopySend + Copy>(
    f: &iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
    rig: &str,
) -> Result<Pub<T>, PortError> {
    f.publisher_builder().create().map_err(|e| err(rig, "create publisher", e))
}

fn subscriber<T: core::fmt::Debug + ZeroCopySend + Copy>(
    f: &iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
    rig: &str,
) -> Result<Sub<T>, PortError> {
    f.subscriber_builder().buffer_size(qos::SUBSCRIBER_BUFFER).create().map_err(|e| err(rig, "create subscriber", e))
}

/// Drain a subscriber and keep the newest sample (older ones are stale by construction).
fn newest<T: core::fmt::Debug + ZeroCopySend + Copy>(sub: &Sub<T>) -> Option<T> {
    let mut last = None;
    while let Ok(Some(s)) = sub.receive() {
        last = Some(*s);
    }
    last
}

/// Drain a subscriber, keeping the newest sample whose `tick` satisfies `want`.
fn newest_matching<T: core::fmt::Debug + ZeroCopySend + Copy>(sub: &Sub<T>, mut want: impl FnMut(&T) -> bool) -> Option<T> {
    let mut last = None;
    while let Ok(Some(s)) = sub.receive() {
        if want(&s) {
            last = Some(*s);
        }
    }
    last
}

/// Wait until `fd` is readable or the absolute `deadline` passes (monotonic clock, ns precision).
/// Returns true if readable. A signal ends the wait early (the daemons catch only SIGINT/SIGTERM,
/// their stop requests): a lockstep plant whose controller died with it would otherwise sit out
/// its whole watchdog before it looks at its stop flag.
pub fn wait_readable(fd: i32, deadline: Instant) -> bool {
    loop {
        let now = Instant::now();
        if now >= deadline {
            // One last non-blocking check so an event that arrived exactly at the deadline counts.
            return poll_once(fd, Duration::ZERO);
        }
        let rem = deadline - now;
        let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
        let ts = libc::timespec { tv_sec: rem.as_secs() as libc::time_t, tv_nsec: rem.subsec_nanos() as libc::c_long };
        // SAFETY: one valid pollfd, valid timespec, no signal mask change.
        let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
        if r > 0 {
            return true;
        }
        if r == 0 {
            continue; // timed out: the loop head re-checks the deadline
        }
        if std::io::Error::last_os_error().raw_os_error() == Some(libc::EINTR) {
            return poll_once(fd, Duration::ZERO);
        }
        return false;
    }
}

fn poll_once(fd: i32, d: Duration) -> bool {
    let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
    let ts = libc::timespec { tv_sec: d.as_secs() as libc::time_t, tv_nsec: d.subsec_nanos() as libc::c_long };
    // SAFETY: as above.
    unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) > 0 }
}

/// The one way this crate waits on an iceoryx2 event: drain `listener` until a drain finds no
/// activation, then look for the data (`pending`), and only then sleep on the listener's `fd`
/// until it is readable or `deadline`.
///
/// Why (issue 22): in iceoryx2 0.10 a listener's notifiers share one notification state
/// (idle → pending → notified). `notify` activates its event id, moves idle → pending, sends a
/// datagram and only then marks "notified"; while the state is "notified" it sends no datagram.
/// A drain (`try_wait`) that finds "notified" moves it to idle and then empties the socket: the
/// datagram of a `notify` that runs in between is eaten, and that notifier's late "notified"
/// mark lands on an empty socket. From then on `notify` returns Ok and sends nothing, and a
/// waiter sleeping on the fd (ppoll here, epoll in iceoryx2's WaitSet) is not woken until
/// something drains the listener. The old waits drained only after a wake-up, so once in that
/// state every later tick waited for its 1 ms slice. Draining before the sleep clears a mark
/// that has landed; draining once more whenever a drain found activations also disarms one that
/// has not landed yet (that drain finds the state "pending" and sets it idle, so the late mark's
/// compare-exchange fails): the eaten datagram's activation is always counted by the drain that
/// ate it. Looking for the data after the drains keeps an answer whose notification they
/// consumed from being slept through. The minimal program: `tests/src/bin/iox2_lost_wakeup.rs`.
fn drain_then_wait(listener: &Listener, fd: i32, deadline: Instant, pending: impl Fn() -> bool) -> Wake {
    // Bounded: a peer notifying without pause must not keep us here (the caller's slice is the
    // backstop then).
    for _ in 0..MAX_DRAINS {
        if listener.try_wait(|_| {}).unwrap_or(0) == 0 {
            break;
        }
    }
    if pending() || wait_readable(fd, deadline) {
        Wake::Notified
    } else {
        Wake::Timeout
    }
}

/// Most drains of one [`drain_then_wait`] (each after one that found activations).
const MAX_DRAINS: usize = 4;

fn listener_fd(l: &Listener) -> i32 {
    use iceoryx2_bb_posix::file_descriptor::FileDescriptorBased;
    // SAFETY: the fd lives as long as the listener, which outlives every use through `self`.
    unsafe { l.file_descriptor().native_handle() }
}

/// One controller's answer to a tick, with the iceoryx2 id of the publisher that sent it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Answer {
    pub origin: u128,
    pub torque: JointTorque,
}

/// The answers to one tick, at most one per publisher (fixed capacity: the service's publishers).
#[derive(Debug, Clone, Copy, Default)]
pub struct Answers {
    items: [Option<Answer>; qos::MAX_PUBLISHERS],
}

impl Answers {
    /// Keep `a`, replacing an older answer of the same publisher; beyond capacity it is dropped.
    pub fn insert(&mut self, a: Answer) {
        if let Some(slot) = self.items.iter_mut().find(|x| x.is_some_and(|x| x.origin == a.origin)) {
            *slot = Some(a);
        } else if let Some(slot) = self.items.iter_mut().find(|x| x.is_none()) {
            *slot = Some(a);
        }
    }
    pub fn clear(&mut self) {
        self.items = [None; qos::MAX_PUBLISHERS];
    }
    pub fn iter(&self) -> impl Iterator<Item = &Answer> {
        self.items.iter().flatten()
    }
    pub fn from_origin(&self, origin: u128) -> Option<&Answer> {
        self.iter().find(|a| a.origin == origin)
    }
    pub fn is_empty(&self) -> bool {
        self.items.iter().all(Option::is_none)
    }
}

/// Outcome of waiting for the peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// The peer notified (new data may be there).
    Notified,
    /// The deadline passed without a notification.
    Timeout,
}

pub(crate) type PsFactory<T> = iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// Every service of one rig, opened (or created) with the contract's QoS by one node. Both ends
/// open the same set and differ only in which ports they take from it.
struct RigServices {
    state: PsFactory<JointState>,
    wrench: PsFactory<Wrench>,
    torque: PsFactory<JointTorque>,
    diag: PsFactory<ControllerDiagnostics>,
    state_ready: EventFactory,
    torque_ready: EventFactory,
    // Last: the node must outlive its services.
    _node: Node<ipc::Service>,
}

impl RigServices {
    fn open(rig: &str, role: &str) -> Result<Self, PortError> {
        let node = node(rig, role)?;
        Ok(Self {
            state: pubsub(&node, rig, services::JOINT_STATE)?,
            wrench: pubsub(&node, rig, services::WRENCH)?,
            torque: pubsub(&node, rig, services::JOINT_TORQUE)?,
            diag: pubsub(&node, rig, services::CONTROLLER_DIAGNOSTICS)?,
            state_ready: event(&node, rig, services::STATE_READY)?,
            torque_ready: event(&node, rig, services::TORQUE_READY)?,
            _node: node,
        })
    }

    fn listener(f: &EventFactory, rig: &str) -> Result<Listener, PortError> {
        f.listener_builder().create().map_err(|e| err(rig, "create listener", e))
    }

    fn notifier(f: &EventFactory, rig: &str) -> Result<Notifier, PortError> {
        f.notifier_builder().create().map_err(|e| err(rig, "create notifier", e))
    }
}

/// The plant's end: publishes state and wrench, receives torques and diagnostics.
pub struct PlantPorts {
    rig: String,
    state_pub: Pub<JointState>,
    wrench_pub: Pub<Wrench>,
    torque_sub: Sub<JointTorque>,
    diag_sub: Sub<ControllerDiagnostics>,
    state_ready: Notifier,
    torque_ready: Listener,
    torque_fd: i32,
    // Last: ports must drop before their services and node.
    _services: RigServices,
}

impl PlantPorts {
    /// Open (or create) every service of rig `rig` as the plant. `role` names the node
    /// (e.g. "plant-sim" or "replay").
    pub fn open(rig: &str, role: &str) -> Result<Self, PortError> {
        let s = RigServices::open(rig, role)?;
        let torque_ready = RigServices::listener(&s.torque_ready, rig)?;
        Ok(Self {
            rig: rig.to_string(),
            state_pub: publisher(&s.state, rig)?,
            wrench_pub: publisher(&s.wrench, rig)?,
            torque_sub: subscriber(&s.torque, rig)?,
            diag_sub: subscriber(&s.diag, rig)?,
            state_ready: RigServices::notifier(&s.state_ready, rig)?,
            torque_fd: listener_fd(&torque_ready),
            torque_ready,
            _services: s,
        })
    }

    pub fn rig(&self) -> &str {
        &self.rig
    }

    /// Publish wrench and state of one tick, then wake the controller. The wrench goes first: a
    /// controller that polls for the state (shared memory, no notification) then finds that
    /// tick's wrench already there, even if this thread is preempted between the two sends.
    pub fn publish(&self, state: &JointState, wrench: &Wrench) -> Result<(), PortError> {
        self.wrench_pub.send_copy(*wrench).map_err(|e| err(&self.rig, "send wrench", e))?;
        self.state_pub.send_copy(*state).map_err(|e| err(&self.rig, "send joint state", e))?;
        self.state_ready.notify().map_err(|e| err(&self.rig, "notify state_ready", e))?;
        Ok(())
    }

    /// Wait for a torque until the absolute `deadline`: drain the listener first, return at once
    /// if a torque waits in the subscriber, else sleep on the listener's fd. See
    /// [`drain_then_wait`] for why the drain comes before the sleep. The notification that ends
    /// the sleep is left for the next call to drain.
    pub fn wait_torque(&self, deadline: Instant) -> Wake {
        drain_then_wait(&self.torque_ready, self.torque_fd, deadline, || self.torque_sub.has_samples().unwrap_or(false))
    }

    /// Drain the torque listener: the number of notifications (iceoryx2 activations) it held.
    pub fn drain_torque_events(&self) -> u64 {
        self.torque_ready.try_wait(|_| {}).unwrap_or(0)
    }

    /// Newest torque whose `tick` equals `tick` (older answers are discarded).
    pub fn receive_torque_for(&self, tick: u64) -> Option<JointTorque> {
        newest_matching(&self.torque_sub, |t| t.tick == tick)
    }

    /// Drain the torque subscriber into `answers`: every answer to `tick`, the newest per publisher
    /// (iceoryx2 publisher id, [`Answer::origin`]); answers already in `answers` are kept, so
    /// repeated calls within a tick accumulate. Older ticks are discarded. Allocation-free.
    pub fn receive_answers(&self, tick: u64, answers: &mut Answers) {
        while let Ok(Some(s)) = self.torque_sub.receive() {
            if s.tick == tick {
                answers.insert(Answer { origin: s.origin().value(), torque: *s });
            }
        }
    }

    /// Newest controller diagnostics of tick `tick` from publisher `origin` (0 = any publisher),
    /// and the newest of an earlier tick (a late answer's, whose stage stamps tell why it was
    /// late). Allocation-free.
    pub fn receive_diagnostics_from(&self, origin: u128, tick: u64) -> (Option<ControllerDiagnostics>, Option<ControllerDiagnostics>) {
        let (mut now, mut late) = (None, None);
        while let Ok(Some(s)) = self.diag_sub.receive() {
            if origin == 0 || s.origin().value() == origin {
                if s.tick == tick {
                    now = Some(*s);
                } else if s.tick < tick {
                    late = Some(*s);
                }
            }
        }
        (now, late)
    }

    /// Newest torque of any tick (late answers included): for diagnostics and version checks.
    pub fn receive_torque_any(&self) -> Option<JointTorque> {
        newest(&self.torque_sub)
    }

    /// Newest controller diagnostics, if the controller publishes any.
    pub fn receive_diagnostics(&self) -> Option<ControllerDiagnostics> {
        newest(&self.diag_sub)
    }
}

/// The controller's end: receives state and wrench, publishes torques and diagnostics.
pub struct ControllerPorts {
    rig: String,
    state_sub: Sub<JointState>,
    wrench_sub: Sub<Wrench>,
    torque_pub: Pub<JointTorque>,
    diag_pub: Pub<ControllerDiagnostics>,
    torque_ready: Notifier,
    state_ready: Listener,
    state_fd: i32,
    _services: RigServices,
}

impl ControllerPorts {
    /// Open (or create) every service of rig `rig` as a controller.
    pub fn open(rig: &str, role: &str) -> Result<Self, PortError> {
        let s = RigServices::open(rig, role)?;
        let state_ready = RigServices::listener(&s.state_ready, rig)?;
        Ok(Self {
            rig: rig.to_string(),
            state_sub: subscriber(&s.state, rig)?,
            wrench_sub: subscriber(&s.wrench, rig)?,
            torque_pub: publisher(&s.torque, rig)?,
            diag_pub: publisher(&s.diag, rig)?,
            torque_ready: RigServices::notifier(&s.torque_ready, rig)?,
            state_fd: listener_fd(&state_ready),
            state_ready,
            _services: s,
        })
    }

    pub fn rig(&self) -> &str {
        &self.rig
    }

    /// Wait for a state until the absolute `deadline`: drain the listener first, return at once
    /// if a state waits in the subscriber, else sleep on the listener's fd ([`drain_then_wait`]).
    pub fn wait_state(&self, deadline: Instant) -> Wake {
        drain_then_wait(&self.state_ready, self.state_fd, deadline, || self.state_pending())
    }

    /// Wait for the next state until `deadline`. With `spin = Some((due, w))` (real time), sleep in
    /// `ppoll` until `due − w`, then poll the subscriber's shared memory until `due + w`, then sleep
    /// again. A vCPU that halted in `ppoll` needs tens of µs to wake on the plant's notification (the
    /// round trip pays it twice); a thread already awake at the due time sees the state within a µs,
    /// for a bounded `2 w` of CPU per tick (the other process keeps the rest of both cores). The
    /// controller daemon and the C client library (`rig-client`) wait with this one function.
    pub fn wait_state_spinning(&self, spin: Option<(Instant, Duration)>, deadline: Instant) -> Wake {
        if let Some((due, w)) = spin {
            let from = due.checked_sub(w).unwrap_or(due).min(deadline);
            if self.wait_state(from) == Wake::Notified || self.state_pending() {
                return Wake::Notified;
            }
            let until = (due + w).min(deadline);
            while Instant::now() < until {
                if self.state_pending() {
                    // Its notification stays in the listener: the next wait drains it before it
                    // sleeps (`drain_then_wait`), off the path from the state to the torque.
                    return Wake::Notified;
                }
                std::hint::spin_loop();
            }
        }
        self.wait_state(deadline)
    }

    /// True when a joint state waits in the subscriber. Reads shared memory only (no syscall):
    /// what a controller busy-polls in the short window around a state's due time, where waking
    /// from `ppoll` would cost a halted vCPU's wake-up (tens of µs on a VM).
    pub fn state_pending(&self) -> bool {
        self.state_sub.has_samples().unwrap_or(false)
    }

    /// Newest joint state (older ones are stale).
    pub fn receive_state(&self) -> Option<JointState> {
        newest(&self.state_sub)
    }

    /// Newest joint state with the iceoryx2 id of the publisher that sent it (which plant).
    pub fn receive_state_with_origin(&self) -> Option<(JointState, u128)> {
        let mut last = None;
        while let Ok(Some(s)) = self.state_sub.receive() {
            last = Some((*s, s.origin().value()));
        }
        last
    }

    /// Newest wrench whose tick equals `tick`, else the newest of any tick.
    pub fn receive_wrench(&self) -> Option<Wrench> {
        newest(&self.wrench_sub)
    }

    /// Publish the diagnostics (optional) and the torque of one tick, then wake the plant.
    /// Diagnostics go first: a plant that polls sees the torque only once its diagnostics are there.
    pub fn publish(&self, torque: &JointTorque, diag: Option<&ControllerDiagnostics>) -> Result<(), PortError> {
        if let Some(d) = diag {
            self.diag_pub.send_copy(*d).map_err(|e| err(&self.rig, "send diagnostics", e))?;
        }
        self.torque_pub.send_copy(*torque).map_err(|e| err(&self.rig, "send joint torque", e))?;
        self.torque_ready.notify().map_err(|e| err(&self.rig, "notify torque_ready", e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use messages::CONTRACT_VERSION;

    fn unique_rig(tag: &str) -> String {
        let n = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos();
        format!("t-{tag}-{}-{}", std::process::id(), n % 1_000_000_000)
    }

    fn state(tick: u64) -> JointState {
        JointState::at_rest(tick, messages::PlantStatus::Running, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    }

    /// Plant and controller opening the same rig at the same instant (as `rig run` starts them):
    /// whichever creates each service, the other opens it, and the ports connect. 20 rigs.
    #[test]
    fn plant_and_controller_opening_at_once_connect() {
        for round in 0..20u64 {
            let rig = unique_rig(&format!("race{round}"));
            // Both open at once, then both wait until the other has opened; the controller keeps
            // its ports until the plant has its torque.
            let (go, opened) = (std::sync::Barrier::new(2), std::sync::Barrier::new(2));
            let (done, plant_done) = std::sync::mpsc::channel::<()>();
            let plant_done = std::sync::Mutex::new(plant_done);
            std::thread::scope(|s| {
                s.spawn(|| {
                    go.wait();
                    let plant = PlantPorts::open(&rig, "race-plant").unwrap();
                    opened.wait();
                    let w = Wrench { contract_version: CONTRACT_VERSION, frame: 0, tick: round, force: [1.0, 2.0, 3.0], torque: [0.0; 3] };
                    plant.publish(&state(round), &w).unwrap();
                    assert_eq!(plant.wait_torque(Instant::now() + Duration::from_secs(2)), Wake::Notified, "round {round}");
                    assert_eq!(plant.receive_torque_for(round).unwrap().controller_id, 9, "round {round}");
                    done.send(()).unwrap();
                });
                s.spawn(|| {
                    go.wait();
                    let ctrl = ControllerPorts::open(&rig, "race-controller").unwrap();
                    opened.wait();
                    assert_eq!(ctrl.wait_state(Instant::now() + Duration::from_secs(2)), Wake::Notified, "round {round}");
                    assert_eq!(ctrl.receive_state().unwrap().tick, round);
                    let t = JointTorque {
                        contract_version: CONTRACT_VERSION,
                        controller_status: 0,
                        tick: round,
                        controller_id: 9,
                        tau: [1.0; 6],
                    };
                    ctrl.publish(&t, None).unwrap();
                    let _ = plant_done.lock().unwrap().recv_timeout(Duration::from_secs(5));
                });
            });
        }
    }

    #[test]
    fn round_trip_between_plant_and_controller_ports() {
        let rig = unique_rig("rt");
        let plant = PlantPorts::open(&rig, "test-plant").unwrap();
        let ctrl = ControllerPorts::open(&rig, "test-controller").unwrap();
        let w = Wrench { contract_version: CONTRACT_VERSION, frame: 0, tick: 5, force: [1.0, 2.0, 3.0], torque: [0.0; 3] };
        plant.publish(&state(5), &w).unwrap();
        assert_eq!(ctrl.wait_state(Instant::now() + Duration::from_secs(1)), Wake::Notified);
        let s = ctrl.receive_state().unwrap();
        assert_eq!(s.tick, 5);
        assert_eq!(s.q, state(5).q);
        assert_eq!(ctrl.receive_wrench().unwrap().force, [1.0, 2.0, 3.0]);
        let t = JointTorque { contract_version: CONTRACT_VERSION, controller_status: 0, tick: 5, controller_id: 9, tau: [1.0; 6] };
        ctrl.publish(&t, None).unwrap();
        assert_eq!(plant.wait_torque(Instant::now() + Duration::from_secs(1)), Wake::Notified);
        assert_eq!(plant.receive_torque_for(5).unwrap().controller_id, 9);
    }

    #[test]
    fn wait_times_out_at_a_sub_millisecond_deadline() {
        let rig = unique_rig("to");
        let plant = PlantPorts::open(&rig, "test-plant").unwrap();
        let t0 = Instant::now();
        assert_eq!(plant.wait_torque(t0 + Duration::from_micros(300)), Wake::Timeout);
        // Correctness, not timing: the wait must not return before its deadline.
        assert!(t0.elapsed() >= Duration::from_micros(300));
    }

    #[test]
    fn stale_answers_are_not_taken_for_the_current_tick() {
        let rig = unique_rig("st");
        let plant = PlantPorts::open(&rig, "test-plant").unwrap();
        let ctrl = ControllerPorts::open(&rig, "test-controller").unwrap();
        let mut t = JointTorque { contract_version: CONTRACT_VERSION, controller_status: 0, tick: 3, controller_id: 1, tau: [0.0; 6] };
        ctrl.publish(&t, None).unwrap();
        t.tick = 4;
        ctrl.publish(&t, None).unwrap();
        assert!(plant.receive_torque_for(5).is_none());
    }

    #[test]
    fn two_rigs_do_not_see_each_other() {
        let (a, b) = (unique_rig("a"), unique_rig("b"));
        let pa = PlantPorts::open(&a, "test-plant").unwrap();
        let cb = ControllerPorts::open(&b, "test-controller").unwrap();
        let w = Wrench { contract_version: CONTRACT_VERSION, frame: 0, tick: 1, force: [0.0; 3], torque: [0.0; 3] };
        pa.publish(&state(1), &w).unwrap();
        assert_eq!(cb.wait_state(Instant::now() + Duration::from_millis(20)), Wake::Timeout);
        assert!(cb.receive_state().is_none());
    }
}
