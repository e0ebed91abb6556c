//! Reading a recording back into columns, one `Vec` per channel.
//!
//! [`Recording::open`] reads the file linearly (no index needed), so a file whose writer was
//! killed still gives every complete chunk; [`Recording::truncated`] then says where it ended.
//! [`Recording::open_complete`] refuses such a file.

pub use crate::schema::{EventRow, StripRow, TimingRow, TorqueRow};
use crate::schema::{self, CHANNELS, MESSAGE_ENCODING, SCHEMA_ENCODING};
use crate::EventKind;
use mcap::records::Record;
use messages::{ControllerDiagnostics, JointState, Wrench};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The 8 magic bytes every MCAP file starts (and a complete one ends) with.
pub const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

#[derive(Debug, Error)]
pub enum ReadError {
    #[error("cannot read recording {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path} is not an MCAP recording (it starts with {start:02x?}, an MCAP file starts with {MCAP_MAGIC:02x?})")]
    NotMcap { path: PathBuf, start: Vec<u8> },
    #[error("{path} is truncated: it ends without its summary and footer after {ticks} complete ticks (the recording process was probably killed): {reason}")]
    Truncated { path: PathBuf, ticks: usize, reason: String },
    #[error("{path} is an MCAP file but not a rig recording: it has no {topic} channel with schema {schema}")]
    Foreign { path: PathBuf, topic: &'static str, schema: &'static str },
    #[error("{path}: channel {topic} has schema {found}, this reader knows {expected:?} (ros2msg/cdr) with other fields; the file was written by another version")]
    SchemaMismatch { path: PathBuf, topic: String, found: String, expected: &'static str },
    #[error("{path}: message {sequence} on {topic} does not decode: {source}")]
    Decode { path: PathBuf, topic: String, sequence: u32, source: crate::cdr::CdrError },
}

/// A recording read into columns. Each tick channel holds one row per recorded tick, in order.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    pub path: PathBuf,
    /// MCAP metadata records by name: `rig` (written at start: rig, mode, scenario, ...),
    /// `recording_summary` (written by `finish`: counters; absent in a truncated file).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    pub joint_state: Vec<JointState>,
    pub joint_torque: Vec<TorqueRow>,
    pub wrench: Vec<Wrench>,
    pub strip: Vec<StripRow>,
    /// Only ticks for which the controller published diagnostics.
    pub controller: Vec<ControllerDiagnostics>,
    pub timing: Vec<TimingRow>,
    pub events: Vec<EventRow>,
    /// Log time (simulated time, ns) of each `joint_state` row.
    pub log_time_ns: Vec<u64>,
    /// z of the centre-line nodes as the first `/strip` message carrying them has it, m.
    pub strip_centreline_z_m: Vec<f32>,
    /// Set if the file ends without summary and footer: why reading stopped.
    pub truncated: Option<String>,
}

