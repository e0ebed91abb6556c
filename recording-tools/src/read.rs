//! Reading a recording back into columns, one `Vec` per channel.
//!
//! [`Recording::open`] walks the file record by record (no index needed). Every chunk is
//! decompressed whole and its CRC checked before any of its records is decoded, so nothing of a
//! chunk that is incomplete or fails its CRC is ever used: reading stops at the first bad chunk
//! and [`Recording::integrity`] says where and why. It tells apart a file cut short (a killed
//! run), a complete file damaged in the middle, and a recording the plant ended early on purpose
//! (disk full, write error). [`Recording::open_complete`] refuses the first two.

use mcap::records::{op, MessageHeader, Record};
use messages::{ControllerDiagnostics, JointState, Wrench};
use recordings::run_metadata::{MetadataError, RunMetadata, RECORD_NAME};
use recordings::schema::{self, Channel, MESSAGE_ENCODING, SCHEMA_ENCODING};
pub use recordings::schema::{EventRow, StripRow, TimingRow, TorqueRow};
use recordings::EventKind;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use thiserror::Error;

pub use recordings::MCAP_MAGIC;

/// Opcode and length in front of every MCAP record, bytes.
const RECORD_HEAD: usize = 1 + 8;

/// A complete file ends with a footer record (20 bytes of body) and the magic.
const FOOTER_TAIL: usize = RECORD_HEAD + 20 + MCAP_MAGIC.len();

/// Which of our channels a read decodes into columns ([`Recording::open_channels`]). Every
/// chunk is still decompressed and CRC-checked and every schema and channel record checked, so
/// the integrity found is the same; the messages of the other channels are skipped, and their
/// columns stay empty. `/joint_state` is always decoded: the ticks, and the integrity's first
/// tick lost, are its.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channels(u16);

impl Channels {
    /// Every channel ([`Recording::open`]).
    pub const ALL: Channels = Channels(u16::MAX);

    /// These channels only (and `/joint_state`).
    pub const fn of(list: &[Channel]) -> Channels {
        let mut bits = 1 << Channel::JointState.index();
        let mut i = 0;
        while i < list.len() {
            bits |= 1 << list[i].index();
            i += 1;
        }
        Channels(bits)
    }

    /// Whether `ch` is decoded.
    pub const fn has(self, ch: Channel) -> bool {
        self.0 & (1 << ch.index()) != 0
    }
}

#[derive(Debug, Error)]
pub enum ReadError {
    /// The OS error is part of the message, not a `source` (printed once in an error chain).
    #[error("cannot read recording {path}: {cause}")]
    Io { path: PathBuf, cause: std::io::Error },
    #[error("{path} is not an MCAP recording (it starts with {start:02x?}, an MCAP file starts with {MCAP_MAGIC:02x?})")]
    NotMcap { path: PathBuf, start: Vec<u8> },
    #[error("{path} is truncated (cut short, no footer: the recording process was probably killed) after {ticks} intact ticks: {damage}")]
    Cut { path: PathBuf, ticks: usize, damage: Damage },
    #[error("{path} is corrupt (damaged after it was written) after {ticks} intact ticks: {damage}")]
    Corrupt { path: PathBuf, ticks: usize, damage: Damage },
    #[error("{path} is an MCAP file but not a rig recording: it has no {topic} channel with schema {schema}")]
    Foreign { path: PathBuf, topic: &'static str, schema: &'static str },
    #[error("{path}: channel {topic} has schema {found}, this reader knows {expected:?} (ros2msg/cdr) with other fields; the file was written by another version")]
    SchemaMismatch { path: PathBuf, topic: String, found: String, expected: &'static str },
    #[error("{path}: in a chunk that passed its CRC, {what}; the file was written by another writer or version")]
    Format { path: PathBuf, what: String },
    #[error("{path}: message {sequence} on {topic} does not decode: {cause}")]
    Decode { path: PathBuf, topic: String, sequence: u32, cause: recordings::cdr::CdrError },
}

/// Where and why reading stopped early.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Damage {
    /// The chunk (counting from 0 in file order) where reading stopped, if it stopped at one.
    pub chunk: Option<usize>,
    /// Byte offset of the record where reading stopped.
    pub offset: u64,
    /// The first tick not read (every tick before it was read intact); None if no tick is lost.
    pub first_tick_lost: Option<u64>,
    pub reason: String,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.chunk {
            Some(c) => write!(f, "chunk {c} at byte {}: {}", self.offset, self.reason)?,
            None => write!(f, "at byte {}: {}", self.offset, self.reason)?,
        }
        match self.first_tick_lost {
            Some(t) => write!(f, "; reading stopped there, the first tick lost is {t}"),
            None => write!(f, "; every tick before it is intact"),
        }
    }
}

/// How a recording ends, as the reader found it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Integrity {
    /// Footer and end magic present, every chunk decompressed and passed its CRC.
    #[default]
    Complete,
    /// Complete and intact, but the plant ended the recording before the run ended (disk full,
    /// write error): the writer's reason, as its `recording_summary` metadata says.
    StoppedEarly(String),
    /// No footer: the file ends early, as a killed run leaves it.
    Cut(Damage),
    /// A chunk fails its CRC or does not decompress, or a record is damaged, in a file that is
    /// complete (or, cut as well, where the damage comes before the cut).
    Corrupt(Damage),
}

