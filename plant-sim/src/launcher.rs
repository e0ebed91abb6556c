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

    /// [`gone`](Self::gone), waiting up to `grace` for it. PR_SET_PDEATHSIG fires when the
    /// *thread* that started the plant ends; when a launcher is killed, its other threads may
    /// still be on their way out, and until the last one is, the parent is still its PID.
    pub fn gone_within(&self, grace: std::time::Duration) -> bool {
        let until = std::time::Instant::now() + grace;
        while !self.gone() {
            if std::time::Instant::now() >= until {
                return false;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        true
    }

    /// The `/events` text for a plant that its launcher's death stopped.
    pub fn death_note(&self) -> String {
        format!("the launcher (PID {}) ended without stopping the plant; the plant stopped on its parent-death SIGTERM", self.pid)
    }
}
