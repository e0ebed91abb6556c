//! What a rig needs from its host, checked before any iceoryx2 node exists, so that each failure
//! is one sentence with its fix instead of a SIGBUS or an iceoryx2 error code:
//!
//! - [`iceoryx2_config`]: the rig's own iceoryx2 configuration (`messages/iceoryx2.toml`, filled in
//!   per user), kept in an owner-only state directory ([`state_dir`]);
//! - [`check_shared_memory`]: `/dev/shm` exists, is writable and has room for a rig;
//! - [`claim_plant`]: one plant per rig name (an advisory lock, then iceoryx2's node list);
//! - [`exit_on_sigbus`]: the last guard if shared memory runs out after the check;
//! - [`die_with_parent`]: daemons started by a launcher end with it.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

/// Exit status of a daemon refused because a live plant already runs the rig (sysexits
/// EX_UNAVAILABLE).
pub const EXIT_RIG_TAKEN: i32 = 69;
/// Exit status of a daemon that found shared memory unusable (missing, read-only, full, or a
/// SIGBUS on it; sysexits EX_OSERR).
pub const EXIT_SHARED_MEMORY: i32 = 71;

/// Where iceoryx2 0.10 keeps its shared memory on Linux (its compile-time
/// `SHARED_MEMORY_DIRECTORY`; the configuration cannot move it).
pub const SHM_DIR: &str = "/dev/shm";

/// Shared memory one running rig holds in [`SHM_DIR`]: 17 files (4 data segments, 6 dynamic
/// service configs, 2 event managements, 4 connections, the global management segment) that
/// occupy 19 tmpfs pages of 4 KiB. Measured with `ls -ls /dev/shm` during a run of plant-sim and
/// controller on a private tmpfs (apparent sizes 33,592 bytes).
pub const RIG_SHM_BYTES: u64 = 19 * 4096;

/// Free space a daemon asks for before it creates its node: four rigs' worth, so that a second
/// controller, larger pages or another rig starting at the same moment still fit (a tmpfs that
/// runs out delivers SIGBUS on the first touch of a mapped page).
pub const SHM_REQUIRED_BYTES: u64 = 4 * RIG_SHM_BYTES;

/// Longest state directory: iceoryx2 puts its event sockets in `<dir>/iox2/`, named
/// `<prefix><node id>.event`, and a Unix socket path has 108 bytes: 40 + 6 + 22 (prefix for a
/// 5-digit uid) + 33 (node id digits, with room to grow) + 6 + NUL = 108.
pub const MAX_STATE_DIR_LEN: usize = 40;

/// The shipped template of the rig's iceoryx2 configuration.
pub const CONFIG_TEMPLATE: &str = messages::ICEORYX2_CONFIG_TEMPLATE;

/// Environment variable that moves the state directory (every peer of a rig must see the same).
pub const STATE_DIR_ENV: &str = "RIG_ICEORYX2_DIR";

/// The OS or iceoryx2 error behind a [`HostError`], shared so that the error can be kept once
/// per process (the configuration is set up once) and handed to every caller.
pub type Cause = Arc<dyn std::error::Error + Send + Sync>;

/// A host problem that stops a daemon; [`HostError::exit_code`] is the status it should end
/// with. The message is one sentence with its fix; the OS or iceoryx2 error behind it is its
/// `source()`, so that `{:#}` chains print it once.
#[derive(Debug, Clone, thiserror::Error)]
pub enum HostError {
    /// Shared memory or the rig's state directory is unusable ([`EXIT_SHARED_MEMORY`]): `what`
    /// says what and how to fix it.
    #[error("{what}")]
    SharedMemory {
        what: String,
        #[source]
        source: Option<Cause>,
    },
    /// A live plant already runs rig `rig` ([`EXIT_RIG_TAKEN`]); `pid` is that plant's, if known.
    #[error("rig {rig:?} is already running ({}); start this plant with another --rig name, or stop that one first", holder(.pid))]
    RigTaken { rig: String, pid: Option<i32> },
}

impl HostError {
    /// The exit status a daemon ends with on this error (sysexits).
    pub fn exit_code(&self) -> i32 {
        match self {
            HostError::SharedMemory { .. } => EXIT_SHARED_MEMORY,
            HostError::RigTaken { .. } => EXIT_RIG_TAKEN,
        }
    }
}