impl Recording {
    /// Reads a recording; a truncated file yields its complete chunks and sets `truncated`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        let path = path.as_ref();
        let io = |source| ReadError::Io { path: path.into(), source };
        let file = std::fs::File::open(path).map_err(io)?;
        if !file.metadata().map_err(io)?.is_file() {
            return Err(io(std::io::Error::other("not a regular file")));
        }
        let map = Mapped::new(&file).map_err(io)?;
        Self::from_bytes(path, map.bytes())
    }

    /// Like [`open`](Self::open) but a truncated file is an error.
    pub fn open_complete(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        let rec = Self::open(path)?;
        match rec.truncated {
            Some(reason) => Err(ReadError::Truncated { path: rec.path, ticks: rec.joint_state.len(), reason }),
            None => Ok(rec),
        }
    }

    /// The error [`open_complete`](Self::open_complete) would give, for a lenient reader.
    pub fn truncation_error(&self) -> Option<ReadError> {
        self.truncated.as_ref().map(|reason| ReadError::Truncated {
            path: self.path.clone(),
            ticks: self.joint_state.len(),
            reason: reason.clone(),
        })
    }

    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, ReadError> {
        if !bytes.starts_with(MCAP_MAGIC) {
            return Err(ReadError::NotMcap { path: path.into(), start: bytes[..bytes.len().min(8)].to_vec() });
        }
        let mut rec = Recording { path: path.into(), ..Default::default() };
        let mut saw_data_end = false;
        for r in mcap::read::LinearReader::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
            .expect("magic checked")
        {
            match r {
                Ok(Record::Metadata(m)) => {
                    rec.metadata.insert(m.name, m.metadata);
                }
                Ok(Record::DataEnd(_)) => saw_data_end = true,
                Ok(_) => {}
                Err(_) => break, // the message pass below reports it
            }
        }
        let mut checked = [false; CHANNELS.len()];
        let opts = mcap::read::Options::ValidateChunkCrcs.into();
        for m in mcap::read::MessageStream::new_with_options(bytes, opts).expect("magic checked") {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    rec.truncated = Some(if saw_data_end {
                        format!("the end of the file is damaged: {e}")
                    } else {
                        format!("no data-end record; reading stopped at: {e}")
                    });
                    break;
                }
            };
            let topic = m.channel.topic.as_str();
            let Some(ch) = CHANNELS.iter().position(|c| c.topic == topic) else { continue };
            if !checked[ch] {
                check_schema(path, &m.channel, ch)?;
                checked[ch] = true;
            }
            let data: &[u8] = &m.data;
            let bad = |source| ReadError::Decode { path: path.into(), topic: topic.into(), sequence: m.sequence, source };
            match ch {
                0 => {
                    rec.joint_state.push(schema::decode_joint_state(data).map_err(bad)?);
                    rec.log_time_ns.push(m.log_time);
                }
                1 => rec.joint_torque.push(schema::decode_joint_torque(data).map_err(bad)?),
                2 => rec.wrench.push(schema::decode_wrench(data).map_err(bad)?),
                3 => {
                    let (row, z) = schema::decode_strip(data, rec.strip_centreline_z_m.is_empty()).map_err(bad)?;
                    if let Some(z) = z {
                        rec.strip_centreline_z_m = z;
                    }
                    rec.strip.push(row);
                }
                4 => rec.controller.push(schema::decode_controller(data).map_err(bad)?),
                5 => rec.timing.push(schema::decode_timing(data).map_err(bad)?),
                _ => rec.events.push(schema::decode_event(data, m.publish_time).map_err(bad)?),
            }
        }
        if !rec.metadata.contains_key("rig") && rec.joint_state.is_empty() && rec.truncated.is_none() {
            return Err(ReadError::Foreign { path: path.into(), topic: CHANNELS[0].topic, schema: CHANNELS[0].schema_name });
        }
        Ok(rec)
    }

    /// A value of the `rig` metadata written at the start (rig, mode, scenario, ...).
    pub fn rig_metadata(&self, key: &str) -> Option<&str> {
        self.metadata.get("rig")?.get(key).map(String::as_str)
    }

    /// A value of the `recording_summary` metadata written by `finish`.
    pub fn summary_metadata(&self, key: &str) -> Option<&str> {
        self.metadata.get("recording_summary")?.get(key).map(String::as_str)
    }

    /// Records the recorder dropped: from the final summary, else the last `/timing` row.
    pub fn dropped(&self) -> u64 {
        let from_summary = ["dropped_ticks", "dropped_events"]
            .iter()
            .filter_map(|k| self.summary_metadata(k)?.parse::<u64>().ok())
            .reduce(|a, b| a + b);
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
                return Err(format!(
                    "{topic}: ticks {:?}..={:?}, /joint_state has {first}..={last}",
                    ticks.first(),
                    ticks.last()
                ));
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

    /// z of the centre-line nodes, m (metadata `centreline_z_m`, else the first `/strip` row).
    pub fn centreline_z_m(&self) -> Vec<f64> {
        if let Some(z) = self.rig_metadata("centreline_z_m").and_then(|j| schema::parse_f64_list(j).ok()) {
            return z;
        }
        self.strip_centreline_z_m.iter().map(|&z| z as f64).collect()
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

fn check_schema(path: &Path, ch: &mcap::Channel, idx: usize) -> Result<(), ReadError> {
    let def = &CHANNELS[idx];
    let (name, encoding, data) = match &ch.schema {
        Some(s) => (s.name.clone(), s.encoding.clone(), s.data.as_ref()),
        None => (String::new(), String::new(), &[][..]),
    };
    if name != def.schema_name
        || encoding != SCHEMA_ENCODING
        || ch.message_encoding != MESSAGE_ENCODING
        || data != def.schema_text.as_bytes()
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
        let ptr = unsafe { libc::mmap(std::ptr::null_mut(), len, libc::PROT_READ, libc::MAP_PRIVATE, file.as_raw_fd(), 0) };
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
