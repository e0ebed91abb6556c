//! Did the controller a launcher started ever connect? (issue 27, item 4)
//!
//! A controller that does not load the rig's iceoryx2 configuration, opens another rig's name,
//! speaks another contract version or hangs before opening anything never answers a state, and
//! the plant cannot tell why (in lockstep it republishes tick 0 forever). [`ConnectWatch`] runs
//! on its own thread with its own node (`rig-connect/<rig>`): it watches the plant's states and
//! the torque service until a state shows that the plant applied an answer (or a torque of this
//! contract version arrives), and otherwise, at the connect timeout, looks at the rig's nodes
//! and the torque service's publishers for what the controller process did ([`NotConnected`]).
//! It ends (and drops its node) as soon as the controller connected: no cost during the run.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

use crate::ports::{PortError, PsFactory};
use messages::{services, JointState, JointTorque, PlantStatus, CONTRACT_VERSION};

/// What a launcher saw of a controller process that answered no state within the connect timeout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NotConnected {
    /// No iceoryx2 node of that process in the rig's configuration (it loaded another
    /// configuration, iceoryx2's defaults included, or has not created its node yet).
    NoNode,
    /// Its node is named for another rig (`role/<other rig>`).
    OtherRig { node: String, rig: String },
    /// Its node is on this rig but has no publisher on the torque service.
    NoTorquePublisher { node: String },
    /// Torques of another contract version arrived (the plant refuses them).
    OtherVersion { version: u32 },
    /// A torque publisher of this process exists but sent nothing.
    Silent { node: String },
}

impl NotConnected {
    /// A code for the plant's `/events` entry (`plant_sim::signals::ControllerEnd::NeverConnected`).
    pub fn code(&self) -> u8 {
        match self {
            NotConnected::NoNode => 0,
            NotConnected::OtherRig { .. } => 1,
            NotConnected::NoTorquePublisher { .. } => 2,
            NotConnected::OtherVersion { .. } => 3,
            NotConnected::Silent { .. } => 4,
        }
    }

    /// What was seen, for the plant's `/events` entry, by [`Self::code`].
    pub fn what(code: u8) -> &'static str {
        match code {
            0 => "no iceoryx2 node of it on this rig",
            1 => "its iceoryx2 node is on another rig",
            2 => "an iceoryx2 node of it but no torque publisher",
            3 => "torques of another contract version",
            _ => "a torque publisher of it that sent nothing",
        }
    }

    /// "what was seen; the likely fix", the tail of the launcher's sentence.
    pub fn explain(&self, rig: &str) -> String {
        let cfg = crate::host::config_path();
        match self {
            NotConnected::NoNode => format!(
                "it has no iceoryx2 node of rig {rig:?} in the rig's iceoryx2 configuration; load that configuration, {}, before creating its node (messages/README.md, \"iceoryx2 configuration\"), or, if it is only slow to start, raise loop.connect_timeout_s",
                cfg.display()
            ),
            NotConnected::OtherRig { node, rig: other } => format!(
                "its iceoryx2 node {node:?} is on rig {other:?}, not {rig:?}; open the rig its --rig argument names"
            ),
            NotConnected::NoTorquePublisher { node } => format!(
                "its iceoryx2 node {node:?} has no publisher on {}; publish each answer there (messages/README.md, \"Services of one rig\")",
                services::service_name(rig, services::JOINT_TORQUE)
            ),
            NotConnected::OtherVersion { version } => format!(
                "it publishes torques of contract version {version}, which the plant refuses (it speaks version {CONTRACT_VERSION}); build it against contract version {CONTRACT_VERSION} (messages/README.md, \"Versioning\")"
            ),
            NotConnected::Silent { node } => format!(
                "its iceoryx2 node {node:?} has a torque publisher but sent no torque; answer every joint state with a torque of the same tick and notify torque_ready (messages/README.md, \"One tick\")"
            ),
        }
    }
}

/// Watches one rig until its controller connects. Dropping it stops the thread.
pub struct ConnectWatch {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<Option<NotConnected>>>,
}

/// How often the states and torques are looked at.
const POLL: Duration = Duration::from_millis(10);