impl Integrity {
    /// Short name for tables and report.json: complete, stopped_early, cut or corrupt.
    pub fn kind(&self) -> &'static str {
        match self {
            Integrity::Complete => "complete",
            Integrity::StoppedEarly(_) => "stopped_early",
            Integrity::Cut(_) => "cut",
            Integrity::Corrupt(_) => "corrupt",
        }
    }

    /// Where and why reading stopped, for a cut or corrupt file.
    pub fn damage(&self) -> Option<&Damage> {
        match self {
            Integrity::Cut(d) | Integrity::Corrupt(d) => Some(d),
            _ => None,
        }
    }

    /// One sentence on how the file ends (None for a complete file).
    pub fn describe(&self) -> Option<String> {
        match self {
            Integrity::Complete => None,
            Integrity::StoppedEarly(why) => Some(format!("the plant stopped the recording early: {why}")),
            Integrity::Cut(d) => Some(format!("cut short (no footer: the recording process was probably killed): {d}")),
            Integrity::Corrupt(d) => Some(format!("corrupt (damaged after it was written): {d}")),
        }
    }
}

/// A recording read into columns. Each tick channel holds one row per recorded tick, in order.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    pub path: PathBuf,
    /// MCAP metadata records by name: `rig` (written at start: rig, mode, scenario, ...),
    /// `recording_summary` (written by `finish`: counters; absent in a cut file).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    pub joint_state: Vec<JointState>,
    pub joint_torque: Vec<TorqueRow>,
    pub wrench: Vec<Wrench>,
    pub strip: Vec<StripRow>,
    /// Only ticks for which the controller published diagnostics.
    pub controller: Vec<ControllerDiagnostics>,
    pub timing: Vec<TimingRow>,
    pub events: Vec<EventRow>,
    /// `/egm`, one row per EGM cycle (EGM runs only).
    pub egm: Vec<recordings::EgmRecord>,
    /// Log time (Unix ns: the run's wall-clock start + simulated time) of each `joint_state` row.
    pub log_time_ns: Vec<u64>,
    /// z of the centre-line nodes as the first `/strip` message carrying them has it, m.
    pub strip_centreline_z_m: Vec<f32>,
    /// Per `/strip` row, its nodes' z where they differ from `strip_centreline_z_m` (a windowed
    /// long strip: the nodes around the wheel move with it), else empty. See [`Self::strip_row_z`].
    pub strip_row_z_m: Vec<Vec<f32>>,
    /// How the file ends: complete, stopped early by the plant, cut short or corrupt.
    pub integrity: Integrity,
}

/// A schema record as read: name, encoding, text.
type SchemaRec = (String, String, Vec<u8>);

/// Schemas and channels seen so far; channel id -> which of ours (None: not ours).
#[derive(Default)]
struct Links {
    schemas: HashMap<u16, SchemaRec>,
    channels: HashMap<u16, Option<Channel>>,
    /// The channels decoded; the others' messages are skipped.
    wanted: Channels,
}

impl Default for Channels {
    fn default() -> Self {
        Channels::ALL
    }
}

/// Why the record walk stopped: the bytes ran out (a cut) or a whole record is bad.
enum Stop {
    Short(String),
    Bad(String),
}

/// How much of a followed file is read before it is known to be the rig's: its header, schemas,
/// channels and run metadata (with the scenario's text) come first, within a few kB.
const FOLLOW_PROBE_BYTES: usize = 1 << 20;

/// Whether the writer of a followed recording ([`Recording::follow_channels`]) is still at it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Writing {
    /// The file may still grow.
    Running,
    /// The file is finished (or its writer gone): read the rest and judge it.
    Finished,
    /// Nobody wants the result any more.
    Abandoned,
}

/// Where a walk of a recording's records stands: what it read and where it goes on.
struct Walk {
    rec: Recording,
    links: Links,
    /// The next record's byte.
    at: usize,
    /// Chunks read so far.
    chunk: usize,
    /// The chunk the walk is in when it stops, if it stops at one.
    in_chunk: Option<usize>,
    saw_data_end: bool,
    /// Stop (as [`Step::More`]) right after the run metadata: a follow that has yet to learn
    /// whose file it is reads no further.
    pause_at_run_metadata: bool,
}

/// How far a walk over the bytes so far got.
enum Step {
    /// The bytes end inside or after a record, and more may come.
    More,
    /// The walk is over: at the data end (None) or at damage.
    Stopped(Option<Stop>),
}

/// The records of a chunk: decompressed and verified here, or ahead on a second thread.
trait ChunkSource {
    /// The records of the chunk record at byte `at` (body `body`), or why it is bad.
    fn chunk(&mut self, at: usize, body: &[u8]) -> Result<&[u8], String>;
}

impl ChunkSource for Unpacker {
    fn chunk(&mut self, _at: usize, body: &[u8]) -> Result<&[u8], String> {
        self.verified_chunk(body)
    }
}

impl ChunkSource for Ahead {
    fn chunk(&mut self, at: usize, body: &[u8]) -> Result<&[u8], String> {
        Ahead::chunk(self, at, body)
    }
}

impl Walk {
    fn new(path: &Path, wanted: Channels) -> Self {
        Walk {
            rec: Recording { path: path.into(), ..Default::default() },
            links: Links { wanted, ..Default::default() },
            at: MCAP_MAGIC.len(),
            chunk: 0,
            in_chunk: None,
            saw_data_end: false,
            pause_at_run_metadata: false,
        }
    }