/// Who holds a taken rig, for [`HostError::RigTaken`]'s message.
fn holder(pid: &Option<i32>) -> String {
    pid.map_or("another plant".to_string(), |p| format!("the plant with PID {p}"))
}

fn shm_error(what: String) -> HostError {
    HostError::SharedMemory { what, source: None }
}

/// [`shm_error`] with the error behind it.
fn shm_error_from(what: String, source: impl std::error::Error + Send + Sync + 'static) -> HostError {
    HostError::SharedMemory { what, source: Some(Arc::new(source)) }
}

fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() }
}

/// The user's state directory: the iceoryx2 root path, the effective config and the plants'
/// lock files live there, mode 0700. `$RIG_ICEORYX2_DIR` if set; else `/run/rig-iceoryx2` for
/// root (only root can create entries in /run) and `/run/user/<uid>/rig-iceoryx2` for a user with
/// a login runtime directory (the user's own, mode 0700): there no other user can take the name
/// first. Else `/tmp/rig-iceoryx2-<uid>`, which another user could create first (refused, with
/// the fix).
pub fn state_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(STATE_DIR_ENV).filter(|d| !d.is_empty()) {
        return d.into();
    }
    let uid = euid();
    if uid == 0 {
        return "/run/rig-iceoryx2".into();
    }
    let run_user = PathBuf::from(format!("/run/user/{uid}"));
    if std::fs::metadata(&run_user).is_ok_and(|m| m.is_dir() && m.uid() == uid) {
        return run_user.join("rig-iceoryx2");
    }
    PathBuf::from(format!("/tmp/rig-iceoryx2-{uid}"))
}

/// Path of the effective iceoryx2 configuration every peer loads.
pub fn config_path() -> PathBuf {
    state_dir().join("iceoryx2.toml")
}

/// Create `dir` (mode 0700) or check that it is a directory of ours that nobody else can enter.
fn private_dir(dir: &Path) -> Result<(), HostError> {
    if dir.as_os_str().len() > MAX_STATE_DIR_LEN {
        return Err(shm_error(format!(
            "the rig's state directory {} is longer than {MAX_STATE_DIR_LEN} bytes, too long for iceoryx2's socket paths: set {STATE_DIR_ENV} to a shorter one",
            dir.display()
        )));
    }
    private_dir_as(dir, "the rig's state directory")
}

/// [`private_dir`] without the length check, `what` naming the directory in its messages.
fn private_dir_as(dir: &Path, what: &str) -> Result<(), HostError> {
    let uid = euid();
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
        std::fs::DirBuilder::new().recursive(true).mode(0o700).create(parent).map_err(|e| {
            shm_error_from(
                format!("cannot create {} for the rig's iceoryx2 files; set {STATE_DIR_ENV} to a directory of yours", parent.display()),
                e,
            )
        })?;
    }
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => {
            return Err(shm_error_from(
                format!("cannot create {what} {}; make its parent writable or set {STATE_DIR_ENV} to a directory of yours", dir.display()),
                e,
            ))
        }
    }
    let m = std::fs::symlink_metadata(dir).map_err(|e| shm_error_from(format!("cannot inspect {}", dir.display()), e))?;
    if !m.is_dir() || m.uid() != uid {
        return Err(shm_error(format!(
            "{what} {} is not a directory owned by you (uid {uid}; it belongs to uid {}): if another user created it first, remove it; or set {STATE_DIR_ENV} to a directory of yours",
            dir.display(),
            m.uid()
        )));
    }
    if m.mode() & 0o077 != 0 {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
            .map_err(|e| shm_error_from(format!("cannot make {} owner-only", dir.display()), e))?;
    }
    Ok(())
}

/// Where iceoryx2 keeps a rig's node, service and socket files: `<state dir>/iox2` when the state
/// directory is on a tmpfs (as `/run` is on most hosts), else `/dev/shm/<prefix>iox2`, an
/// owner-only directory named with the configuration's random prefix. iceoryx2 creates, syncs and
/// removes a few dozen files there per run: on an ext4 mounted with `discard` (this project's CI
/// VM has `/run` there) the ports of each daemon took 15-36 ms to open against 4-12 ms on a tmpfs
/// (2026-12-07, README "Lockstep start-up").
fn iceoryx2_root(state_dir: &Path, prefix: &str) -> PathBuf {
    if is_tmpfs(state_dir) {
        state_dir.join("iox2")
    } else {
        Path::new(SHM_DIR).join(format!("{prefix}iox2"))
    }
}

