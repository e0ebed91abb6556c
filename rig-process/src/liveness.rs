//! Is a peer dead? iceoryx2 raises no error when the process behind a publisher dies; its node's
//! liveness (the node monitor) says so. [`PeerWatch`] asks on its own thread every
//! [`WATCH_PERIOD`] (the node list is a directory scan, no place for the 1 kHz path) and answers
//! the loop through atomics: the loop stores the publisher it follows ([`PeerWatch::follow`]) and
//! reads whether that publisher's node is gone ([`PeerWatch::is_gone`]), both lock-free.
//!
//! A publisher is *gone* when its node is dead (SIGKILL, crash) or no longer exists, or when the
//! publisher left the service (the peer dropped it). A stalled but living peer (SIGSTOP, a host
//! stall) is not gone: silence alone never means death (DESIGN section 10).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use iceoryx2::prelude::*;

use crate::ports::PortError;
use messages::services;

/// How often the node list is read: a dead peer is seen within this plus the scan, well inside
/// the 100 ms the contract promises.
pub const WATCH_PERIOD: Duration = Duration::from_millis(10);

/// A 128-bit id in two atomics, with a sequence word so a reader never sees a torn pair.
#[derive(Default)]
struct AtomicId {
    seq: AtomicU64,
    hi: AtomicU64,
    lo: AtomicU64,
}

impl AtomicId {
    /// Single writer.
    fn store(&self, v: u128) {
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s.wrapping_add(1), Ordering::Release);
        self.hi.store((v >> 64) as u64, Ordering::Release);
        self.lo.store(v as u64, Ordering::Release);
        self.seq.store(s.wrapping_add(2), Ordering::Release);
    }
    fn load(&self) -> u128 {
        loop {
            let s0 = self.seq.load(Ordering::Acquire);
            let hi = self.hi.load(Ordering::Acquire);
            let lo = self.lo.load(Ordering::Acquire);
            if s0.is_multiple_of(2) && self.seq.load(Ordering::Acquire) == s0 {
                return (u128::from(hi) << 64) | u128::from(lo);
            }
            std::hint::spin_loop();
        }
    }
}

#[derive(Default)]
struct Shared {
    /// Publisher the loop follows (0 = none).
    followed: AtomicId,
    /// The followed publisher found gone by the watcher (0 = none).
    gone: AtomicId,
    /// Another publisher of the same node as the followed one, on the companion service (the
    /// controller's diagnostics publisher next to its torque publisher), 0 = unknown.
    companion: AtomicId,
    stop: AtomicBool,
}

/// Watches the node behind one publisher of a rig service. Dropping it stops the thread.
pub struct PeerWatch {
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// A [`PeerWatch`] whose thread is still setting up. Dropping it stops the thread.
pub struct StartingWatch {
    watch: PeerWatch,
    ready: std::sync::mpsc::Receiver<Result<(), PortError>>,
    rig: String,
}

impl StartingWatch {
    /// Wait until the thread's node and services are open: the watch, or why they are not.
    pub fn ready(self) -> Result<PeerWatch, PortError> {
        match self.ready.recv() {
            Ok(Ok(())) => Ok(self.watch),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(PortError::WatcherEnded { rig: self.rig, watcher: "peer" }),
        }
    }
}

/// Which service's publishers are watched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Watched {
    /// The plant, through its `joint_state` publisher (a controller watches this).
    Plant,
    /// Controllers, through their `joint_torque` publishers, with their `controller_diagnostics`
    /// publishers as companions (the plant watches this).
    Controllers,
}

impl PeerWatch {
    /// Start the watcher thread for rig `rig` and wait until its set-up is done. It opens its own
    /// iceoryx2 node (`role` names it), since iceoryx2's IPC ports belong to the thread that made
    /// them.
    pub fn spawn(rig: &str, role: &str, watched: Watched) -> Result<PeerWatch, PortError> {
        PeerWatch::start(rig, role, watched)?.ready()
    }