    /// Walks on over `bytes` (the file from its start, as far as it is known). `growing`: the
    /// file may still grow, so bytes that end inside a record say [`Step::More`] (the walk stays
    /// before that record) rather than a cut.
    fn on(&mut self, path: &Path, bytes: &[u8], chunks: &mut impl ChunkSource, growing: bool) -> Result<Step, ReadError> {
        loop {
            self.in_chunk = (bytes.get(self.at) == Some(&op::CHUNK)).then_some(self.chunk);
            let (opcode, body, next) = match record_at(bytes, self.at) {
                Ok(Some(r)) => r,
                Ok(None) | Err(_) if growing => return Ok(Step::More),
                Ok(None) => return Ok(Step::Stopped(Some(Stop::Short("the file ends there, without a data-end record".into())))),
                Err(why) => return Ok(Step::Stopped(Some(Stop::Short(why)))),
            };
            match opcode {
                op::CHUNK => {
                    match chunks.chunk(self.at, body) {
                        Ok(records) => self.rec.read_records(path, records, &mut self.links)?,
                        Err(why) => return Ok(Step::Stopped(Some(Stop::Bad(why)))),
                    }
                    self.chunk += 1;
                }
                op::DATA_END => {
                    self.saw_data_end = true;
                    let saved = body.get(..4).map_or(0, |b| u32::from_le_bytes(b.try_into().unwrap()));
                    let computed = crc32fast::hash(&bytes[..self.at]);
                    if saved != 0 && saved != computed {
                        return Ok(Step::Stopped(Some(Stop::Bad(format!(
                            "the data section fails its CRC (stored {saved:08x}, computed {computed:08x}): a record outside the chunks is damaged, every chunk passed its CRC"
                        )))));
                    }
                    return Ok(Step::Stopped(None));
                }
                op::FOOTER => return Ok(Step::Stopped(Some(Stop::Bad("a footer comes before the data-end record".into())))),
                op::SCHEMA | op::CHANNEL | op::MESSAGE | op::METADATA => {
                    if let Err(why) = self.rec.read_record(path, opcode, body, &mut self.links)? {
                        return Ok(Step::Stopped(Some(Stop::Bad(why))));
                    }
                    if opcode == op::METADATA && self.pause_at_run_metadata && self.rec.metadata.contains_key(RECORD_NAME) {
                        self.at = next;
                        return Ok(Step::More);
                    }
                }
                _ => {}
            }
            self.at = next;
        }
    }

    /// The recording read, judged from where the walk stopped and how the whole file ends.
    fn finish(self, path: &Path, bytes: &[u8], stop: Option<Stop>) -> Result<Recording, ReadError> {
        let Walk { mut rec, at, in_chunk, saw_data_end, .. } = self;
        let complete = bytes.len() >= MCAP_MAGIC.len() + FOOTER_TAIL
            && bytes.ends_with(MCAP_MAGIC)
            && bytes[bytes.len() - FOOTER_TAIL] == op::FOOTER
            && bytes[bytes.len() - FOOTER_TAIL + 1..][..8] == 20u64.to_le_bytes();
        let first_tick_lost = (!saw_data_end).then(|| rec.joint_state.last().map_or(0, |s| s.tick + 1));
        let damage = |reason: String| Damage { chunk: in_chunk, offset: at as u64, first_tick_lost, reason };
        rec.integrity = match stop {
            Some(Stop::Short(why)) if !complete => Integrity::Cut(damage(why)),
            Some(Stop::Short(why)) => Integrity::Corrupt(damage(format!("{why}, yet the file ends with a footer"))),
            Some(Stop::Bad(why)) if !complete => Integrity::Corrupt(damage(format!("{why} (the file has no footer either)"))),
            Some(Stop::Bad(why)) => Integrity::Corrupt(damage(why)),
            None if !complete => Integrity::Cut(Damage {
                chunk: None,
                offset: at as u64,
                first_tick_lost: None,
                reason: "the summary or footer after the data-end record is missing or cut".into(),
            }),
            None => match rec.summary_metadata("stopped_early").filter(|s| !s.is_empty()) {
                Some(why) => Integrity::StoppedEarly(why.to_string()),
                None => Integrity::Complete,
            },
        };
        if !rec.metadata.contains_key(RECORD_NAME) && rec.joint_state.is_empty() && rec.integrity == Integrity::Complete {
            let first = Channel::JointState.def();
            return Err(ReadError::Foreign { path: path.into(), topic: first.topic, schema: first.schema_name });
        }
        Ok(rec)
    }
}

