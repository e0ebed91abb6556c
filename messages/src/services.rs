//! Service names. Every name carries a rig prefix so several rigs (and parallel tests) share a host
//! without seeing each other: `<rig>/joint_state`, `<rig>/wrench`, ...

/// Publish-subscribe: [`crate::JointState`], plant → controller.
pub const JOINT_STATE: &str = "joint_state";
/// Publish-subscribe: [`crate::Wrench`], plant → controller.
pub const WRENCH: &str = "wrench";
/// Publish-subscribe: [`crate::JointTorque`], controller → plant.
pub const JOINT_TORQUE: &str = "joint_torque";
/// Publish-subscribe: [`crate::ControllerDiagnostics`], controller → plant (optional for a controller).
/// Named after its layout's contract version: iceoryx2 refuses to open a service whose payload
/// size differs, so a controller built against version 1 (120-byte diagnostics on
/// `controller_diagnostics`) opens a service of its own, starts, and is refused by contract
/// version, both versions named, instead of failing inside iceoryx2.
pub const CONTROLLER_DIAGNOSTICS: &str = "controller_diagnostics_v2";
/// Event: the plant notifies after publishing state and wrench of a tick.
pub const STATE_READY: &str = "state_ready";
/// Event: the controller notifies after publishing the torque of a tick.
pub const TORQUE_READY: &str = "torque_ready";

/// Longest rig name, bytes.
pub const MAX_RIG_NAME: usize = 64;

/// A rig name that cannot name a rig's services; the message names it and the rule it breaks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RigNameError {
    #[error("rig name {0:?} must be 1..={MAX_RIG_NAME} characters")]
    Length(String),
    #[error("rig name {0:?} may only contain ASCII letters, digits, '_', '-' and '.'")]
    Characters(String),
}

/// Characters allowed in a rig name (it becomes part of shared-memory file names).
pub fn validate_rig_name(rig: &str) -> Result<(), RigNameError> {
    if rig.is_empty() || rig.len() > MAX_RIG_NAME {
        return Err(RigNameError::Length(rig.to_string()));
    }
    if !rig.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.') {
        return Err(RigNameError::Characters(rig.to_string()));
    }
    Ok(())
}

/// Full iceoryx2 service name `<rig>/<service>`.
pub fn service_name(rig: &str, service: &str) -> String {
    format!("rig/{rig}/{service}")
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn names_carry_the_rig_prefix() {
        assert_eq!(service_name("a1", JOINT_STATE), "rig/a1/joint_state");
        assert_ne!(service_name("a1", WRENCH), service_name("a2", WRENCH));
        assert!(validate_rig_name("test-17_x").is_ok());
        assert_eq!(validate_rig_name("bad/name"), Err(RigNameError::Characters("bad/name".into())));
        assert_eq!(validate_rig_name(""), Err(RigNameError::Length(String::new())));
        assert!(validate_rig_name(&"x".repeat(MAX_RIG_NAME)).is_ok());
        assert_eq!(
            validate_rig_name(&"x".repeat(MAX_RIG_NAME + 1)).unwrap_err().to_string(),
            format!("rig name {:?} must be 1..=64 characters", "x".repeat(MAX_RIG_NAME + 1))
        );
    }
}
