//! The recorder: a wait-free queue from the plant's 1 kHz thread to a writer thread that owns the
//! MCAP file (DESIGN section 6: the loop allocates nothing, takes no locks, does no I/O).
//!
//! Crash safety: the writer closes a chunk (and hands it to the OS) every `chunk_size_bytes` of
//! uncompressed messages or every [`RecorderTuning::max_flush_interval`], whichever comes first,
//! so a SIGKILL loses at most that much; chunks are built in memory, so the file never holds a
//! half-written chunk except when the process dies inside one `write`. [`Recorder::finish`]
//! writes the summary and index. A disk that runs low (below [`RecorderTuning::min_free_bytes`])
//! ends the recording cleanly with an `/events` entry. A full disk tells the same story: after
//! every chunk the writer keeps room for the next chunk and the file's end allocated past the end
//! of the file ([`RecorderTuning::tail_reserve_bytes`], `fallocate` KEEP_SIZE), so ENOSPC shows
//! up there, between chunks, and the file is ended in that room with the `/events` entry, the
//! `recording_summary` metadata and a footer (no summary section). A write that fails anyway
//! (no reserve on this file system, EFBIG, EIO) cuts the file back to its last complete chunk and
//! ends it the same way if it can. Either way [`RecordingSummary::stopped_early`] says why and the
//! writer keeps draining the queue, so the loop never notices.
//!
//! With [`RecorderConfig::live`] the writer also offers every message it writes to the live view
//! ([`crate::live`]): a bounded queue to a thread of its own that serves Foxglove clients.

use crate::live::{LiveChannel, LiveConfig, LiveError, LiveSummary, LiveView};
use crate::run_metadata::RunMetadata;
use crate::schema::{self, Channel, TickHead, CHANNELS, MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::{
    error_chain, sim_time_ns, wall_clock_ns, EventKind, EventRecord, TickRecord, MAX_CENTRELINE, MAX_MODAL_STATE, RECORDING_FORMAT_VERSION,
};
use mcap::records::{op, MessageHeader, Metadata};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::mem::MaybeUninit;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use thiserror::Error;

/// What the plant passes to [`Recorder::start`].
#[derive(Debug, Clone)]
pub struct RecorderConfig {
    /// The MCAP file to create (parent directories are created).
    pub path: PathBuf,
    /// Records the queue holds; at 1 kHz, 4096 absorb a 4 s stall of the writer.
    pub queue_capacity: usize,
    /// Uncompressed bytes per chunk: bounds what a SIGKILL loses (about 0.6 s at 1 kHz for 1 MiB).
    pub chunk_size_bytes: u64,
    /// Written once as MCAP metadata `rig` (with the writer's own keys: start time, format and
    /// contract version): rig name, mode, scenario, EGM or not, the centre-line nodes' z (also
    /// repeated in every `/strip` message).
    pub metadata: RunMetadata,
    /// Serve the channels live over the Foxglove WebSocket protocol as they are written.
    pub live: Option<LiveConfig>,
    /// What Foxglove draws (URDF, transforms, strip scene; [`crate::scene`]); None: only the
    /// URDF-less channels (`/log` is written either way).
    pub scene: Option<crate::scene::SceneConfig>,
    /// Control period, s: the decimation of the scene (every `round(1 / (rate T))`-th tick).
    pub period_s: f64,
    /// The plant's centre line from its strip's state: with it, a tick whose record carries
    /// its state ([`crate::StripRecord::modal_len`]) gets its centre line computed here, on the
    /// writer thread, instead of on the loop's. None: records come with their centre line.
    pub centre_line: Option<Arc<dyn CentreLineFromState>>,
}

/// A strip record's centre line from the strip's state, for the writer thread (the plant's
/// contact implements it with its own tables, so the bits are the loop's would have been).
pub trait CentreLineFromState: Send + Sync + std::fmt::Debug {
    /// Fill `r.centreline_pressure_pa[..r.n_centreline]`, `r.max_bottom_pressure_pa` and, when
    /// `top_line`, `r.top_centreline_uy_m[..r.n_centreline]` (else zeros there) from the strip's
    /// `state` and `r`'s scalars (`wheel_z_m`, `contact_force_n`), as the loop would have.
    fn expand(&self, state: &[f64], top_line: bool, r: &mut crate::StripRecord);
}

impl RecorderConfig {
    pub const DEFAULT_QUEUE_CAPACITY: usize = 4096;
    pub const DEFAULT_CHUNK_SIZE_BYTES: u64 = 1 << 20;

    pub fn new(path: impl Into<PathBuf>, metadata: RunMetadata) -> Self {
        Self {
            path: path.into(),
            queue_capacity: Self::DEFAULT_QUEUE_CAPACITY,
            chunk_size_bytes: Self::DEFAULT_CHUNK_SIZE_BYTES,
            metadata,
            live: None,
            scene: None,
            period_s: 1e-3,
            centre_line: None,
        }
    }
}

/// Writer-thread knobs with sensible defaults (tests shorten them).
#[derive(Debug, Clone)]
pub struct RecorderTuning {
    /// Stop recording (cleanly, with an `/events` entry) when the file system has less free space.
    pub min_free_bytes: u64,
    /// Close the open chunk at least this often, so a SIGKILL loses at most this much.
    pub max_flush_interval: Duration,
    /// zstd level; 0 is zstd's default (3); negative levels are zstd's fast ones.
    pub compression_level: i32,
    /// Writer sleep when the queue is empty (parked: `finish` wakes it at once).
    pub idle_sleep: Duration,
    /// Bytes kept allocated past the end of the file after every chunk: room for the next chunk
    /// and for ending the file. None: twice the chunk size plus 64 KiB; 0: none (a full disk is
    /// then met by a failing write in the middle of a chunk).
    pub tail_reserve_bytes: Option<u64>,
}

impl RecorderTuning {
    /// zstd level of a lockstep run's recording. The writer thread is the lockstep run's slowest
    /// part (it has one CPU to itself, the loop the other; the scene is most of its bytes).
    /// Level 1 compresses in less CPU than zstd's default 3, for files about 10 % larger (20
    /// default-scenario cases, 2026-12-02); level -1 (zstd's first fast level) compresses the
    /// sunroof's messages 1.4-1.7x faster again and decompresses them 1.1x faster, to a file
    /// 0.2 % larger (`zstd -b` with 512 KiB blocks, 2026-12-06).
    pub const LOCKSTEP_COMPRESSION_LEVEL: i32 = -1;

    /// The knobs for a run in `mode`: lockstep compresses at [`Self::LOCKSTEP_COMPRESSION_LEVEL`],
    /// real time at zstd's default.
    pub fn for_mode(mode: scenarios::Mode) -> Self {
        match mode {
            scenarios::Mode::Lockstep => Self { compression_level: Self::LOCKSTEP_COMPRESSION_LEVEL, ..Self::default() },
            scenarios::Mode::Realtime => Self::default(),
        }
    }
}

impl Default for RecorderTuning {
    fn default() -> Self {
        Self {
            min_free_bytes: 64 << 20,
            max_flush_interval: Duration::from_secs(1),
            compression_level: 0,
            idle_sleep: Duration::from_millis(2),
            tail_reserve_bytes: None,
        }
    }
}

#[derive(Debug, Error)]
pub enum RecorderError {
    /// The OS error is part of the message, not a `source` (printed once in an error chain).
    #[error("recording {path}: cannot create the file: {cause}")]
    Create { path: PathBuf, cause: std::io::Error },
    #[error("recording {path}: {what}")]
    Mcap { path: PathBuf, what: String },
    #[error("recording {path}: {what}")]
    Config { path: PathBuf, what: String },
    #[error("recording {path}: the writer thread panicked")]
    WriterPanicked { path: PathBuf },
    #[error(transparent)]
    Live(#[from] LiveError),
}

/// What [`Recorder::finish`] reports.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSummary {
    pub path: PathBuf,
    pub ticks_written: u64,
    pub events_written: u64,
    /// Records the queue refused because it was full (must be 0).
    pub dropped_ticks: u64,
    pub dropped_events: u64,
    /// Records not in the file because the recording had stopped (disk full, I/O error): those
    /// drained afterwards and those of the chunk the error cut off.
    pub lost_after_stop: u64,
    /// Why the recording stopped before `finish`, if it did.
    pub stopped_early: Option<String>,
    /// Whether the file got its footer: with summary and index normally, or (after a write error)
    /// cut back to its last complete chunk and ended there.
    pub finalised: bool,
    /// File size, bytes.
    pub bytes: u64,
    /// What the live view sent and dropped, if it ran.
    pub live: Option<LiveSummary>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Tick,
    /// A tick whose centre line the writer computes from the strip state in the slot.
    TickState,
    Event,
    Egm,
}

/// One queue slot (5,160 bytes), written in place by the loop thread: the kind, then either the
/// tick head and only the valid centre-line pressures (as f32, the file's precision) or the
/// strip state the writer computes them from, or the event. Leaving the rest untouched keeps the
/// push to about 1 KB of stores for an 81-node centre line (4 KB for the default strip's state)
/// instead of a copy of the whole slot (the benchmark's p99 target is 2 us).
#[derive(Clone, Copy)]
struct Slot {
    kind: Kind,
    tick: MaybeUninit<TickHead>,
    /// An event or an EGM cycle (by `kind`): they share the space, so `/egm` does not make a
    /// slot larger.
    small: MaybeUninit<Small>,
    centre_line: CentreLineSlot,
}

/// A tick's centre line (`Kind::Tick`) or the strip state it is computed from
/// (`Kind::TickState`): they share the space (the state's 4 KB, twice the centre line's).
#[derive(Clone, Copy)]
union CentreLineSlot {
    expanded: ExpandedSlot,
    state: [MaybeUninit<f64>; MAX_MODAL_STATE],
}

#[derive(Clone, Copy)]
struct ExpandedSlot {
    pressure_pa: [MaybeUninit<f32>; MAX_CENTRELINE],
    top_uy_m: [MaybeUninit<f32>; MAX_CENTRELINE],
}

#[derive(Clone, Copy)]
union Small {
    event: EventRecord,
    egm: crate::EgmRecord,
}

const _: () = assert!(std::mem::size_of::<crate::EgmRecord>() <= std::mem::size_of::<EventRecord>());

#[derive(Default)]
struct Shared {
    dropped_ticks: AtomicU64,
    dropped_events: AtomicU64,
    stopped: AtomicBool,
}

/// Records every tick of a run into one MCAP file. Owned by the plant's loop thread.
pub struct Recorder {
    producer: Option<rtrb::Producer<Slot>>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<RecordingSummary>>,
    path: PathBuf,
    live_addr: Option<std::net::SocketAddr>,
    /// Every how many ticks the writer draws the scene; None without one.
    scene_every: Option<u64>,
    /// Whether the writer computes a record's centre line from its strip state.
    expands_centre_line: bool,
}

type McapFile = mcap::Writer<BufWriter<SlicedFile>>;

/// Bytes an MCAP message record adds to its payload: opcode (1), record length (8), channel id
/// (2), sequence (4), log time (8), publish time (8). Counted toward `chunk_size_bytes`.
const MESSAGE_RECORD_HEADER_BYTES: u64 = 1 + 8 + 2 + 4 + 8 + 8;

/// Largest single `write(2)` of a recording, bytes.
const WRITE_SLICE_BYTES: usize = 16 * 1024;

/// The recording's file, written at most [`WRITE_SLICE_BYTES`] per system call. A kernel built
/// without preemption (`PREEMPT_NONE`, common on cloud VMs) runs a syscall to its end before a
/// woken SCHED_FIFO thread on that CPU gets it: one chunk of a few hundred kB copied into the
/// page cache in one `write` held the controller off its CPU for long enough to miss ticks. Each
/// return to user space between slices lets a waiting real-time thread in. It also keeps a
/// [`Tally`] of what went to the file, so the writer knows where its last complete chunk ends.
struct SlicedFile(File, Arc<Tally>);

/// Bytes written so far and their CRC-32 (the data section's, as long as it lasts): what ending
/// the file after a write error needs. Only the writer thread touches it.
#[derive(Default)]
struct Tally {
    position: AtomicU64,
    crc: std::sync::Mutex<crc32fast::Hasher>,
    /// Set by a seek that moved: the running CRC no longer is the file's.
    seeked: AtomicBool,
}

impl std::io::Write for SlicedFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.0.write(&buf[..buf.len().min(WRITE_SLICE_BYTES)])?;
        self.1.position.fetch_add(n as u64, Ordering::Relaxed);
        self.1.crc.lock().unwrap_or_else(|e| e.into_inner()).update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

impl std::io::Seek for SlicedFile {
    /// The writer runs with seeking disabled (it only asks where it is); a real seek would make
    /// the running CRC meaningless, and the end after a write error then carries none.
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        let at = self.0.seek(pos)?;
        if self.1.position.swap(at, Ordering::Relaxed) != at {
            self.1.seeked.store(true, Ordering::Relaxed);
        }
        Ok(at)
    }
}