impl Recording {
    /// Reads a recording; a cut or corrupt file yields the ticks before the damage and says where
    /// in `integrity`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        Self::open_channels(path, Channels::ALL)
    }

    /// Like [`open`](Self::open), decoding only the `wanted` channels' messages (the others'
    /// columns stay empty; the integrity is found the same, from every chunk).
    pub fn open_channels(path: impl AsRef<Path>, wanted: Channels) -> Result<Self, ReadError> {
        let path = path.as_ref();
        let io = |cause| ReadError::Io { path: path.into(), cause };
        let file = std::fs::File::open(path).map_err(io)?;
        if !file.metadata().map_err(io)?.is_file() {
            return Err(io(std::io::Error::other("not a regular file")));
        }
        let map = Mapped::new(&file).map_err(io)?;
        Self::from_bytes_channels(path, map.bytes(), wanted)
    }

    /// Like [`open`](Self::open) but a cut or corrupt file is an error (one the plant stopped
    /// early is complete and intact, so it is not).
    pub fn open_complete(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        let rec = Self::open(path)?;
        match rec.damage_error() {
            Some(e) => Err(e),
            None => Ok(rec),
        }
    }

    /// The error [`open_complete`](Self::open_complete) would give, for a lenient reader.
    pub fn damage_error(&self) -> Option<ReadError> {
        let (path, ticks) = (self.path.clone(), self.joint_state.len());
        match &self.integrity {
            Integrity::Cut(d) => Some(ReadError::Cut { path, ticks, damage: d.clone() }),
            Integrity::Corrupt(d) => Some(ReadError::Corrupt { path, ticks, damage: d.clone() }),
            _ => None,
        }
    }

    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, ReadError> {
        Self::from_bytes_channels(path, bytes, Channels::ALL)
    }

    /// [`from_bytes`](Self::from_bytes) decoding the `wanted` channels only.
    pub fn from_bytes_channels(path: &Path, bytes: &[u8], wanted: Channels) -> Result<Self, ReadError> {
        if !bytes.starts_with(MCAP_MAGIC) {
            return Err(ReadError::NotMcap { path: path.into(), start: bytes[..bytes.len().min(8)].to_vec() });
        }
        let mut walk = Walk::new(path, wanted);
        // The chunks are decompressed and checked ahead, on a second thread, while this one
        // decodes the chunk before (`Ahead`).
        let stop = std::thread::scope(|scope| -> Result<_, ReadError> {
            let mut ahead = Ahead::start(scope, bytes);
            match walk.on(path, bytes, &mut ahead, false)? {
                Step::Stopped(stop) => Ok(stop),
                Step::More => unreachable!("a walk of the whole file stops"),
            }
        })?;
        walk.finish(path, bytes, stop)
    }

    /// Reads the recording at `path` while a plant still writes it, so that little is left to
    /// read when it is finished (`rig run`'s summary: the sunroof's 24 MB took 0.15 s to read
    /// after the run, 2026-12-07). Follows the file as it grows, decoding each chunk once whole;
    /// `progress` says whether the writer is still at it. A file whose run metadata names another
    /// rig than `rig` (the last run's at the same path, before the plant truncates it) is read
    /// again from the start once it does. Once `progress` says [`Writing::Finished`] the rest is
    /// read and judged exactly as [`open_channels`](Self::open_channels) would judge the whole
    /// file; [`Writing::Abandoned`] ends the follow with None. Polls every `poll`, waiting with
    /// [`std::thread::park_timeout`]: whoever changes `progress` can unpark this thread to be
    /// heard at once.
    pub fn follow_channels(
        path: &Path,
        wanted: Channels,
        rig: &str,
        poll: std::time::Duration,
        progress: &dyn Fn() -> Writing,
    ) -> Option<Result<Self, ReadError>> {
        use std::io::Read;
        let mut bytes: Vec<u8> = Vec::new();
        let mut file: Option<std::fs::File> = None;
        let mut walk = Walk::new(path, wanted);
        let mut unpack = Unpacker::default();
        // Whether the file is this rig's: its run metadata came and names `rig`.
        let mut ours = false;
        // Another rig's file as last seen (length, modification time): not read again unchanged.
        let mut stale: Option<(u64, Option<std::time::SystemTime>)> = None;
        let seen = || std::fs::metadata(path).ok().filter(|m| m.is_file()).map(|m| (m.len(), m.modified().ok()));
        let io = |cause| ReadError::Io { path: path.into(), cause };
        loop {
            // Read before reading the file: what was written by then is in the file.
            let writing = progress();
            if writing == Writing::Abandoned {
                return None;
            }
            let finished = writing == Writing::Finished;
            if !ours && finished {
                // never found to be ours: read as a read of it after the run would read it
                return Some(Self::open_channels(path, wanted));
            }
            if !ours {
                // Its start only (the run metadata comes before the first message), up to that
                // record; again from the start whenever it turns out to be another's (or not an
                // MCAP file).
                if file.is_none() && (stale.is_none() || seen() != stale) {
                    file = std::fs::File::open(path).ok().filter(|f| f.metadata().is_ok_and(|m| m.is_file()));
                }
                if let Some(f) = file.as_mut() {
                    let room = FOLLOW_PROBE_BYTES.saturating_sub(bytes.len()) as u64;
                    if let Err(e) = f.by_ref().take(room).read_to_end(&mut bytes) {
                        return Some(Err(io(e)));
                    }
                }
                walk.pause_at_run_metadata = true;
                let walked = bytes.starts_with(MCAP_MAGIC).then(|| walk.on(path, &bytes, &mut unpack, true));
                let meta_rig = walk.rec.metadata.get(RECORD_NAME).map(|m| m.get("rig").map(String::as_str) == Some(rig));
                match (walked, meta_rig) {
                    (Some(Ok(_)), Some(true)) => {
                        ours = true;
                        walk.pause_at_run_metadata = false;
                    }
                    (Some(Ok(Step::More)), None) if bytes.len() < FOLLOW_PROBE_BYTES => {}
                    (None, _) if bytes.len() < MCAP_MAGIC.len() => {}
                    (_, other_rig) => {
                        stale = if other_rig == Some(false) { seen() } else { None };
                        (bytes, file, walk) = (Vec::new(), None, Walk::new(path, wanted));
                    }
                }
            }
            if ours {
                if let Some(f) = file.as_mut() {
                    if let Err(e) = f.read_to_end(&mut bytes) {
                        return Some(Err(io(e)));
                    }
                }
                if finished {
                    // The whole file, judged as a read of it after the run would judge it.
                    let stop = match walk.on(path, &bytes, &mut unpack, false) {
                        Ok(Step::Stopped(stop)) => stop,
                        Ok(Step::More) => unreachable!("a walk of the whole file stops"),
                        Err(e) => return Some(Err(e)),
                    };
                    return Some(walk.finish(path, &bytes, stop));
                }
                if let Err(e) = walk.on(path, &bytes, &mut unpack, true) {
                    return Some(Err(e));
                }
            }
            std::thread::park_timeout(poll);
        }
    }

    /// Reads the records of a verified chunk.
    fn read_records(&mut self, path: &Path, records: &[u8], links: &mut Links) -> Result<(), ReadError> {
        let mut at = 0;
        while let Ok(Some((opcode, body, next))) = record_at(records, at) {
            if let Err(what) = self.read_record(path, opcode, body, links)? {
                // the chunk passed its CRC, so its writer wrote this: not damage but another format
                return Err(ReadError::Format { path: path.into(), what });
            }
            at = next;
        }
        Ok(())
    }

    /// One schema, channel, message or metadata record. Err(why) (inner) if it does not parse.
    fn read_record(&mut self, path: &Path, opcode: u8, body: &[u8], links: &mut Links) -> Result<Result<(), String>, ReadError> {
        let record = match mcap::parse_record(opcode, body) {
            Ok(r) => r,
            Err(e) => return Ok(Err(format!("a record (opcode {opcode:#04x}) does not parse: {e}"))),
        };
        match record {
            Record::Schema { header, data } => {
                links.schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(ch) => {
                let ours = Channel::of_topic(&ch.topic);
                if let Some(ours) = ours {
                    check_schema(path, &ch, links.schemas.get(&ch.schema_id), ours)?;
                }
                links.channels.insert(ch.id, ours);
            }
            Record::Message { header, data } => match links.channels.get(&header.channel_id) {
                Some(Some(ch)) if links.wanted.has(*ch) => self.push_message(path, *ch, &header, &data)?,
                Some(Some(_)) => {}
                Some(None) => {}
                None => {
                    return Ok(Err(format!("message {} is on channel {}, which was never defined", header.sequence, header.channel_id)))
                }
            },
            Record::Metadata(m) => {
                self.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
        Ok(Ok(()))
    }

    fn push_message(&mut self, path: &Path, ch: Channel, m: &MessageHeader, data: &[u8]) -> Result<(), ReadError> {
        let bad = |source| ReadError::Decode { path: path.into(), topic: ch.def().topic.into(), sequence: m.sequence, cause: source };
        match ch {
            Channel::JointState => {
                self.joint_state.push(schema::decode_joint_state(data).map_err(bad)?);
                self.log_time_ns.push(m.log_time);
            }
            Channel::JointTorque => self.joint_torque.push(schema::decode_joint_torque(data).map_err(bad)?),
            Channel::Wrench => self.wrench.push(schema::decode_wrench(data).map_err(bad)?),
            Channel::Strip => {
                let (row, z) = schema::decode_strip(data, true).map_err(bad)?;
                let z = z.unwrap_or_default();
                if self.strip_centreline_z_m.is_empty() {
                    self.strip_centreline_z_m = z;
                    self.strip_row_z_m.push(Vec::new());
                } else if z != self.strip_centreline_z_m {
                    self.strip_row_z_m.push(z);
                } else {
                    self.strip_row_z_m.push(Vec::new());
                }
                self.strip.push(row);
            }
            Channel::Controller => self.controller.push(schema::decode_controller(data).map_err(bad)?),
            Channel::Timing => self.timing.push(schema::decode_timing(data).map_err(bad)?),
            Channel::Events => self.events.push(schema::decode_event(data, m.publish_time).map_err(bad)?),
            Channel::Egm => self.egm.push(schema::decode_egm(data).map_err(bad)?),
        }
        Ok(())
    }

    /// A value of the `rig` metadata written at the start (rig, mode, scenario, ...), untyped:
    /// [`Self::run_metadata`] reads the run's description whole.
    pub fn rig_metadata(&self, key: &str) -> Option<&str> {
        self.metadata.get(RECORD_NAME)?.get(key).map(String::as_str)
    }

    /// The run's description as the plant wrote it; a required key missing is an error naming it.
    pub fn run_metadata(&self) -> Result<RunMetadata, MetadataError> {
        RunMetadata::from_entries(self.metadata.get(RECORD_NAME).ok_or(MetadataError::NoRecord)?)
    }

    /// The run's wall-clock start (Unix ns, metadata `rig/start_wall_ns`; 0 in files before
    /// format 2): log time = this + simulated time.
    pub fn start_wall_ns(&self) -> u64 {
        self.rig_metadata("start_wall_ns").and_then(|v| v.parse().ok()).unwrap_or(0)
    }

    /// A value of the `recording_summary` metadata written by `finish`.
    pub fn summary_metadata(&self, key: &str) -> Option<&str> {
        self.metadata.get("recording_summary")?.get(key).map(String::as_str)
    }

    /// Records the recorder dropped: from the final summary, else the last `/timing` row.
    pub fn dropped(&self) -> u64 {
        let from_summary =
            ["dropped_ticks", "dropped_events"].iter().filter_map(|k| self.summary_metadata(k)?.parse::<u64>().ok()).reduce(|a, b| a + b);
        from_summary.unwrap_or_else(|| self.timing.last().map_or(0, |t| t.recorder_dropped))
    }

    /// Control period, s (from the first joint state).
    pub fn period_s(&self) -> f64 {
        self.joint_state.first().map_or(0.0, |s| s.period_s)
    }

    /// Events of one kind.
    pub fn events_of(&self, kind: EventKind) -> impl Iterator<Item = &EventRow> {
        self.events.iter().filter(move |e| e.kind == Some(kind))
    }

    /// Checks that every tick channel holds the same consecutive ticks with no gap, and that
    /// `/controller` ticks are a subset in order. Returns the tick range.
    pub fn check_continuity(&self) -> Result<std::ops::RangeInclusive<u64>, String> {
        let cols: [(&str, Vec<u64>); 5] = [
            ("/joint_state", self.joint_state.iter().map(|r| r.tick).collect()),
            ("/joint_torque", self.joint_torque.iter().map(|r| r.tick).collect()),
            ("/wrench", self.wrench.iter().map(|r| r.tick).collect()),
            ("/strip", self.strip.iter().map(|r| r.tick).collect()),
            ("/timing", self.timing.iter().map(|r| r.tick).collect()),
        ];
        let first = *cols[0].1.first().ok_or("the recording has no /joint_state messages")?;
        let last = *cols[0].1.last().unwrap();
        for (topic, ticks) in &cols {
            if let Some(w) = ticks.windows(2).find(|w| w[1] != w[0] + 1) {
                return Err(format!("{topic}: tick {} is followed by tick {} (gap or reorder)", w[0], w[1]));
            }
            if ticks.first() != Some(&first) || ticks.last() != Some(&last) {
                return Err(format!("{topic}: ticks {:?}..={:?}, /joint_state has {first}..={last}", ticks.first(), ticks.last()));
            }
        }
        if let Some(w) = self.controller.windows(2).find(|w| w[1].tick <= w[0].tick) {
            return Err(format!("/controller: tick {} is followed by tick {}", w[0].tick, w[1].tick));
        }
        if let Some(c) = self.controller.iter().find(|c| c.tick < first || c.tick > last) {
            return Err(format!("/controller: tick {} is outside {first}..={last}", c.tick));
        }
        Ok(first..=last)
    }

    /// z of the centre-line nodes, m (metadata `centreline_z_m`, else the first `/strip` row, as
    /// f32).
    pub fn centreline_z_m(&self) -> Vec<f64> {
        if let Some(z) = self.run_metadata().ok().and_then(|m| m.centreline_z_m) {
            return z;
        }
        self.strip_centreline_z_m.iter().map(|&z| z as f64).collect()
    }

    /// Whether the centre-line nodes move from row to row (a windowed long strip, issue 25).
    pub fn strip_nodes_move(&self) -> bool {
        self.strip_row_z_m.iter().any(|z| !z.is_empty())
    }

    /// z (m) of the centre-line nodes of `/strip` row `i`, as that message has them.
    pub fn strip_row_z(&self, i: usize) -> &[f32] {
        match self.strip_row_z_m.get(i) {
            Some(z) if !z.is_empty() => z,
            _ => &self.strip_centreline_z_m,
        }
    }

    /// Index of the `/controller` row for each tick row (None where the controller sent none).
    pub fn controller_by_tick(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.joint_state.len()];
        let Some(first) = self.joint_state.first().map(|s| s.tick) else { return out };
        for (i, c) in self.controller.iter().enumerate() {
            if let Some(slot) = c.tick.checked_sub(first).and_then(|k| out.get_mut(k as usize)) {
                *slot = Some(i);
            }
        }
        out
    }
}

fn check_schema(path: &Path, ch: &mcap::records::Channel, schema: Option<&SchemaRec>, ours: Channel) -> Result<(), ReadError> {
    let def = ours.def();
    let (name, encoding, data) = match schema {
        Some((n, e, d)) => (n.as_str(), e.as_str(), d.as_slice()),
        None => ("", "", &[][..]),
    };
    if name != def.schema_name
        || encoding != SCHEMA_ENCODING
        || ch.message_encoding != MESSAGE_ENCODING
        || !is_earlier_version(data, def.schema_text)
    {
        return Err(ReadError::SchemaMismatch {
            path: path.into(),
            topic: ch.topic.clone(),
            found: format!("{name:?} ({encoding}/{})", ch.message_encoding),
            expected: def.schema_name,
        });
    }
    Ok(())
}

/// `found` is `ours` or an earlier version of it: fields are only ever appended to a message (the
/// decoders read a shorter message's missing tail as absent), so its own message definition must
/// be whole lines at the start of ours, and its dependent types (`MSG:` sections) equal ours.
fn is_earlier_version(found: &[u8], ours: &str) -> bool {
    let Ok(found) = std::str::from_utf8(found) else { return false };
    fn split(t: &str) -> (&str, &str) {
        t.find("\n====").map_or((t, ""), |i| t.split_at(i + 1))
    }
    let (our_main, our_deps) = split(ours);
    let (main, deps) = split(found);
    found == ours || (deps == our_deps && !main.is_empty() && main.ends_with('\n') && our_main.starts_with(main))
}

/// One MCAP record in a byte slice: opcode, body, and where the next record starts.
type RawRecord<'a> = (u8, &'a [u8], usize);