    /// [`PeerWatch::spawn`] without the wait: the thread opens its node and services while the
    /// caller opens its own ports ([`StartingWatch::ready`] then waits). Both are mostly file
    /// creation and syncs in iceoryx2's state directory; one after the other they were 20-27 ms
    /// of the plant's start-up, the watch 3-7 ms of it (2026-12-06).
    pub fn start(rig: &str, role: &str, watched: Watched) -> Result<StartingWatch, PortError> {
        let shared = Arc::new(Shared::default());
        let (tx, rx) = std::sync::mpsc::channel::<Result<(), PortError>>();
        let (rig_s, role_s, sh) = (rig.to_string(), role.to_string(), shared.clone());
        let thread = std::thread::Builder::new()
            .name("peer-watch".into())
            .spawn(move || watch_thread(&rig_s, &role_s, watched, &sh, &tx))
            .map_err(|source| PortError::Spawn { rig: rig.to_string(), watcher: "peer", source })?;
        Ok(StartingWatch { watch: PeerWatch { shared, thread: Some(thread) }, ready: rx, rig: rig.to_string() })
    }

    /// Follow publisher `id` (a sample's origin); 0 follows none. Lock-free.
    pub fn follow(&self, id: u128) {
        if self.shared.followed.load() != id {
            self.shared.followed.store(id);
        }
    }

    /// True once the watcher saw the node of publisher `id` dead or gone. Lock-free.
    pub fn is_gone(&self, id: u128) -> bool {
        id != 0 && self.shared.gone.load() == id
    }

    /// The followed peer's publisher on the companion service, 0 while unknown. Lock-free.
    pub fn companion(&self) -> u128 {
        self.shared.companion.load()
    }

    /// Asks the thread to end without waiting for it: it tears its iceoryx2 node down while
    /// the caller drops its own ports (the drop then joins it).
    pub fn stop_soon(&self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = &self.thread {
            t.thread().unpark();
        }
    }
}

impl Drop for PeerWatch {
    /// Stops the thread at once: it waits for its next scan parked, not asleep, so the unpark
    /// ends the wait (a plain sleep cost the plant's exit up to a whole [`WATCH_PERIOD`]).
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

use crate::ports::{pubsub as open, PsFactory as Factory};

/// The node of publisher `id` on a service, if it is registered there.
fn node_of<T: core::fmt::Debug + ZeroCopySend + Copy>(f: &Factory<T>, id: u128) -> Option<u128> {
    let mut node = None;
    f.dynamic_config().list_publishers(|d| {
        if d.publisher_id.value() == id {
            node = Some(d.node_id.value());
            return CallbackProgression::Stop;
        }
        CallbackProgression::Continue
    });
    node
}

/// A publisher of node `node` on a service, if any.
fn publisher_of_node<T: core::fmt::Debug + ZeroCopySend + Copy>(f: &Factory<T>, node: u128) -> Option<u128> {
    let mut id = None;
    f.dynamic_config().list_publishers(|d| {
        if d.node_id.value() == node {
            id = Some(d.publisher_id.value());
            return CallbackProgression::Stop;
        }
        CallbackProgression::Continue
    });
    id
}

/// The monitoring concept of iceoryx2's IPC service (a file lock per node).
type Monitor = <ipc::Service as iceoryx2::service::Service>::Monitoring;

/// iceoryx2's own monitor of ONE node: the same dead-node detection as `Node::list`, without its
/// cost. `Node::list` reads and parses every node's details file and Debug-formats the whole
/// configuration once per node on every call (iceoryx2 0.10, node/mod.rs `get_node_details`):
/// 1-2 ms of CPU per scan with the rig's half-dozen nodes, every [`WATCH_PERIOD`], in both
/// daemons: on two cores that preempted the 1 kHz threads (issue 22). This asks the one node's
/// monitor (a stat, an open, a read, a lock test).
struct NodeMonitor {
    node: u128,
    monitor: Option<<Monitor as Monitoring>::Monitor>,
}

use iceoryx2::prelude::FileName;
use iceoryx2_cal::monitoring::{Monitoring, MonitoringBuilder, MonitoringMonitor, MonitoringStateError, State};
use iceoryx2_cal::named_concept::{NamedConceptBuilder, NamedConceptConfiguration, NamedConceptMgmt};

impl NodeMonitor {
    fn open(config: &Config, node: u128) -> NodeMonitor {
        // The configuration iceoryx2 builds for its node monitors (service/config_scheme.rs
        // `node_monitoring_config`); the monitor's name is the node id in decimal (as `Node::list`
        // parses it back).
        let cfg = <<Monitor as NamedConceptMgmt>::Configuration>::default()
            .prefix(&config.global.prefix)
            .suffix(&config.global.node.monitor_suffix)
            .path_hint(&config.global.node_dir());
        let monitor = FileName::new(node.to_string().as_bytes())
            .ok()
            .and_then(|name| <Monitor as Monitoring>::Builder::new(&name).config(&cfg).monitor().ok());
        NodeMonitor { node, monitor }
    }