/// True if `dir` is on a tmpfs (false if it cannot be inspected).
fn is_tmpfs(dir: &Path) -> bool {
    let Ok(c) = std::ffi::CString::new(dir.as_os_str().as_encoded_bytes()) else { return false };
    // SAFETY: statfs fills the zeroed struct we own; c is a valid C string.
    let mut st: libc::statfs = unsafe { std::mem::zeroed() };
    // SAFETY: as above.
    unsafe { libc::statfs(c.as_ptr(), &mut st) == 0 && st.f_type == libc::TMPFS_MAGIC }
}

/// The root path a configuration's text names (`root-path = "..."`), without its trailing slash.
fn root_path_of(config_text: &str) -> Option<PathBuf> {
    let line = config_text.lines().find(|l| l.starts_with("root-path"))?;
    let value = line.split_once('=')?.1.trim().trim_matches('"');
    Some(PathBuf::from(value.trim_end_matches('/')))
}

/// The template with this user's root path and a fresh random prefix.
fn effective_config_text(dir: &Path) -> Result<String, HostError> {
    let mut random = [0u8; 6];
    File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut random))
        .map_err(|e| shm_error_from("cannot read /dev/urandom for the rig's iceoryx2 prefix".into(), e))?;
    let hex: String = random.iter().map(|b| format!("{b:02x}")).collect();
    let prefix = format!("rig{}_{hex}_", euid());
    let root = iceoryx2_root(dir, &prefix);
    let mut out = String::from("# Written by the rig from messages/iceoryx2.toml for this user; load it, do not edit it.\n");
    for line in CONFIG_TEMPLATE.lines() {
        if line.starts_with("root-path") {
            out += &format!("root-path = \"{}/\"\n", root.display());
        } else if line.starts_with("prefix") {
            out += &format!("prefix = \"{prefix}\"\n");
        } else {
            out += line;
            out.push('\n');
        }
    }
    Ok(out)
}

/// Write the effective config once per state directory: to a temporary file, then hard-linked
/// into place, so that two daemons starting together agree on one prefix.
fn ensure_config_file(dir: &Path) -> Result<PathBuf, HostError> {
    let path = dir.join("iceoryx2.toml");
    if !path.exists() {
        let tmp = dir.join(format!(".iceoryx2.toml.{}", std::process::id()));
        let text = effective_config_text(dir)?;
        let written = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .open(&tmp)
            .and_then(|mut f| f.write_all(text.as_bytes()));
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            return Err(shm_error_from(format!("cannot write the rig's iceoryx2 configuration to {}", dir.display()), e));
        }
        let linked = std::fs::hard_link(&tmp, &path);
        let _ = std::fs::remove_file(&tmp);
        if let Err(e) = linked {
            if e.kind() != std::io::ErrorKind::AlreadyExists {
                return Err(shm_error_from(format!("cannot install {}", path.display()), e));
            }
        }
    }
    Ok(path)
}

/// The rig's iceoryx2 configuration, set up as this process's global one on first use (before
/// anything else touches iceoryx2; that also keeps iceoryx2's "No config file was loaded"
/// warning away).
pub fn iceoryx2_config() -> Result<&'static Config, HostError> {
    static CONFIG: OnceLock<Result<&'static Config, HostError>> = OnceLock::new();
    CONFIG
        .get_or_init(|| {
            set_log_level_from_env_or(LogLevel::Error);
            let dir = state_dir();
            private_dir(&dir)?;
            let path = ensure_config_file(&dir)?;
            let wanted = std::fs::read_to_string(&path).map_err(|e| shm_error_from(format!("cannot read {}", path.display()), e))?;
            // A root path outside the state directory (on /dev/shm) is made, or checked, owner-only
            // before iceoryx2 uses it; it goes when the host reboots while the configuration stays.
            if let Some(root) = root_path_of(&wanted).filter(|r| !r.starts_with(&dir)) {
                private_dir_as(&root, "the rig's iceoryx2 directory")?;
            }
            let fp = FilePath::new(path.as_os_str().as_encoded_bytes()).map_err(|e| {
                shm_error_from(format!("{} is not a path iceoryx2 accepts; set {STATE_DIR_ENV} to a shorter one", path.display()), e)
            })?;
            let cfg = Config::setup_global_config_from_file(&fp).map_err(|e| {
                shm_error_from(
                    format!("iceoryx2 refused its configuration {}; remove the file, the next daemon writes it anew", path.display()),
                    e,
                )
            })?;
            // setup_global_config_from_file returns an earlier global config silently.
            if !wanted.contains(&format!("prefix = \"{}\"", cfg.global.prefix)) {
                return Err(shm_error(format!("iceoryx2 was used before the rig loaded {} (a bug of this program)", path.display())));
            }
            Ok(cfg)
        })
        .clone()
}