/// The record at byte `at`; None at the very end; Err(why) if the record does not fit in `bytes`.
fn record_at(bytes: &[u8], at: usize) -> Result<Option<RawRecord<'_>>, String> {
    let rest = &bytes[at..];
    if rest.is_empty() {
        return Ok(None);
    }
    if rest.len() < RECORD_HEAD {
        return Err(format!("the file ends inside a record header ({} of {RECORD_HEAD} bytes)", rest.len()));
    }
    let len = u64::from_le_bytes(rest[1..RECORD_HEAD].try_into().unwrap());
    let have = (rest.len() - RECORD_HEAD) as u64;
    if len > have {
        return Err(format!("a record (opcode {:#04x}) of {len} bytes is incomplete: {have} bytes follow", rest[0]));
    }
    let end = RECORD_HEAD + len as usize;
    Ok(Some((rest[0], &rest[RECORD_HEAD..end], at + end)))
}

/// Largest chunk (uncompressed) decompressed in one call into the reused buffer; a header that
/// promises more (a damaged one, or a writer with huge chunks) goes through the stream decoder,
/// which grows its output only as the data really comes.
const BULK_LIMIT: u64 = 64 << 20;

/// A chunk as the thread ahead found it: where its record starts, and its records or why not.
type Verified = (usize, Result<Vec<u8>, String>);