    /// Is the node alive? Dead, vanished or undefined nodes are not (as in `Node::list`); one
    /// whose monitor cannot be read for lack of permission counts as alive (`Inaccessible`), and
    /// so does one whose check a signal interrupted: the next period asks again.
    fn alive(&self) -> bool {
        let Some(m) = &self.monitor else { return false };
        match m.state() {
            Ok(State::Alive) => true,
            Ok(State::Dead | State::DoesNotExist) => false,
            Err(MonitoringStateError::InsufficientPermissions | MonitoringStateError::Interrupt) => true,
            Err(MonitoringStateError::InternalError) => false,
        }
    }
}

fn watch_thread(rig: &str, role: &str, watched: Watched, sh: &Shared, ready: &std::sync::mpsc::Sender<Result<(), PortError>>) {
    let setup = (|| -> Result<_, PortError> {
        let node = crate::ports::node(rig, role)?;
        let (main, companion) = match watched {
            Watched::Plant => (Either::State(open::<messages::JointState>(&node, rig, services::JOINT_STATE)?), None),
            Watched::Controllers => (
                Either::Torque(open::<messages::JointTorque>(&node, rig, services::JOINT_TORQUE)?),
                Some(open::<messages::ControllerDiagnostics>(&node, rig, services::CONTROLLER_DIAGNOSTICS)?),
            ),
        };
        Ok((node, main, companion))
    })();
    let (node, main, companion) = match setup {
        Ok(x) => {
            let _ = ready.send(Ok(()));
            x
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    let mut known: (u128, u128) = (0, 0); // (followed publisher, its node)
    let mut monitor: Option<NodeMonitor> = None;
    let mut next_scan = std::time::Instant::now() + WATCH_PERIOD;
    while !sh.stop.load(Ordering::Acquire) {
        // Parked until the next scan; `Drop` unparks it to stop (a spurious wake-up parks again).
        let now = std::time::Instant::now();
        if now < next_scan {
            std::thread::park_timeout(next_scan - now);
            continue;
        }
        next_scan = now + WATCH_PERIOD;
        let followed = sh.followed.load();
        if followed == 0 || sh.gone.load() == followed {
            continue;
        }
        let node_id = match &main {
            Either::State(f) => node_of(f, followed),
            Either::Torque(f) => node_of(f, followed),
        };
        let gone = match node_id {
            Some(n) => {
                if known != (followed, n) {
                    // Found once the companion publisher exists (a controller may open it later).
                    match companion.as_ref().map(|c| publisher_of_node(c, n)) {
                        Some(Some(c)) => {
                            sh.companion.store(c);
                            known = (followed, n);
                        }
                        Some(None) => sh.companion.store(0),
                        None => known = (followed, n),
                    }
                }
                if monitor.as_ref().is_none_or(|m| m.node != n) {
                    monitor = Some(NodeMonitor::open(node.config(), n));
                }
                !monitor.as_ref().is_some_and(NodeMonitor::alive)
            }
            None => true,
        };
        if gone {
            sh.gone.store(followed);
        }
    }
}

enum Either {
    State(Factory<messages::JointState>),
    Torque(Factory<messages::JointTorque>),
}