/// Check that [`SHM_DIR`] exists, is writable and has [`SHM_REQUIRED_BYTES`] free.
pub fn check_shared_memory() -> Result<(), HostError> {
    check_shared_memory_at(Path::new(SHM_DIR))
}

fn check_shared_memory_at(dir: &Path) -> Result<(), HostError> {
    let d = dir.display();
    if !std::fs::metadata(dir).is_ok_and(|m| m.is_dir()) {
        return Err(shm_error(format!(
            "{d} does not exist: iceoryx2 keeps the rig's shared memory there; mount a tmpfs (`mount -t tmpfs -o size=64m tmpfs {d}`), or start the container with one (`docker run --shm-size=64m`)"
        )));
    }
    let c = std::ffi::CString::new(dir.as_os_str().as_encoded_bytes()).map_err(|e| shm_error_from(format!("{d}: bad path"), e))?;
    // SAFETY: statvfs fills the zeroed struct we own; c is a valid C string.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: c is a valid NUL-terminated path and st a statvfs we own.
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return Err(shm_error_from(format!("cannot inspect {d}"), std::io::Error::last_os_error()));
    }
    if st.f_flag & libc::ST_RDONLY != 0 {
        return Err(shm_error(format!(
            "{d} is mounted read-only, so the rig cannot create its shared memory: remount it read-write (`mount -o remount,rw {d}`), or start the container with a writable one (`docker run --shm-size=64m`)"
        )));
    }
    // SAFETY: as above.
    if unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) } != 0 {
        return Err(shm_error_from(
            format!("{d} is not writable for uid {}: make it a tmpfs with mode 1777 (`chmod 1777 {d}`)", euid()),
            std::io::Error::last_os_error(),
        ));
    }
    let free = st.f_bavail as u64 * st.f_frsize as u64;
    if free < SHM_REQUIRED_BYTES {
        return Err(shm_error(format!(
            "{d} has {} KiB free, too little for a rig (it holds {} KiB while it runs; {} KiB are asked for): free space there (`ls -l {d}` shows what holds it), or enlarge it (`mount -o remount,size=64m {d}`; Docker: `docker run --shm-size=64m`); if the rig's files vanish while it runs, systemd-logind removes a user's IPC at logout: set RemoveIPC=no in /etc/systemd/logind.conf",
            free / 1024,
            RIG_SHM_BYTES / 1024,
            SHM_REQUIRED_BYTES / 1024
        )));
    }
    Ok(())
}

/// Everything a daemon checks before its first node: shared memory, then the configuration
/// (which may put iceoryx2's directory on `/dev/shm`, so a full or read-only one is said first).
pub fn prepare() -> Result<&'static Config, HostError> {
    check_shared_memory()?;
    iceoryx2_config()
}

/// iceoryx2 creates its global management segment (`*.global_mgmt` in [`SHM_DIR`]) world-writable
/// (0666) on purpose, for other users' nodes; the rig's segment carries the rig's own prefix, so
/// make it owner-only. Refuses a segment with our prefix that belongs to another user.
pub fn lock_down_global_mgmt(cfg: &Config) -> Result<(), HostError> {
    let prefix = cfg.global.prefix.to_string();
    let Ok(entries) = std::fs::read_dir(SHM_DIR) else { return Ok(()) };
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with(prefix.as_str()) && name.ends_with(".global_mgmt")) {
            continue;
        }
        let path = e.path();
        let Ok(f) = OpenOptions::new().read(true).custom_flags(libc::O_NOFOLLOW).open(&path) else { continue };
        let Ok(m) = f.metadata() else { continue };
        if m.uid() != euid() {
            return Err(shm_error(format!(
                "{} belongs to uid {}, not to you: another user placed it to disturb the rig; remove it (as root) and start again",
                path.display(),
                m.uid()
            )));
        }
        if m.mode() & 0o077 != 0 {
            f.set_permissions(std::fs::Permissions::from_mode(0o600))
                .map_err(|e| shm_error_from(format!("cannot make {} owner-only", path.display()), e))?;
        }
    }
    Ok(())
}