/// Decompresses and verifies the chunks on a second thread, two ahead of the decoding (which
/// takes about as long: the read of a lockstep recording in a little over half the time). It
/// walks the same records as the reader and hands over each chunk's verdict of
/// [`Unpacker::verified_chunk`]; the buffers come back for reuse. If that thread cannot start,
/// ends early or strays, the reader decompresses the chunks itself, with the same verdicts.
struct Ahead {
    verified: Option<std::sync::mpsc::Receiver<Verified>>,
    reuse: Option<std::sync::mpsc::Sender<Vec<u8>>>,
    current: Vec<u8>,
    here: Unpacker,
}

impl Ahead {
    fn start<'scope>(scope: &'scope std::thread::Scope<'scope, '_>, bytes: &'scope [u8]) -> Ahead {
        let (tx, verified) = std::sync::mpsc::sync_channel::<Verified>(2);
        let (reuse, reused) = std::sync::mpsc::channel::<Vec<u8>>();
        let started = std::thread::Builder::new().name("mcap-unpack".into()).spawn_scoped(scope, move || {
            let mut un = Unpacker::default();
            let mut at = MCAP_MAGIC.len();
            while let Ok(Some((opcode, body, next))) = record_at(bytes, at) {
                match opcode {
                    op::CHUNK => {
                        un.records = reused.try_recv().unwrap_or_default();
                        let item = un.verified_chunk(body).map(|_| ()).map(|()| std::mem::take(&mut un.records));
                        let bad = item.is_err();
                        // the reader stopped (it dropped its end), or stops at this chunk
                        if tx.send((at, item)).is_err() || bad {
                            return;
                        }
                    }
                    op::DATA_END | op::FOOTER => return,
                    _ => {}
                }
                at = next;
            }
        });
        let (verified, reuse) = match started {
            Ok(_) => (Some(verified), Some(reuse)),
            Err(_) => (None, None),
        };
        Ahead { verified, reuse, current: Vec::new(), here: Unpacker::default() }
    }

    /// The records of the chunk record at byte `at` (body `body`), or why it is bad; valid
    /// until the next call.
    fn chunk(&mut self, at: usize, body: &[u8]) -> Result<&[u8], String> {
        if let Some(rx) = &self.verified {
            match rx.recv() {
                Ok((a, item)) if a == at => {
                    let records = item?;
                    let used = std::mem::replace(&mut self.current, records);
                    if let Some(r) = &self.reuse {
                        let _ = r.send(used);
                    }
                    return Ok(&self.current);
                }
                // ended or out of step (never expected): from here on, here
                _ => (self.verified, self.reuse) = (None, None),
            }
        }
        self.here.verified_chunk(body)
    }
}

