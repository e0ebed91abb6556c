//! The process that started the plant (`rig`, a shell, a test). `rig` gives its daemons
//! PR_SET_PDEATHSIG = SIGTERM, so a plant stopped by a signal whose parent has changed was stopped
//! because its launcher died: the recording says so, instead of a bare "stopped (signal)".

/// The parent as it was when the plant started.
#[derive(Debug, Clone, Copy)]
pub struct Launcher {
    pub pid: i32,
}

impl Launcher {
    pub fn now() -> Self {
        // SAFETY: getppid has no preconditions.
        Launcher { pid: unsafe { libc::getppid() } }
    }

    /// True once the launcher has ended (this process was reparented).
    pub fn gone(&self) -> bool {
        // SAFETY: as above.
        unsafe { libc::getppid() != self.pid }
    }

    /// The `/events` text for a plant that its launcher's death stopped.
    pub fn death_note(&self) -> String {
        format!("the launcher (PID {}) ended without stopping the plant; the plant stopped on its parent-death SIGTERM", self.pid)
    }
}