/// Held by the one plant of a rig for its lifetime: an exclusive `flock` on
/// `<state dir>/plant-<rig>.lock` (the kernel drops it when the process ends, however it ends;
/// a clean end also removes the file).
#[derive(Debug)]
pub struct PlantClaim {
    lock: File,
    path: PathBuf,
}

impl Drop for PlantClaim {
    fn drop(&mut self) {
        // Removed while still locked: a plant that opened this inode and locks it after us finds
        // it unlinked and starts over (see `claim_plant`).
        let _ = std::fs::remove_file(&self.path);
        let _ = &self.lock;
    }
}

fn rig_taken(rig: &str, pid: Option<i32>) -> HostError {
    HostError::RigTaken { rig: rig.to_string(), pid }
}

/// PID of a live node named `plant-sim/<rig>`, from iceoryx2's node list.
pub fn live_plant_pid(rig: &str, cfg: &Config) -> Option<i32> {
    let name = format!("plant-sim/{rig}");
    let mut pid = None;
    let _ = Node::<ipc::Service>::list(cfg, |state| {
        if let NodeState::<ipc::Service>::Alive(view) = state {
            if let Some(d) = view.details() {
                if d.name().as_str() == name {
                    pid = Some(d.process_id().value());
                    return CallbackProgression::Stop;
                }
            }
        }
        CallbackProgression::Continue
    });
    pid
}

/// Claim rig `rig` for this plant, or say which plant holds it. The lock closes the start-up race
/// of two plants; the node list catches a plant that does not take the lock and names the PID.
pub fn claim_plant(rig: &str, cfg: &Config) -> Result<PlantClaim, HostError> {
    let path = state_dir().join(format!("plant-{rig}.lock"));
    for _ in 0..8 {
        let mut f = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&path)
            .map_err(|e| shm_error_from(format!("cannot open the rig's lock file {}", path.display()), e))?;
        // SAFETY: flock on a descriptor we own.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let pid = live_plant_pid(rig, cfg).or_else(|| {
                let mut s = String::new();
                f.read_to_string(&mut s).ok()?;
                s.trim().parse().ok()
            });
            return Err(rig_taken(rig, pid));
        }
        // The previous holder may have removed the file between our open and our lock: then the
        // lock is on a dead inode; take the new file instead.
        let same = match (f.metadata(), std::fs::symlink_metadata(&path)) {
            (Ok(a), Ok(b)) => a.ino() == b.ino() && a.dev() == b.dev(),
            _ => false,
        };
        if !same {
            continue;
        }
        if let Some(pid) = live_plant_pid(rig, cfg) {
            return Err(rig_taken(rig, Some(pid)));
        }
        // The PID for a plant that loses the race before this one's node exists.
        let _ = f.set_len(0).and_then(|_| f.rewind()).and_then(|_| write!(f, "{}", std::process::id()));
        remove_stale_locks(&path);
        return Ok(PlantClaim { lock: f, path });
    }
    Err(rig_taken(rig, None))
}

/// Remove the lock files that killed plants left behind (unlocked ones), each while holding its
/// lock, so a plant that opened it just before finds it unlinked and starts over.
fn remove_stale_locks(ours: &Path) {
    let Some(dir) = ours.parent() else { return };
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name();
        let name = name.to_string_lossy();
        if p == ours || !(name.starts_with("plant-") && name.ends_with(".lock")) {
            continue;
        }
        if let Ok(f) = OpenOptions::new().read(true).custom_flags(libc::O_NOFOLLOW).open(&p) {
            // SAFETY: flock on a descriptor we own.
            if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
                let _ = std::fs::remove_file(&p);
            }
        }
    }
}

static SIGBUS_MESSAGE: OnceLock<Vec<u8>> = OnceLock::new();

extern "C" fn on_sigbus(_: libc::c_int) {
    if let Some(m) = SIGBUS_MESSAGE.get() {
        // SAFETY: write and _exit are async-signal-safe; the buffer lives for the process.
        unsafe { libc::write(2, m.as_ptr().cast(), m.len()) };
    }
    // SAFETY: as above.
    unsafe { libc::_exit(EXIT_SHARED_MEMORY) };
}