/// Decompresses chunks into one reused buffer with one reused zstd context.
#[derive(Default)]
struct Unpacker {
    records: Vec<u8>,
    zstd: Option<zstd::bulk::Decompressor<'static>>,
}

impl Unpacker {
    /// Decompresses a chunk whole, checks its size and CRC and that its records fill it exactly;
    /// Err(why) if any of that fails. Only a chunk that passes is decoded at all. The records
    /// are valid until the next call.
    fn verified_chunk(&mut self, body: &[u8]) -> Result<&[u8], String> {
        let Ok(Record::Chunk { header, data }) = mcap::parse_record(op::CHUNK, body) else {
            return Err("its header does not parse".into());
        };
        let size = header.uncompressed_size;
        let records = &mut self.records;
        records.clear();
        match header.compression.as_str() {
            "zstd" => {
                // In one call, straight into the buffer: the stream decoder below decodes into its
                // own window and copies out, a third of the read's time on a lockstep recording
                // (2026-12-06). Up to one byte more than the header promises, as below; a stream
                // that fails here, or gives another size, takes the stream decoder, whose
                // verdict (and message) is the reader's.
                let bulk = size < BULK_LIMIT && {
                    records.reserve(size as usize + 1);
                    let dec = match &mut self.zstd {
                        Some(d) => Some(d),
                        None => zstd::bulk::Decompressor::new().ok().map(|d| self.zstd.insert(d)),
                    };
                    dec.is_some_and(|d| d.decompress_to_buffer(&data[..], records).is_ok_and(|n| n as u64 == size))
                };
                if !bulk {
                    records.clear();
                    stream_decompress(&data, size, records)?;
                }
            }
            "" => records.extend_from_slice(&data),
            other => return Err(format!("it uses compression {other:?}, which this reader does not know")),
        }
        if records.len() as u64 != size {
            return Err(format!("it decompresses to {} bytes, its header says {size}", records.len()));
        }
        if header.uncompressed_crc == 0 {
            return Err("it carries no CRC (this project's writer always writes one)".into());
        }
        let computed = crc32fast::hash(records);
        if computed != header.uncompressed_crc {
            return Err(format!("it fails its CRC (stored {:08x}, computed {computed:08x})", header.uncompressed_crc));
        }
        let mut at = 0;
        while at < records.len() {
            match record_at(records, at) {
                Ok(Some((_, _, next))) => at = next,
                _ => return Err(format!("its records do not fill it (a record at byte {at} of {size} overruns it)")),
            }
        }
        Ok(records)
    }
}