impl ConnectWatch {
    /// Start watching rig `rig` for the controller process `pid`; the verdict comes
    /// `timeout` after the plant's first state ([`Self::verdict`]). Start it before the controller, so that no early
    /// torque goes unseen.
    pub fn spawn(rig: &str, pid_of: Arc<std::sync::atomic::AtomicU32>, timeout: Duration) -> Result<ConnectWatch, PortError> {
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel::<Result<(), PortError>>();
        let (rig_s, st) = (rig.to_string(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("connect-watch".into())
            .spawn(move || watch(&rig_s, &pid_of, timeout, &st, &tx))
            .map_err(|source| PortError::Spawn { rig: rig.to_string(), watcher: "connect", source })?;
        match rx.recv() {
            Ok(Ok(())) => Ok(ConnectWatch { stop, thread: Some(thread) }),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(PortError::WatcherEnded { rig: rig.to_string(), watcher: "connect" }),
        }
    }

    /// A flag that ends the watch when set: the supervisor sets it when the run ends otherwise
    /// (a plant that dies before its first state would leave the watch, and `rig`'s exit
    /// waiting on it, running for good).
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Block until the controller connected (None) or the timeout passed (what was seen).
    pub fn verdict(mut self) -> Option<NotConnected> {
        self.thread.take().and_then(|t| t.join().ok()).flatten()
    }
}

impl Drop for ConnectWatch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

fn watch(
    rig: &str,
    pid_of: &std::sync::atomic::AtomicU32,
    timeout: Duration,
    stop: &AtomicBool,
    ready: &std::sync::mpsc::Sender<Result<(), PortError>>,
) -> Option<NotConnected> {
    let setup = (|| -> Result<_, PortError> {
        let node = crate::ports::node(rig, "rig-connect")?;
        let state = crate::ports::pubsub::<JointState>(&node, rig, services::JOINT_STATE)?;
        let torque = crate::ports::pubsub::<JointTorque>(&node, rig, services::JOINT_TORQUE)?;
        let state_sub =
            state.subscriber_builder().create().map_err(|e| crate::ports::err(rig, "the connect watcher's state subscriber", e))?;
        let torque_sub =
            torque.subscriber_builder().create().map_err(|e| crate::ports::err(rig, "the connect watcher's torque subscriber", e))?;
        Ok((node, torque, state_sub, torque_sub))
    })();
    let (node, torque, state_sub, torque_sub) = match setup {
        Ok(x) => {
            let _ = ready.send(Ok(()));
            x
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return None;
        }
    };
    // The timeout counts from the plant's first state: before it (a strip model being built, for
    // seconds or minutes) there is nothing to answer.
    let mut until: Option<Instant> = None;
    let mut other_version = None;
    while !stop.load(Ordering::Acquire) {
        while let Ok(Some(s)) = state_sub.receive() {
            until.get_or_insert_with(|| Instant::now() + timeout);
            // Running or holding: the plant applied an answer (refused ones lead to the safe
            // stop without either).
            if s.plant_status == PlantStatus::Running as u32 || s.plant_status == PlantStatus::HoldingTorque as u32 {
                return None;
            }
        }
        while let Ok(Some(t)) = torque_sub.receive() {
            if t.contract_version == CONTRACT_VERSION {
                return None;
            }
            other_version = Some(t.contract_version);
        }
        if until.is_some_and(|u| Instant::now() >= u) {
            let pid = pid_of.load(Ordering::Acquire);
            return Some(diagnose(rig, &node, &torque, pid, other_version));
        }
        std::thread::sleep(POLL);
    }
    None
}

/// What the rig's iceoryx2 state says of process `pid`.
fn diagnose(rig: &str, node: &Node<ipc::Service>, torque: &PsFactory<JointTorque>, pid: u32, other_version: Option<u32>) -> NotConnected {
    if let Some(version) = other_version {
        return NotConnected::OtherVersion { version };
    }
    // The nodes of that process (name, id).
    let mut nodes: Vec<(String, u128)> = Vec::new();
    let _ = Node::<ipc::Service>::list(node.config(), |state| {
        if let NodeState::<ipc::Service>::Alive(view) = state {
            let of_pid = view.id().pid::<ipc::Service>().is_ok_and(|p| p.value() as i64 == i64::from(pid));
            if of_pid {
                let name = view.details().as_ref().map(|d| d.name().as_str().to_string()).unwrap_or_default();
                nodes.push((name, view.id().value()));
            }
        }
        CallbackProgression::Continue
    });
    let suffix = format!("/{rig}");
    let Some((name, id)) = nodes.iter().find(|(n, _)| n.ends_with(&suffix)).or(nodes.first()).cloned() else {
        return NotConnected::NoNode;
    };
    if !name.ends_with(&suffix) {
        let other = name.rsplit_once('/').map_or(String::new(), |(_, r)| r.to_string());
        return NotConnected::OtherRig { node: name, rig: other };
    }
    let mut has_publisher = false;
    torque.dynamic_config().list_publishers(|p| {
        has_publisher |= p.node_id.value() == id;
        CallbackProgression::Continue
    });
    if has_publisher {
        NotConnected::Silent { node: name }
    } else {
        NotConnected::NoTorquePublisher { node: name }
    }
}