impl Recorder {
    /// Creates the file, writes header, schemas, channels and metadata, and spawns the writer.
    /// Call before the loop starts (this does blocking I/O).
    pub fn start(cfg: RecorderConfig) -> Result<Self, RecorderError> {
        Self::start_with(cfg, RecorderTuning::default())
    }

    pub fn start_with(cfg: RecorderConfig, tuning: RecorderTuning) -> Result<Self, RecorderError> {
        let path = cfg.path.clone();
        let config_err = |what: String| RecorderError::Config { path: path.clone(), what };
        if cfg.queue_capacity == 0 {
            return Err(config_err("queue_capacity must be at least 1".into()));
        }
        if cfg.chunk_size_bytes == 0 {
            return Err(config_err("chunk_size_bytes must be at least 1".into()));
        }
        let centreline_z = match &cfg.metadata.centreline_z_m {
            Some(z) => schema::centreline_z_f32(z).map_err(config_err)?,
            None => Vec::new(),
        };
        let fox_defs = FoxgloveChannels::defs(cfg.scene.as_ref());
        // `/egm` only in EGM runs: a torque run's file and live view stay as they were. `/egm` is
        // the last of CHANNELS, so the others keep their index in both.
        const _: () = assert!(Channel::Egm.index() == CHANNELS.len() - 1);
        let has_egm = cfg.metadata.egm.is_some();
        let ros_channels = if has_egm { CHANNELS.len() } else { Channel::Egm.index() };
        // The live view first: an address it cannot serve on ends the start before a file exists.
        let live = match &cfg.live {
            Some(live_cfg) => {
                let name = &cfg.metadata.rig;
                let ros = CHANNELS[..ros_channels].iter().map(|ch| LiveChannel {
                    topic: ch.topic,
                    schema_name: ch.schema_name,
                    schema_encoding: SCHEMA_ENCODING,
                    schema: ch.schema_text.as_bytes(),
                    message_encoding: MESSAGE_ENCODING,
                });
                let fox = fox_defs.iter().map(|d| LiveChannel {
                    topic: d.topic,
                    schema_name: &d.schema.0,
                    schema_encoding: &d.schema.1,
                    schema: &d.schema.2,
                    message_encoding: d.message_encoding,
                });
                let channels: Vec<LiveChannel<'_>> = ros.chain(fox).collect();
                Some(LiveView::start(live_cfg, &format!("rig {name}"), &channels)?)
            }
            None => None,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| RecorderError::Create { path: path.clone(), cause: source })?;
        }
        let file = File::create(&path).map_err(|source| RecorderError::Create { path: path.clone(), cause: source })?;
        let fd = std::os::fd::AsRawFd::as_raw_fd(&file);
        let tally = Arc::new(Tally::default());
        let mcap_err = |e: mcap::McapError| RecorderError::Mcap { path: path.clone(), what: error_chain(&e) };
        let mut mcap = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            // mcap 0.26 takes the level as u32 and hands it to zstd `as i32`: the two's
            // complement carries a negative (fast) level through (tested in recording-tools'
            // `roundtrip`).
            .compression_level(tuning.compression_level as u32)
            .compression_threads(0)
            // Chunks end when the writer thread says so (size or age); buffered in memory so the
            // file never holds a half-built chunk.
            .chunk_size(None)
            .disable_seeking(true)
            .library(format!("rig-recordings {}", env!("CARGO_PKG_VERSION")))
            // Not `ros2`: that profile wants every channel cdr + ros2msg, and the Foxglove
            // channels are protobuf. Ours says what to expect (recordings/README.md).
            .profile(crate::RECORDING_PROFILE)
            .create(BufWriter::with_capacity(WRITE_SLICE_BYTES, SlicedFile(file, tally.clone())))
            .map_err(mcap_err)?;
        let mut channel_ids = [0u16; CHANNELS.len()];
        // `/egm` only in EGM runs: a torque run's file is as before.
        for (id, ch) in channel_ids.iter_mut().zip(CHANNELS.iter()).filter(|(_, ch)| has_egm || ch.topic != Channel::Egm.def().topic) {
            let schema_id = mcap.add_schema(ch.schema_name, SCHEMA_ENCODING, ch.schema_text.as_bytes()).map_err(mcap_err)?;
            *id = mcap.add_channel(schema_id, ch.topic, MESSAGE_ENCODING, &BTreeMap::new()).map_err(mcap_err)?;
        }
        let fox = FoxgloveChannels::register(&mut mcap, &fox_defs, ros_channels).map_err(mcap_err)?;
        // The run's wall-clock start, taken once: log time = start + simulated time.
        let start_ns = wall_clock_ns();
        let mut meta = cfg.metadata.to_entries();
        meta.insert("start_wall_ns".into(), start_ns.to_string());
        meta.insert("recording_format".into(), RECORDING_FORMAT_VERSION.to_string());
        meta.insert("contract_version".into(), messages::CONTRACT_VERSION.to_string());
        meta.insert("created_wall_ns".into(), wall_clock_ns().to_string());
        mcap.write_metadata(&Metadata { name: crate::run_metadata::RECORD_NAME.into(), metadata: meta }).map_err(mcap_err)?;
        let mut robot_description = Vec::new();
        if let (Some(scene), Some(ch)) = (cfg.scene.as_ref(), fox.robot_description) {
            let text = robot::urdf::urdf(&scene.tool);
            let buf = &mut robot_description;
            crate::cdr::CdrWriter::new(buf).string(&text);
            let header = MessageHeader { channel_id: ch.id, sequence: 0, log_time: start_ns, publish_time: start_ns };
            mcap.write_to_known_channel(&header, buf).map_err(mcap_err)?;
            let attachment = mcap::Attachment {
                log_time: start_ns,
                create_time: start_ns,
                name: "irb2400_wheel.urdf".into(),
                media_type: "application/xml".into(),
                data: std::borrow::Cow::Owned(text.into_bytes()),
            };
            mcap.attach(&attachment).map_err(mcap_err)?;
        }
        mcap.flush().map_err(mcap_err)?;