/// The stream decoder: at most one byte more than the header promises (a damaged stream cannot
/// balloon), appended to `records`.
fn stream_decompress(data: &[u8], size: u64, records: &mut Vec<u8>) -> Result<(), String> {
    use std::io::Read;
    records.reserve(size.min(BULK_LIMIT) as usize);
    let mut dec = zstd::stream::read::Decoder::with_buffer(data).map_err(|e| format!("it does not decompress (zstd: {e})"))?;
    dec.by_ref().take(size.saturating_add(1)).read_to_end(records).map_err(|e| format!("it does not decompress (zstd: {e})"))?;
    Ok(())
}

/// A read-only memory map of a whole file (long recordings are not copied into memory).
struct Mapped {
    ptr: *mut libc::c_void,
    len: usize,
}

impl Mapped {
    fn new(file: &std::fs::File) -> std::io::Result<Self> {
        use std::os::fd::AsRawFd;
        let len = file.metadata()?.len() as usize;
        if len == 0 {
            return Ok(Self { ptr: std::ptr::null_mut(), len: 0 });
        }
        // SAFETY: a private read-only mapping of an open file; unmapped in Drop.
        // MAP_POPULATE: the reader walks every byte; one populate instead of a fault per page.
        let ptr =
            unsafe { libc::mmap(std::ptr::null_mut(), len, libc::PROT_READ, libc::MAP_PRIVATE | libc::MAP_POPULATE, file.as_raw_fd(), 0) };
        if ptr == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Self { ptr, len })
    }

    fn bytes(&self) -> &[u8] {
        if self.len == 0 {
            return &[];
        }
        // SAFETY: ptr maps len readable bytes for the lifetime of self. A recording is not
        // rewritten in place (the writer only appends), so the bytes do not change under us.
        unsafe { std::slice::from_raw_parts(self.ptr as *const u8, self.len) }
    }
}

impl Drop for Mapped {
    fn drop(&mut self) {
        if self.len > 0 {
            // SAFETY: ptr/len come from a successful mmap.
            unsafe { libc::munmap(self.ptr, self.len) };
        }
    }
}

/// Opens a recording for a command: a cut or corrupt file is an error unless `allow_truncated`.
pub fn open_for(path: &Path, allow_truncated: bool) -> anyhow::Result<Recording> {
    let rec = Recording::open(path)?;
    if let Some(e) = rec.damage_error() {
        if !allow_truncated {
            let flag = if matches!(e, ReadError::Cut { .. }) { "--allow-truncated" } else { "--allow-damaged" };
            return Err(anyhow::Error::new(e).context(format!("pass {flag} to use the intact ticks before the damage")));
        }
        tracing::warn!("{e}; using the intact ticks before it");
    }
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;
    use recordings::schema::TIMING;

    #[test]
    fn an_earlier_schema_is_one_whose_fields_start_ours() {
        let ours = TIMING.schema_text;
        assert!(is_earlier_version(ours.as_bytes(), ours));
        // The same message without its last field (the probe's period), dependencies kept.
        let (main, deps) = ours.split_at(ours.find("\n====").unwrap() + 1);
        let last = main[..main.len() - 1].rfind('\n').unwrap() + 1;
        assert!(main[last..].starts_with("uint64 probe_period_ns"), "{}", &main[last..]);
        let earlier = format!("{}{deps}", &main[..last]);
        assert!(is_earlier_version(earlier.as_bytes(), ours));
        // A field renamed, a field cut in the middle of its line, a changed dependency: not ours.
        assert!(!is_earlier_version(ours.replace("uint64 tick", "uint64 tock").as_bytes(), ours));
        assert!(!is_earlier_version(format!("{}{deps}", &main[..last + 3]).as_bytes(), ours));
        assert!(!is_earlier_version(format!("{}{}", &main[..last], deps.replace("int32 sec", "int64 sec")).as_bytes(), ours));
        assert!(!is_earlier_version(b"", ours));
    }
}