/// A SIGBUS (a page of shared memory the tmpfs cannot back) ends `daemon` with one sentence and
/// [`EXIT_SHARED_MEMORY`] instead of a core dump: the guard behind [`check_shared_memory`] for
/// space that runs out while the rig runs.
pub fn exit_on_sigbus(daemon: &str) {
    let _ = SIGBUS_MESSAGE.set(
        format!(
            "{daemon}: error: shared memory in {SHM_DIR} failed under the rig (SIGBUS: the tmpfs is full or its files vanished): free space there or enlarge it (`docker run --shm-size=64m`); under systemd-logind set RemoveIPC=no\n"
        )
        .into_bytes(),
    );
    // SAFETY: the handler only calls async-signal-safe functions.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigbus as extern "C" fn(libc::c_int) as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGBUS, &sa, std::ptr::null_mut());
    }
}

/// For `Command::pre_exec` of a launcher's children: the child gets SIGTERM when the launcher's
/// spawning thread ends (PR_SET_PDEATHSIG; spawn from the main thread, as `rig` and `replay` do),
/// and gives up at once if the launcher is already gone.
pub fn die_with_parent() -> impl FnMut() -> std::io::Result<()> + Send + Sync + 'static {
    // SAFETY: getpid has no preconditions.
    let parent = unsafe { libc::getpid() };
    move || {
        // SAFETY: prctl and getppid are async-signal-safe and touch only this (child) process.
        unsafe {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() != parent {
                return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
            }
        }
        Ok(())
    }
}

/// Write to stdout, ignoring a closed pipe (a launcher that died must not make a daemon panic).
pub fn print_stdout(text: &str) {
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes()).and_then(|_| out.flush());
}

/// Write to stderr, ignoring a closed pipe.
pub fn print_stderr(text: &str) {
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shared_memory_directory_is_iceoryx2s() {
        assert_eq!(iceoryx2_bb_posix::config::SHARED_MEMORY_DIRECTORY.to_string(), format!("{SHM_DIR}/"));
    }

    #[test]
    fn a_missing_directory_is_one_sentence_with_the_fix() {
        let e = check_shared_memory_at(Path::new("/nonexistent-shm-dir")).unwrap_err();
        assert_eq!(e.exit_code(), EXIT_SHARED_MEMORY);
        let m = e.to_string();
        assert!(m.contains("does not exist") && m.contains("--shm-size"), "{e}");
    }

    #[test]
    fn a_taken_rig_is_one_sentence_naming_the_holder_with_its_own_status() {
        let e = rig_taken("r1", Some(42));
        assert_eq!(e.exit_code(), EXIT_RIG_TAKEN);
        assert_eq!(
            e.to_string(),
            "rig \"r1\" is already running (the plant with PID 42); start this plant with another --rig name, or stop that one first"
        );
        assert!(rig_taken("r1", None).to_string().contains("(another plant)"));
    }

    #[test]
    fn an_os_error_is_the_source_not_part_of_the_sentence() {
        let e = shm_error_from("cannot inspect /x".into(), std::io::Error::from_raw_os_error(libc::EACCES));
        assert_eq!(e.to_string(), "cannot inspect /x");
        let cause = std::error::Error::source(&e).expect("the OS error is the source").to_string();
        assert!(cause.contains("os error 13"), "{cause}");
    }

    #[test]
    fn the_effective_config_keeps_the_template_and_fills_in_root_and_prefix() {
        // /dev/shm is a tmpfs (check_shared_memory's premise): the root stays in the state directory
        let on_tmpfs = Path::new(SHM_DIR);
        let t = effective_config_text(on_tmpfs).unwrap();
        assert!(t.contains("root-path = \"/dev/shm/iox2/\""), "{t}");
        assert!(t.contains(&format!("prefix = \"rig{}_", euid())), "{t}");
        assert_eq!(t.lines().filter(|l| l.starts_with("prefix")).count(), 1);
        // /proc is never a tmpfs: the root moves to /dev/shm, named with the prefix
        let t = effective_config_text(Path::new("/proc")).unwrap();
        let prefix = t.lines().find(|l| l.starts_with("prefix")).unwrap().split('"').nth(1).unwrap().to_string();
        assert_eq!(prefix.len(), format!("rig{}_", euid()).len() + 13, "{t}");
        assert_eq!(root_path_of(&t).unwrap(), Path::new(&format!("/dev/shm/{prefix}iox2")), "{t}");
        // iceoryx2's socket paths still fit (MAX_STATE_DIR_LEN's budget: the state dir + "/iox2")
        assert!(root_path_of(&t).unwrap().as_os_str().len() <= MAX_STATE_DIR_LEN + 5);
    }
}