        let (mut producer, mut consumer) = rtrb::RingBuffer::new(cfg.queue_capacity);
        // Touch every slot once so the loop thread never takes a page fault on a fresh slot.
        let blank = Slot {
            kind: Kind::Event,
            tick: MaybeUninit::new(TickHead::of(&TickRecord::default())),
            small: MaybeUninit::new(Small { event: EventRecord::new(0, 0.0, EventKind::Info, "") }),
            centre_line: CentreLineSlot {
                expanded: ExpandedSlot {
                    pressure_pa: [MaybeUninit::new(0.0); MAX_CENTRELINE],
                    top_uy_m: [MaybeUninit::new(0.0); MAX_CENTRELINE],
                },
            },
        };
        for _ in 0..cfg.queue_capacity {
            let _ = producer.push(blank);
        }
        while consumer.pop().is_ok() {}
        let shared = Arc::new(Shared::default());
        let live_addr = live.as_ref().map(LiveView::local_addr);
        let reserve = tuning.tail_reserve_bytes.unwrap_or(2 * cfg.chunk_size_bytes + (64 << 10));
        let mut writer = WriterThread {
            mcap: Some(mcap),
            channel_ids,
            has_egm,
            buf: Vec::with_capacity(4096),
            centreline_z,
            moving_z: Vec::with_capacity(MAX_CENTRELINE),
            pressure: Vec::with_capacity(MAX_CENTRELINE),
            top_uy: Vec::with_capacity(MAX_CENTRELINE),
            centre_line: cfg.centre_line.clone().map(|c| (c, Box::default())),
            bond_peak: match cfg.scene.as_ref() {
                Some(sc) if sc.path.is_some() => {
                    vec![0.0; sc.strip.as_ref().map_or(0, |g| (g.length_m / crate::scene::SCENE_BOND_STEP_M).round() as usize + 1)]
                }
                _ => Vec::new(),
            },
            scene_scratch: Default::default(),
            fox,
            robot_description,
            scene_every: cfg.scene.as_ref().map_or(1, |s| s.every_ticks(cfg.period_s)),
            robot: cfg.scene.as_ref().map(|s| robot::Robot::irb2400_with_tool(s.tool)),
            scene: cfg.scene.clone(),
            start_ns,
            consumer,
            shared: shared.clone(),
            tuning,
            chunk_size: cfg.chunk_size_bytes,
            path: path.clone(),
            ticks_written: 0,
            events_written: 0,
            lost_after_stop: 0,
            bytes_since_flush: 0,
            last_flush: Instant::now(),
            last_tick: 0,
            last_sim_time_s: 0.0,
            stopped_early: None,
            finalised: false,
            fd,
            tally,
            kept: Kept::default(),
            reserve,
            live,
        };
        let scene_every = cfg.scene.as_ref().map(|_| writer.scene_every);
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || writer.run())
            .map_err(|source| RecorderError::Create { path: path.clone(), cause: source })?;
        let expands_centre_line = cfg.centre_line.is_some();
        Ok(Self { producer: Some(producer), shared, thread: Some(thread), path, live_addr, scene_every, expands_centre_line })
    }

    /// Every how many ticks the writer draws the 3D scene (ticks whose `state.tick` is a
    /// multiple of it), the only reader of a record's `top_centreline_uy_m`; None: no scene, the
    /// top line is never read.
    pub fn scene_every(&self) -> Option<u64> {
        self.scene_every
    }

    /// Whether this recorder computes a record's centre line from the strip state it carries
    /// ([`RecorderConfig::centre_line`]): a loop whose records are read by nobody else may then
    /// leave the centre line to the writer thread.
    pub fn expands_centre_line(&self) -> bool {
        self.expands_centre_line
    }

    /// Queues one tick. Wait-free; returns false (and counts a drop) if the queue is full.
    #[inline]
    pub fn record_tick(&mut self, r: &TickRecord) -> bool {
        self.record_tick_commanded(r, None)
    }

    /// Like [`record_tick`](Self::record_tick), plus the controller's own answer for this tick
    /// as received (`None` if none came in time). `/joint_torque.tau` is what the plant applied
    /// (held, refused or blended in); with the answer recorded too, `rig replay` compares a
    /// controller on every answered tick instead of only where applied == answered.
    #[inline]
    pub fn record_tick_commanded(&mut self, r: &TickRecord, commanded: Option<&messages::JointTorque>) -> bool {
        let Some(p) = self.producer.as_mut() else { return false };
        let Ok(mut chunk) = p.write_chunk_uninit(1) else {
            self.shared.dropped_ticks.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        let slot = chunk.as_mut_slices().0[0].as_mut_ptr();
        let n = (r.strip.n_centreline as usize).min(MAX_CENTRELINE);
        let m = (r.strip.modal_len as usize).min(MAX_MODAL_STATE);
        // SAFETY: `slot` points to one slot reserved for us. We write `kind` (the only field
        // without MaybeUninit, so the slot is a valid Slot afterwards), the tick head and either
        // the first n pressures and top displacements (Kind::Tick) or the first m entries of the
        // strip state (Kind::TickState); the reader reads exactly those for that kind.
        unsafe {
            let mut head = TickHead::of(r);
            head.commanded = commanded.map(|t| t.tau);
            std::ptr::addr_of_mut!((*slot).tick).write(MaybeUninit::new(head));
            let centre_line = std::ptr::addr_of_mut!((*slot).centre_line);
            if m > 0 {
                std::ptr::addr_of_mut!((*slot).kind).write(Kind::TickState);
                let dst = std::ptr::addr_of_mut!((*centre_line).state) as *mut f64;
                std::ptr::copy_nonoverlapping(r.strip.modal_state.as_ptr(), dst, m);
            } else {
                std::ptr::addr_of_mut!((*slot).kind).write(Kind::Tick);
                let dst = std::ptr::addr_of_mut!((*centre_line).expanded.pressure_pa) as *mut f32;
                for (i, &v) in r.strip.centreline_pressure_pa[..n].iter().enumerate() {
                    dst.add(i).write(v as f32);
                }
                let dst = std::ptr::addr_of_mut!((*centre_line).expanded.top_uy_m) as *mut f32;
                for (i, &v) in r.strip.top_centreline_uy_m[..n].iter().enumerate() {
                    dst.add(i).write(v as f32);
                }
            }
            chunk.commit(1);
        }
        true
    }

    /// Queues one event. Wait-free; returns false (and counts a drop) if the queue is full.
    #[inline]
    pub fn record_event(&mut self, e: &EventRecord) -> bool {
        // SAFETY: (the write) `slot` points to the slot `push_small` reserved; a Kind::Event
        // slot is read for `small.event` only.
        self.push_small(Kind::Event, |slot| unsafe { std::ptr::addr_of_mut!((*slot).small).write(MaybeUninit::new(Small { event: *e })) })
    }

    /// Queues one EGM cycle (`/egm`; written only in an EGM run: [`RunMetadata::egm`]).
    /// Wait-free; returns false (and counts a drop) if the queue is full.
    #[inline]
    pub fn record_egm(&mut self, e: &crate::EgmRecord) -> bool {
        // SAFETY: (the write) as in record_event; a Kind::Egm slot is read for `small.egm` only.
        self.push_small(Kind::Egm, |slot| unsafe { std::ptr::addr_of_mut!((*slot).small).write(MaybeUninit::new(Small { egm: *e })) })
    }

    /// Reserve one slot, mark it `kind`, let `fill` write the field that kind is read for, commit.
    #[inline]
    fn push_small(&mut self, kind: Kind, fill: impl FnOnce(*mut Slot)) -> bool {
        let Some(p) = self.producer.as_mut() else { return false };
        let Ok(mut chunk) = p.write_chunk_uninit(1) else {
            self.shared.dropped_events.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        let slot = chunk.as_mut_slices().0[0].as_mut_ptr();
        // SAFETY: as in record_tick: `kind` first (the only field without MaybeUninit), then the
        // kind's field by `fill`; the reader reads exactly that.
        unsafe {
            std::ptr::addr_of_mut!((*slot).kind).write(kind);
            fill(slot);
            chunk.commit(1);
        }
        true
    }

    /// Ticks and events the queue refused so far (must stay 0).
    pub fn dropped(&self) -> u64 {
        self.shared.dropped_ticks.load(Ordering::Relaxed) + self.shared.dropped_events.load(Ordering::Relaxed)
    }

    /// True once the writer stopped recording (disk full or I/O error); the loop may go on.
    pub fn is_stopped(&self) -> bool {
        self.shared.stopped.load(Ordering::Relaxed)
    }

    /// Free slots in the queue (for batch producers that would rather wait than drop).
    pub fn queue_free(&self) -> usize {
        self.producer.as_ref().map_or(0, |p| p.slots())
    }

    /// For a producer with no deadline (lockstep): sleep in steps of [`Self::ROOM_POLL`] until
    /// the queue has `slots` free, the writer stopped, or `limit` passed. True if there is room.
    /// Never for real time, where a full queue is a counted drop instead.
    pub fn wait_for_room(&self, slots: usize, limit: std::time::Duration) -> bool {
        let t0 = Instant::now();
        loop {
            if self.queue_free() >= slots {
                return true;
            }
            if self.is_stopped() || self.producer.is_none() || t0.elapsed() >= limit {
                return false;
            }
            std::thread::sleep(Self::ROOM_POLL);
        }
    }

    /// How often [`Self::wait_for_room`] looks at the queue again.
    pub const ROOM_POLL: std::time::Duration = std::time::Duration::from_micros(100);

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where the live view listens, if it runs.
    pub fn live_addr(&self) -> Option<std::net::SocketAddr> {
        self.live_addr
    }

    /// Drains the queue, writes the drop counters, summary, index and footer, joins the writer.
    pub fn finish(mut self) -> Result<RecordingSummary, RecorderError> {
        self.join()
    }

    fn join(&mut self) -> Result<RecordingSummary, RecorderError> {
        // Dropping the producer tells the writer that nothing more comes; the unpark ends its
        // idle wait now rather than after `idle_sleep`.
        self.producer = None;
        match self.thread.take() {
            Some(t) => {
                t.thread().unpark();
                t.join().map_err(|_| RecorderError::WriterPanicked { path: self.path.clone() })
            }
            None => Err(RecorderError::WriterPanicked { path: self.path.clone() }),
        }
    }
}

impl Drop for Recorder {
    /// A recorder dropped without `finish` (early return, unwinding) still finalises its file.
    fn drop(&mut self) {
        if self.thread.is_some() {
            if let Err(e) = self.join() {
                tracing::error!("{e}");
            }
        }
    }
}

#[allow(clippy::large_enum_variant)] // one value at a time, on the writer's stack
enum Popped {
    Tick(TickHead),
    Event(EventRecord),
    Egm(crate::EgmRecord),
}

struct WriterThread {
    mcap: Option<McapFile>,
    channel_ids: [u16; CHANNELS.len()],
    /// The `/egm` channel is registered (an EGM run).
    has_egm: bool,
    buf: Vec<u8>,
    centreline_z: Vec<f32>,
    /// The z of the tick's centre-line nodes when they move with the wheel (a windowed strip:
    /// `StripHead::centreline_dz_m` > 0), expanded here, off the loop; capacity reserved.
    moving_z: Vec<f32>,
    /// Centre-line pressures of the tick being written.
    pressure: Vec<f32>,
    /// Top centre-line displacements of the tick being written.
    top_uy: Vec<f32>,
    /// The plant's centre line from the strip state, with the record it fills (one, reused).
    centre_line: Option<(Arc<dyn CentreLineFromState>, Box<crate::StripRecord>)>,
    /// A contour's scene: the peak centre-line pressure per millimetre so far (every tick's, not
    /// just the scene's ticks); empty otherwise.
    bond_peak: Vec<f32>,
    /// Reused buffers of the scene's encoding.
    scene_scratch: crate::scene::SceneScratch,
    /// Ids of the Foxglove channels.
    fox: FoxgloveChannels,
    /// The `/robot_description` message (CDR), written once at the start of the file and offered
    /// to the live view once a second, since a client may connect at any time.
    robot_description: Vec<u8>,
    /// Transforms and scene every this many ticks.
    scene_every: u64,
    robot: Option<robot::Robot>,
    scene: Option<crate::scene::SceneConfig>,
    /// The run's wall-clock start (Unix ns): log time = start + simulated time.
    start_ns: u64,
    consumer: rtrb::Consumer<Slot>,
    shared: Arc<Shared>,
    tuning: RecorderTuning,
    chunk_size: u64,
    path: PathBuf,
    ticks_written: u64,
    events_written: u64,
    lost_after_stop: u64,
    bytes_since_flush: u64,
    last_flush: Instant,
    last_tick: u64,
    last_sim_time_s: f64,
    stopped_early: Option<String>,
    finalised: bool,
    /// The file's descriptor (owned by `mcap`), for the tail reserve.
    fd: std::os::fd::RawFd,
    /// What went to the file so far (kept by [`SlicedFile`]).
    tally: Arc<Tally>,
    /// What the file holds up to the end of its last complete chunk.
    kept: Kept,
    /// Bytes to keep allocated past the end of the file (0: none, or not supported here).
    reserve: u64,
    /// The live view, offered every message written.
    live: Option<LiveView>,
}

/// The state at the end of the last complete chunk: what a write error falls back to.
#[derive(Default, Clone)]
struct Kept {
    bytes: u64,
    /// CRC-32 of those bytes so far, to be finished over the end appended after a write error
    /// (None if the writer ever seeked).
    crc: Option<crc32fast::Hasher>,
    ticks: u64,
    events: u64,
    last_tick: u64,
    last_sim_time_s: f64,
}

impl WriterThread {
    fn run(&mut self) -> RecordingSummary {
        self.chunk_complete();
        loop {
            if let Some(item) = self.pop() {
                self.handle(item);
                self.maybe_flush();
            } else if self.consumer.is_abandoned() {
                // The producer is gone: everything it pushed is visible now.
                while let Some(item) = self.pop() {
                    self.handle(item);
                    self.maybe_flush();
                }
                break;
            } else {
                self.maybe_flush();
                // Parked, so that `Recorder::join` ends the wait (a spurious wake-up only looks
                // at the queue once more).
                std::thread::park_timeout(self.tuning.idle_sleep);
            }
        }
        self.finalise();
        let live = self.live.take().map(LiveView::finish);
        let finalised = self.finalised;
        let bytes = std::fs::metadata(&self.path).map(|m| m.len()).unwrap_or(0);
        RecordingSummary {
            path: self.path.clone(),
            ticks_written: self.ticks_written,
            events_written: self.events_written,
            dropped_ticks: self.shared.dropped_ticks.load(Ordering::Relaxed),
            dropped_events: self.shared.dropped_events.load(Ordering::Relaxed),
            lost_after_stop: self.lost_after_stop,
            stopped_early: self.stopped_early.clone(),
            finalised,
            bytes,
            live,
        }
    }

    /// Takes the next slot: the tick head is copied out, its pressures go to `self.pressure`.
    fn pop(&mut self) -> Option<Popped> {
        let Self { consumer, pressure, top_uy, moving_z, centre_line, scene, scene_every, .. } = self;
        let chunk = consumer.read_chunk(1).ok()?;
        let slot = &chunk.as_slices().0[0];
        let item = match slot.kind {
            Kind::Tick | Kind::TickState => {
                // SAFETY: record_tick wrote the head.
                let mut head = unsafe { slot.tick.assume_init() };
                let n = head.strip.n_centreline as usize;
                pressure.clear();
                top_uy.clear();
                match (slot.kind, centre_line.as_mut()) {
                    (Kind::TickState, Some((from_state, r))) => {
                        let m = head.strip.modal_len as usize;
                        // SAFETY: record_tick wrote the first modal_len entries of the state
                        // (a Kind::TickState slot), and MaybeUninit<f64> has f64's layout.
                        let state = unsafe { &*(&slot.centre_line.state[..m] as *const [MaybeUninit<f64>] as *const [f64]) };
                        r.wheel_z_m = head.strip.wheel_z_m;
                        r.contact_force_n = head.strip.contact_force_n;
                        r.n_centreline = n as u32;
                        // The top line only where the scene draws it, as the loop would have.
                        let top_line = scene.is_some() && head.state.tick.is_multiple_of(*scene_every);
                        from_state.expand(state, top_line, r);
                        head.strip.max_bottom_pressure_pa = r.max_bottom_pressure_pa;
                        pressure.extend(r.centreline_pressure_pa[..n].iter().map(|&p| p as f32));
                        top_uy.extend(r.top_centreline_uy_m[..n].iter().map(|&u| u as f32));
                    }
                    (Kind::TickState, None) => {
                        // A plant that left its centre line to a writer without the means:
                        // recorded as not computed.
                        head.strip.max_bottom_pressure_pa = f64::NAN;
                        pressure.resize(n, f32::NAN);
                        top_uy.resize(n, f32::NAN);
                    }
                    _ => {
                        // SAFETY: a Kind::Tick slot holds the expanded centre line, whose first
                        // n_centreline pressures and top displacements record_tick wrote.
                        let e = unsafe { &slot.centre_line.expanded };
                        // SAFETY: as above.
                        pressure.extend(e.pressure_pa[..n].iter().map(|p| unsafe { p.assume_init() }));
                        // SAFETY: as above.
                        top_uy.extend(e.top_uy_m[..n].iter().map(|p| unsafe { p.assume_init() }));
                    }
                }
                head.strip.modal_len = 0;
                moving_z.clear();
                let (z0, dz) = (head.strip.centreline_z0_m, head.strip.centreline_dz_m);
                if dz > 0.0 {
                    moving_z.extend((0..n).map(|i| (z0 + i as f64 * dz) as f32));
                }
                Popped::Tick(head)
            }
            // SAFETY: record_event wrote the event.
            Kind::Event => Popped::Event(unsafe { slot.small.assume_init().event }),
            // SAFETY: record_egm wrote the cycle.
            Kind::Egm => Popped::Egm(unsafe { slot.small.assume_init().egm }),
        };
        chunk.commit_all();
        Some(item)
    }

    fn handle(&mut self, item: Popped) {
        if self.mcap.is_none() {
            self.lost_after_stop += 1;
            return;
        }
        let res = match &item {
            Popped::Tick(r) => self.write_tick(r),
            Popped::Event(e) => self.write_event(e),
            Popped::Egm(e) => self.write_egm(e),
        };
        if let Err(e) = res {
            self.fail(&e);
        }
    }

    fn write_tick(&mut self, r: &TickHead) -> Result<(), mcap::McapError> {
        let log_time = self.start_ns + sim_time_ns(r.state.sim_time_s);
        // The tick's timeline stamp; the real publish wall clock is in /timing.
        let publish_time = log_time;
        let dropped = self.shared.dropped_ticks.load(Ordering::Relaxed) + self.shared.dropped_events.load(Ordering::Relaxed);
        let Self { mcap, channel_ids, buf, centreline_z, moving_z, pressure, bytes_since_flush, live, .. } = self;
        let centreline_z = if r.strip.centreline_dz_m > 0.0 { &*moving_z } else { &*centreline_z };
        let mcap = mcap.as_mut().expect("checked by handle");
        let mut put = |ch: Channel, buf: &Vec<u8>| -> Result<(), mcap::McapError> {
            *bytes_since_flush += buf.len() as u64 + MESSAGE_RECORD_HEADER_BYTES;
            let header = MessageHeader { channel_id: channel_ids[ch.index()], sequence: r.state.tick as u32, log_time, publish_time };
            mcap.write_to_known_channel(&header, buf)?;
            if let Some(live) = live.as_mut() {
                live.offer(ch.index(), log_time, buf, true);
            }
            Ok(())
        };
        schema::encode_joint_state(buf, r);
        put(Channel::JointState, buf)?;
        schema::encode_joint_torque(buf, r);
        put(Channel::JointTorque, buf)?;
        schema::encode_wrench(buf, r);
        put(Channel::Wrench, buf)?;
        schema::encode_strip(buf, r, pressure, centreline_z);
        put(Channel::Strip, buf)?;
        if r.has_diag {
            schema::encode_controller(buf, r);
            put(Channel::Controller, buf)?;
        }
        schema::encode_timing(buf, r, dropped);
        put(Channel::Timing, buf)?;
        self.write_scene(r, log_time)?;
        self.ticks_written += 1;
        self.last_tick = r.state.tick;
        self.last_sim_time_s = r.state.sim_time_s;
        Ok(())
    }

    fn write_egm(&mut self, e: &crate::EgmRecord) -> Result<(), mcap::McapError> {
        if !self.has_egm {
            return Ok(());
        }
        schema::encode_egm(&mut self.buf, e);
        self.bytes_since_flush += self.buf.len() as u64 + MESSAGE_RECORD_HEADER_BYTES;
        // The timeline of every channel: the run's start + simulated time (publish = log).
        let log_time = self.start_ns + sim_time_ns(e.sim_time_s);
        let header =
            MessageHeader { channel_id: self.channel_ids[Channel::Egm.index()], sequence: e.tick as u32, log_time, publish_time: log_time };
        self.mcap.as_mut().expect("checked by handle").write_to_known_channel(&header, &self.buf)?;
        if let Some(live) = self.live.as_mut() {
            live.offer(Channel::Egm.index(), log_time, &self.buf, true);
        }
        Ok(())
    }

    fn write_event(&mut self, e: &EventRecord) -> Result<(), mcap::McapError> {
        schema::encode_event(&mut self.buf, e);
        self.bytes_since_flush += self.buf.len() as u64 + MESSAGE_RECORD_HEADER_BYTES;
        let header = MessageHeader {
            channel_id: self.channel_ids[Channel::Events.index()],
            sequence: e.tick as u32,
            log_time: self.start_ns + sim_time_ns(e.sim_time_s),
            publish_time: self.start_ns + sim_time_ns(e.sim_time_s),
        };
        self.mcap.as_mut().expect("checked by handle").write_to_known_channel(&header, &self.buf)?;
        if let Some(live) = self.live.as_mut() {
            live.offer(Channel::Events.index(), header.log_time, &self.buf, false);
        }
        if let Some(ch) = self.fox.log {
            crate::scene::encode_into(&crate::scene::log_message(e, header.log_time), &mut self.buf);
            self.bytes_since_flush += self.buf.len() as u64 + MESSAGE_RECORD_HEADER_BYTES;
            let header = MessageHeader { channel_id: ch.id, ..header };
            self.mcap.as_mut().expect("checked by handle").write_to_known_channel(&header, &self.buf)?;
            if let Some(live) = self.live.as_mut() {
                live.offer(ch.live, header.log_time, &self.buf, false);
            }
        }
        self.events_written += 1;
        Ok(())
    }

    /// Every `scene_every`-th tick: the transforms and the strip scene (decided here, from the
    /// tick records, so the loop does nothing for them).
    fn write_scene(&mut self, r: &TickHead, log_time: u64) -> Result<(), mcap::McapError> {
        let Self {
            mcap,
            buf,
            bytes_since_flush,
            live,
            fox,
            scene,
            robot,
            scene_every,
            centreline_z,
            moving_z,
            pressure,
            top_uy,
            bond_peak,
            scene_scratch,
            robot_description,
            ..
        } = self;
        let centreline_z = if r.strip.centreline_dz_m > 0.0 { &*moving_z } else { &*centreline_z };
        crate::scene::raise_bond_peak(bond_peak, centreline_z, pressure);
        let (Some(cfg), Some(robot)) = (scene.as_ref(), robot.as_ref()) else { return Ok(()) };
        if !r.state.tick.is_multiple_of(*scene_every) {
            return Ok(());
        }
        let header = |channel_id| MessageHeader { channel_id, sequence: r.state.tick as u32, log_time, publish_time: log_time };
        let mcap = mcap.as_mut().expect("checked by handle");
        let mut put = |ch: FoxChannel, bytes: &[u8]| -> Result<(), mcap::McapError> {
            *bytes_since_flush += bytes.len() as u64 + MESSAGE_RECORD_HEADER_BYTES;
            mcap.write_to_known_channel(&header(ch.id), bytes)?;
            if let Some(live) = live.as_mut() {
                live.offer(ch.live, log_time, bytes, true);
            }
            Ok(())
        };
        if let Some(ch) = fox.transforms {
            crate::scene::encode_into(&crate::scene::frame_transforms(robot, cfg, &r.state.q, log_time), buf);
            put(ch, buf)?;
        }
        if let Some(ch) = fox.scene {
            let t = crate::scene::SceneTick {
                head: r,
                centreline_z_m: centreline_z,
                pressure_pa: pressure,
                top_uy_m: top_uy,
                bond_peak_pa: bond_peak,
                ns: log_time,
            };
            crate::scene::encode_scene_into(cfg, &t, scene_scratch, buf);
            put(ch, buf)?;
        }
        if let (Some(ch), true) = (fox.under_wheel, !pressure.is_empty()) {
            let json = crate::scene::under_wheel_json(r, centreline_z, pressure);
            put(ch, json.as_bytes())?;
        }
        // The robot description again for the live view (not the file), once a second of ticks:
        // a client may connect at any time.
        if let (Some(ch), Some(live)) = (fox.robot_description, live.as_mut()) {
            let ticks_per_s = if r.state.period_s > 0.0 { (1.0 / r.state.period_s).round().max(1.0) as u64 } else { 1000 };
            if r.state.tick.is_multiple_of(ticks_per_s) {
                live.offer(ch.live, log_time, robot_description, false);
            }
        }
        Ok(())
    }

    /// Closes the chunk when it is big or old enough, then checks the free disk space.
    fn maybe_flush(&mut self) {
        let Some(mcap) = self.mcap.as_mut() else { return };
        let due = self.bytes_since_flush >= self.chunk_size
            || (self.bytes_since_flush > 0 && self.last_flush.elapsed() >= self.tuning.max_flush_interval);
        if !due {
            return;
        }
        if let Err(e) = mcap.flush() {
            self.fail(&e);
            return;
        }
        if !self.chunk_complete() {
            return;
        }
        self.bytes_since_flush = 0;
        self.last_flush = Instant::now();
        if let Some(free) = free_bytes(&self.path) {
            if free < self.tuning.min_free_bytes {
                let why = format!(
                    "disk almost full: {} MiB free, below the {} MiB reserve; recording stopped at tick {}",
                    free >> 20,
                    self.tuning.min_free_bytes >> 20,
                    self.last_tick
                );
                let e = EventRecord::new(self.last_tick, self.last_sim_time_s, EventKind::RecordingError, &why);
                if let Err(err) = self.write_event(&e) {
                    self.fail(&err);
                    return;
                }
                tracing::error!(path = %self.path.display(), "{why}; the loop keeps running");
                self.stopped_early = Some(why);
                self.shared.stopped.store(true, Ordering::Relaxed);
                self.finalise();
            }
        }
    }

    /// The chunk just flushed is complete in the file: remember where it ends and what it holds,
    /// and keep the tail reserve allocated past it. False if there is no room for the reserve:
    /// then the recording is ended here, in what is left of the previous reserve.
    fn chunk_complete(&mut self) -> bool {
        let bytes = self.tally.position.load(Ordering::Relaxed);
        let crc = (!self.tally.seeked.load(Ordering::Relaxed)).then(|| self.tally.crc.lock().unwrap_or_else(|e| e.into_inner()).clone());
        self.kept = Kept {
            bytes,
            crc,
            ticks: self.ticks_written,
            events: self.events_written,
            last_tick: self.last_tick,
            last_sim_time_s: self.last_sim_time_s,
        };
        if self.reserve == 0 {
            return true;
        }
        // SAFETY: fd is the open recording, owned by self.mcap for as long as the writer runs.
        let rc = unsafe { libc::fallocate(self.fd, libc::FALLOC_FL_KEEP_SIZE, bytes as i64, self.reserve as i64) };
        if rc == 0 {
            return true;
        }
        let err = std::io::Error::last_os_error();
        match err.raw_os_error() {
            Some(libc::ENOSPC | libc::EDQUOT) => {
                let what = format!("no room to keep {} KiB allocated past the end of the file", self.reserve >> 10);
                self.stop(&err, &what);
                false
            }
            _ => {
                tracing::warn!(path = %self.path.display(), "cannot keep room past the end of the recording ({err}): a full disk will cut it mid-chunk");
                self.reserve = 0;
                true
            }
        }
    }

    /// Ends the recording after its last complete chunk because of `err` while doing `what`.
    fn stop(&mut self, err: &(dyn std::error::Error + 'static), what: &str) {
        // Not finish(): the summary would go to a failing disk. Take the file back without
        // flushing what is still buffered.
        let file = self.mcap.take().map(|m| m.into_inner().into_parts().0 .0);
        self.stop_on_error(err, what, file);
    }

    /// A hard write error (ENOSPC, EFBIG, EIO): cut the file back to its last complete chunk and
    /// end it there (event, summary metadata, footer), the same story as the reserve tells.
    fn fail(&mut self, err: &mcap::McapError) {
        self.stop(err, "write failed");
    }

    fn stop_on_error(&mut self, err: &(dyn std::error::Error + 'static), what: &str, file: Option<File>) {
        let mut why = format!(
            "{} at tick {}: {what}: {}; the file keeps the ticks up to {}",
            os_error_name(err),
            self.last_tick,
            error_chain(err),
            if self.kept.ticks > 0 { self.kept.last_tick.to_string() } else { "none".into() }
        );
        if let Some(before) = self.stopped_early.take() {
            why = format!("{before}; then {why}");
        }
        self.stopped_early = Some(why.clone());
        self.shared.stopped.store(true, Ordering::Relaxed);
        if let Some(file) = file {
            self.end_at_kept(file, &why);
        }
        tracing::error!(path = %self.path.display(), "recording stopped: {}; the loop keeps running", self.stopped_early.as_deref().unwrap_or(""));
    }

    /// Truncates the file to its last complete chunk and appends the finale there.
    fn end_at_kept(&mut self, file: File, why: &str) {
        use std::os::unix::fs::FileExt;
        let lost = (self.ticks_written - self.kept.ticks) + (self.events_written - self.kept.events);
        self.lost_after_stop += lost;
        self.ticks_written = self.kept.ticks;
        self.events_written = self.kept.events;
        let e = EventRecord::new(self.kept.last_tick, self.kept.last_sim_time_s, EventKind::RecordingError, why);
        self.events_written += 1;
        let finale = self.finale(&e);
        let end = self.kept.bytes + finale.len() as u64;
        // the second set_len gives back what is left of the tail reserve
        let res = file.set_len(self.kept.bytes).and_then(|_| file.write_all_at(&finale, self.kept.bytes)).and_then(|_| file.set_len(end));
        match res {
            Ok(()) => self.finalised = true,
            Err(err) => {
                self.events_written -= 1;
                let _ = file.set_len(self.kept.bytes);
                tracing::error!(path = %self.path.display(), "ending the recording after its last complete chunk failed: {err}");
                if let Some(w) = self.stopped_early.as_mut() {
                    w.push_str(&format!("; no room for the footer ({err}): the file ends after its last complete chunk"));
                }
            }
        }
    }

    /// The end of a file stopped by a write error, hand-encoded (the mcap writer is broken by
    /// then): the `/events` entry as a message outside any chunk, the `recording_summary`
    /// metadata, a data-end record with the data section's CRC (so that these two records are
    /// checked too) and a footer without summary.
    fn finale(&mut self, e: &EventRecord) -> Vec<u8> {
        fn record(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
            out.push(opcode);
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(body);
        }
        fn string(out: &mut Vec<u8>, s: &str) {
            out.extend_from_slice(&(s.len() as u32).to_le_bytes());
            out.extend_from_slice(s.as_bytes());
        }
        schema::encode_event(&mut self.buf, e);
        let mut out = Vec::new();
        let mut body = Vec::new();
        body.extend_from_slice(&self.channel_ids[Channel::Events.index()].to_le_bytes());
        body.extend_from_slice(&(e.tick as u32).to_le_bytes());
        let ns = self.start_ns + sim_time_ns(e.sim_time_s);
        body.extend_from_slice(&ns.to_le_bytes());
        body.extend_from_slice(&ns.to_le_bytes());
        body.extend_from_slice(&self.buf);
        record(&mut out, op::MESSAGE, &body);
        let mut entries = Vec::new();
        for (k, v) in self.summary_metadata() {
            string(&mut entries, &k);
            string(&mut entries, &v);
        }
        body.clear();
        string(&mut body, "recording_summary");
        body.extend_from_slice(&(entries.len() as u32).to_le_bytes());
        body.extend_from_slice(&entries);
        record(&mut out, op::METADATA, &body);
        let crc = self.kept.crc.clone().map_or(0, |mut h| {
            h.update(&out);
            h.finalize()
        });
        record(&mut out, op::DATA_END, &crc.to_le_bytes());
        record(&mut out, op::FOOTER, &[0u8; 20]);
        out.extend_from_slice(crate::MCAP_MAGIC);
        out
    }

    /// The `recording_summary` metadata: counters, last tick, why it stopped early.
    fn summary_metadata(&self) -> BTreeMap<String, String> {
        let mut meta = BTreeMap::new();
        meta.insert("ticks_written".to_string(), self.ticks_written.to_string());
        meta.insert("events_written".to_string(), self.events_written.to_string());
        meta.insert("dropped_ticks".to_string(), self.shared.dropped_ticks.load(Ordering::Relaxed).to_string());
        meta.insert("dropped_events".to_string(), self.shared.dropped_events.load(Ordering::Relaxed).to_string());
        meta.insert("last_tick".to_string(), if self.mcap.is_some() { self.last_tick } else { self.kept.last_tick }.to_string());
        meta.insert("stopped_early".to_string(), self.stopped_early.clone().unwrap_or_default());
        meta.insert("finished_wall_ns".to_string(), wall_clock_ns().to_string());
        if let Some(live) = self.live.as_ref().map(LiveView::summary) {
            meta.insert("live_sent".to_string(), live.sent.to_string());
            meta.insert("live_dropped".to_string(), live.dropped.to_string());
        }
        meta
    }

    /// Writes the counters, summary, index and footer. Returns whether the file is finalised.
    fn finalise(&mut self) -> bool {
        if self.mcap.is_none() {
            return false;
        }
        let meta = self.summary_metadata();
        let mut mcap = self.mcap.take().expect("checked");
        let res =
            mcap.write_metadata(&Metadata { name: "recording_summary".into(), metadata: meta }).and_then(|_| mcap.finish().map(|_| ()));
        // The disk failed under the summary: end the file after its last complete chunk.
        let (err, file) = match res {
            Ok(()) => {
                use std::io::Write;
                let mut w = mcap.into_inner();
                match w.flush() {
                    Ok(()) => {
                        self.finalised = true;
                        // give back the tail reserve (a file system keeps it past close)
                        let _ = w.into_parts().0 .0.set_len(self.tally.position.load(Ordering::Relaxed));
                        return true;
                    }
                    Err(e) => (mcap::McapError::from(e), w.into_parts().0 .0),
                }
            }
            Err(e) => (e, mcap.into_inner().into_parts().0 .0),
        };
        self.stop_on_error(&err, "write failed", Some(file));
        self.finalised
    }
}

/// What an I/O error inside `e` is, for the stop reason: "disk full (ENOSPC)", ...
fn os_error_name(e: &(dyn std::error::Error + 'static)) -> &'static str {
    let mut cur = Some(e);
    while let Some(c) = cur {
        if let Some(code) = c.downcast_ref::<std::io::Error>().and_then(std::io::Error::raw_os_error) {
            return match code {
                libc::ENOSPC => "disk full (ENOSPC)",
                libc::EDQUOT => "disk quota exceeded (EDQUOT)",
                libc::EFBIG => "file too large (EFBIG)",
                libc::EIO => "I/O error (EIO)",
                _ => "write error",
            };
        }
        cur = c.source();
    }
    "write error"
}

/// Free bytes for unprivileged users on the file system holding `path`.
fn free_bytes(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
    // SAFETY: a zeroed statvfs is a valid value of this plain C struct.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: c is NUL-terminated, s is a valid statvfs to fill.
    if unsafe { libc::statvfs(c.as_ptr(), &mut s) } != 0 {
        return None;
    }
    Some(s.f_bavail as u64 * s.f_frsize as u64)
}

/// One Foxglove channel of a recording: where it is written and where the live view serves it.
#[derive(Debug, Clone, Copy)]
struct FoxChannel {
    /// MCAP channel id.
    id: u16,
    /// Index among the live view's channels (after the [`CHANNELS`] it serves).
    live: usize,
}

/// The Foxglove channels of a recording (None: not written in this one).
#[derive(Debug, Default, Clone, Copy)]
struct FoxgloveChannels {
    robot_description: Option<FoxChannel>,
    transforms: Option<FoxChannel>,
    scene: Option<FoxChannel>,
    under_wheel: Option<FoxChannel>,
    log: Option<FoxChannel>,
}

/// A Foxglove channel's topic, schema (name, encoding, data) and message encoding.
struct FoxDef {
    topic: &'static str,
    schema: (String, String, Vec<u8>),
    message_encoding: &'static str,
}

impl FoxgloveChannels {
    /// `/log` always, and with a scene `/robot_description`, `/tf`, `/strip_scene` and
    /// `/pressure_under_wheel`, in registration order (the file's and the live view's).
    fn defs(scene: Option<&crate::scene::SceneConfig>) -> Vec<FoxDef> {
        use crate::scene::*;
        let def = |topic, schema, message_encoding| FoxDef { topic, schema, message_encoding };
        let mut d = Vec::new();
        if scene.is_some() {
            let string = ("std_msgs/msg/String".to_string(), SCHEMA_ENCODING.to_string(), ROBOT_DESCRIPTION_SCHEMA.as_bytes().to_vec());
            d.push(def(ROBOT_DESCRIPTION_TOPIC, string, MESSAGE_ENCODING));
            d.push(def(TRANSFORMS_TOPIC, schema_of::<foxglove::messages::FrameTransforms>(), "protobuf"));
            d.push(def(SCENE_TOPIC, schema_of::<foxglove::messages::SceneUpdate>(), "protobuf"));
            let json = ("rig.PressureUnderWheel".to_string(), "jsonschema".to_string(), UNDER_WHEEL_SCHEMA.as_bytes().to_vec());
            d.push(def(UNDER_WHEEL_TOPIC, json, "json"));
        }
        d.push(def(LOG_TOPIC, schema_of::<foxglove::messages::Log>(), "protobuf"));
        d
    }

    /// Registers `defs` in the file; the live view numbers them after its `ros_channels` first
    /// [`CHANNELS`].
    fn register(mcap: &mut McapFile, defs: &[FoxDef], ros_channels: usize) -> Result<Self, mcap::McapError> {
        let mut ch = FoxgloveChannels::default();
        for (i, d) in defs.iter().enumerate() {
            let (name, encoding, data) = &d.schema;
            let schema_id = mcap.add_schema(name, encoding, data)?;
            let id = mcap.add_channel(schema_id, d.topic, d.message_encoding, &BTreeMap::new())?;
            let slot = match d.topic {
                crate::scene::ROBOT_DESCRIPTION_TOPIC => &mut ch.robot_description,
                crate::scene::TRANSFORMS_TOPIC => &mut ch.transforms,
                crate::scene::SCENE_TOPIC => &mut ch.scene,
                crate::scene::UNDER_WHEEL_TOPIC => &mut ch.under_wheel,
                _ => &mut ch.log,
            };
            *slot = Some(FoxChannel { id, live: ros_channels + i });
        }
        Ok(ch)
    }
}
