//! The live view: the recording's channels served over the Foxglove WebSocket protocol while the
//! run goes on (`rig run --live [ADDR]`), with the `foxglove` crate's server.
//!
//! Fed from the recorder's writer thread, never from the 1 kHz loop: after the writer encodes a
//! message for the file it offers the same bytes to a [`LiveTee`], which decides first whether
//! to forward them (a client subscribed to the channel, the channel's decimation is due), copies
//! them and `try_send`s them into a bounded queue to the live-view thread. A full queue drops the
//! message and counts it; the writer never waits. The live-view thread owns the WebSocket server
//! (a one-worker tokio runtime of its own) and logs the raw bytes on channels that carry the
//! file's topics, schemas and encodings, whatever they are ([`LiveChannel`]).
//!
//! Both threads are spawned by the thread that starts the recorder, before the plant's real-time
//! set-up, so they inherit its scheduling policy (normal) and CPU affinity (in lockstep: every CPU
//! but the loop's), like the writer.

use crate::error_chain;
use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use std::net::SocketAddr;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Where `rig run --live` listens without an address: loopback only.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// Messages per second and per-tick channel the live view sends by default (`--live-rate`).
pub const DEFAULT_RATE_HZ: f64 = 100.0;
/// Messages the writer-to-live-view queue holds: 1.7 s of the six per-tick channels at 100 Hz,
/// 0.17 s at every tick.
pub const QUEUE_CAPACITY: usize = 1024;

/// What the recorder's caller asks of the live view.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveConfig {
    /// Address the WebSocket server binds (port 0: any free port; see [`LiveView::local_addr`]).
    pub addr: SocketAddr,
    /// Per-tick channels are decimated to this rate, in messages per second of log time;
    /// 0 sends every tick. Event channels are never decimated.
    pub rate_hz: f64,
    /// Messages the queue from the writer to the live-view thread holds ([`QUEUE_CAPACITY`]).
    pub queue_capacity: usize,
}

impl Default for LiveConfig {
    fn default() -> Self {
        Self { addr: DEFAULT_ADDR.parse().expect("a socket address"), rate_hz: DEFAULT_RATE_HZ, queue_capacity: QUEUE_CAPACITY }
    }
}

/// One channel as the recording declares it; the live view advertises exactly this.
#[derive(Debug, Clone, Copy)]
pub struct LiveChannel<'a> {
    pub topic: &'a str,
    pub schema_name: &'a str,
    /// `ros2msg`, `protobuf`, `jsonschema`, ...
    pub schema_encoding: &'a str,
    pub schema: &'a [u8],
    /// `cdr`, `protobuf`, `json`, ...
    pub message_encoding: &'a str,
}

/// What the live view did over a run (recorded in `recording_summary` and the plant's summary).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LiveSummary {
    /// Messages handed to the live-view thread.
    pub sent: u64,
    /// Messages the full queue refused (or a live-view thread that had ended).
    pub dropped: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The OS error is part of the message (printed once in an error chain).
    #[error("live view: cannot serve on {addr}: {cause}")]
    Serve { addr: SocketAddr, cause: String },
    #[error("live view: --live-rate {0}: must be a finite number of Hz >= 0")]
    Rate(f64),
}

struct Msg {
    channel: u16,
    log_time_ns: u64,
    bytes: Vec<u8>,
}

/// The writer thread's end of the live view.
pub struct LiveView {
    tx: Option<SyncSender<Msg>>,
    /// The server's channels, in the order of the recording's; their `has_sinks` says whether any
    /// client subscribed.
    channels: Vec<Arc<RawChannel>>,
    /// Least log-time step between two forwarded messages of a decimated channel, ns (0: every).
    period_ns: u64,
    /// Per channel: the log time from which the next message is forwarded.
    next_ns: Vec<u64>,
    summary: LiveSummary,
    local_addr: SocketAddr,
    thread: Option<JoinHandle<()>>,
}

impl LiveView {
    /// Starts the live-view thread and its server on `cfg.addr`, advertising `channels`; returns
    /// once the server listens (or could not). Blocking: call before the loop starts.
    pub fn start(cfg: &LiveConfig, server_name: &str, channels: &[LiveChannel<'_>]) -> Result<Self, LiveError> {
        if !(cfg.rate_hz.is_finite() && cfg.rate_hz >= 0.0) {
            return Err(LiveError::Rate(cfg.rate_hz));
        }
        let period_ns = if cfg.rate_hz > 0.0 { (1e9 / cfg.rate_hz).round() as u64 } else { 0 };
        let owned: Vec<(String, Schema, String)> = channels
            .iter()
            .map(|c| {
                let schema = Schema::new(c.schema_name, c.schema_encoding, c.schema.to_vec());
                (c.topic.to_string(), schema, c.message_encoding.to_string())
            })
            .collect();
        let addr = cfg.addr;
        let name = server_name.to_string();
        let serve_err = move |cause: String| LiveError::Serve { addr, cause };
        let (tx, rx) = mpsc::sync_channel::<Msg>(cfg.queue_capacity.max(1));
        let (ready_tx, ready_rx) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("live-view".into())
            .spawn(move || serve(addr, &name, owned, rx, ready_tx))
            .map_err(|e| serve_err(format!("cannot start its thread: {e}")))?;
        match ready_rx.recv() {
            Ok(Ok((channels, local_addr))) => {
                let n = channels.len();
                tracing::info!("live view: Foxglove WebSocket server on ws://{local_addr} ({})", rate_text(cfg.rate_hz));
                Ok(Self {
                    tx: Some(tx),
                    channels,
                    period_ns,
                    next_ns: vec![0; n],
                    summary: LiveSummary::default(),
                    local_addr,
                    thread: Some(thread),
                })
            }
            Ok(Err(cause)) => {
                let _ = thread.join();
                Err(serve_err(cause))
            }
            Err(_) => {
                let _ = thread.join();
                Err(serve_err("its thread ended before it listened".into()))
            }
        }
    }

    /// The address the server listens on (the port chosen when asked for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Offers one encoded message of the recording's channel `channel` (an index into the
    /// channels given to [`start`](Self::start)). `decimate`: a per-tick channel, sent at the
    /// configured rate. Never blocks; a full queue drops the message and counts it.
    pub fn offer(&mut self, channel: usize, log_time_ns: u64, bytes: &[u8], decimate: bool) {
        let Some(ch) = self.channels.get(channel) else { return };
        if decimate && self.period_ns > 0 {
            if log_time_ns < self.next_ns[channel] {
                return;
            }
            // the next slot of the rate's grid: the channels of one tick go out together
            self.next_ns[channel] = (log_time_ns / self.period_ns + 1) * self.period_ns;
        }
        // No subscriber: nothing to copy (and nothing lost).
        if !ch.has_sinks() {
            return;
        }
        let Some(tx) = self.tx.as_ref() else { return };
        match tx.try_send(Msg { channel: channel as u16, log_time_ns, bytes: bytes.to_vec() }) {
            Ok(()) => self.summary.sent += 1,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => self.summary.dropped += 1,
        }
    }

    /// What was sent and dropped so far.
    pub fn summary(&self) -> LiveSummary {
        self.summary
    }

    /// Ends the queue, lets the thread send what it holds, stops the server and joins it.
    pub fn finish(mut self) -> LiveSummary {
        self.stop();
        self.summary
    }

    fn stop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                tracing::error!("live view: its thread panicked");
            }
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.stop();
    }
}

fn rate_text(rate_hz: f64) -> String {
    if rate_hz > 0.0 {
        format!("per-tick channels at {rate_hz} Hz")
    } else {
        "every tick".into()
    }
}

type Ready = Result<(Vec<Arc<RawChannel>>, SocketAddr), String>;

/// The live-view thread: its own tokio runtime (one worker, spawned from here so it inherits this
/// thread's affinity), the server, then the queue until the writer hangs up.
fn serve(addr: SocketAddr, name: &str, channels: Vec<(String, Schema, String)>, rx: Receiver<Msg>, ready: mpsc::Sender<Ready>) {
    let runtime = match tokio::runtime::Builder::new_multi_thread().worker_threads(1).thread_name("live-view-io").enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            let _ = ready.send(Err(format!("cannot start its runtime: {e}")));
            return;
        }
    };
    let ctx = Context::new();
    let mut raw = Vec::with_capacity(channels.len());
    for (topic, schema, encoding) in channels {
        match ctx.channel_builder(topic.as_str()).schema(schema).message_encoding(encoding).build_raw() {
            Ok(c) => raw.push(c),
            Err(e) => {
                let _ = ready.send(Err(format!("channel {topic}: {e}")));
                return;
            }
        }
    }
    // An IPv6 host needs its brackets in the "host:port" the server binds.
    let host = match addr {
        SocketAddr::V4(a) => a.ip().to_string(),
        SocketAddr::V6(a) => format!("[{}]", a.ip()),
    };
    let server = WebSocketServer::new().name(name).context(&ctx).bind(host, addr.port()).tokio_runtime(runtime.handle());
    let handle = match runtime.block_on(server.start()) {
        Ok(h) => h,
        Err(e) => {
            let _ = ready.send(Err(error_chain(&e)));
            return;
        }
    };
    let local_addr = SocketAddr::new(addr.ip(), handle.port());
    if ready.send(Ok((raw.clone(), local_addr))).is_err() {
        return;
    }
    while let Ok(m) = rx.recv() {
        raw[m.channel as usize].log_with_meta(&m.bytes, PartialMetadata::with_log_time(m.log_time_ns));
    }
    // The writer is done: close the clients' connections (bounded: a stuck client is cut off).
    let shutdown = handle.stop();
    runtime.block_on(async {
        let _ = tokio::time::timeout(Duration::from_secs(1), shutdown.wait()).await;
    });
    runtime.shutdown_timeout(Duration::from_secs(1));
}

#[cfg(test)]
mod tests {
    //! Against a plain WebSocket client (`tungstenite`) speaking the Foxglove protocol by hand:
    //! JSON `advertise` / `subscribe`, binary message frames (opcode 1, subscription id, log time).
    use super::*;
    use std::collections::HashMap;
    use std::net::TcpStream;
    use std::time::Instant;
    use tungstenite::client::IntoClientRequest;
    use tungstenite::stream::MaybeTlsStream;
    use tungstenite::{Message, WebSocket};

    type Client = WebSocket<MaybeTlsStream<TcpStream>>;

    const TICKS: LiveChannel<'static> = LiveChannel {
        topic: "/ticks",
        schema_name: "t/msg/Tick",
        schema_encoding: "ros2msg",
        schema: b"uint64 tick\n",
        message_encoding: "cdr",
    };
    const EVENTS: LiveChannel<'static> = LiveChannel {
        topic: "/events",
        schema_name: "t/msg/Event",
        schema_encoding: "ros2msg",
        schema: b"string text\n",
        message_encoding: "cdr",
    };

    fn start(rate_hz: f64, queue_capacity: usize) -> LiveView {
        let cfg = LiveConfig { addr: "127.0.0.1:0".parse().unwrap(), rate_hz, queue_capacity };
        LiveView::start(&cfg, "unit test", &[TICKS, EVENTS]).unwrap()
    }

    /// Connects, subscribes to every advertised channel and waits until the server has the
    /// subscriptions; returns the topic of each subscription id.
    fn subscribe(live: &LiveView) -> (Client, HashMap<u32, String>) {
        let mut req = format!("ws://{}", live.local_addr()).into_client_request().unwrap();
        req.headers_mut().insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
        let (mut ws, _) = tungstenite::connect(req).unwrap();
        let channels = loop {
            if let Message::Text(t) = ws.read().unwrap() {
                let v: serde_json::Value = serde_json::from_str(&t).unwrap();
                if v["op"] == "advertise" {
                    break v["channels"].as_array().unwrap().clone();
                }
            }
        };
        let mut topics = HashMap::new();
        let subs: Vec<serde_json::Value> = channels
            .iter()
            .enumerate()
            .map(|(i, c)| {
                topics.insert(i as u32 + 1, c["topic"].as_str().unwrap().to_string());
                serde_json::json!({"id": i + 1, "channelId": c["id"]})
            })
            .collect();
        assert_eq!(subs.len(), 2, "{channels:?}");
        ws.send(Message::text(serde_json::json!({"op": "subscribe", "subscriptions": subs}).to_string())).unwrap();
        let t0 = Instant::now();
        while !live.channels.iter().all(|c| c.has_sinks()) {
            assert!(t0.elapsed() < Duration::from_secs(10), "the server never had the subscriptions");
            std::thread::sleep(Duration::from_millis(5));
        }
        if let MaybeTlsStream::Plain(s) = ws.get_mut() {
            s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        }
        (ws, topics)
    }

    /// Binary message frames until `n` arrived: (topic, log time, payload).
    fn receive(ws: &mut Client, topics: &HashMap<u32, String>, n: usize) -> Vec<(String, u64, Vec<u8>)> {
        let mut got = Vec::new();
        while got.len() < n {
            match ws.read() {
                Ok(Message::Binary(b)) if b[0] == 1 => {
                    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                    let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                    got.push((topics[&sub].clone(), t, b[13..].to_vec()));
                }
                Ok(_) => {}
                Err(e) => panic!("after {} of {n} messages: {e}", got.len()),
            }
        }
        got
    }

    #[test]
    fn decimates_a_per_tick_channel_on_the_rate_grid_and_sends_events_whole() {
        let mut live = start(100.0, QUEUE_CAPACITY);
        let (mut ws, topics) = subscribe(&live);
        // one second of 1 kHz ticks, three events in its first milliseconds
        for k in 0..1000u64 {
            live.offer(0, k * 1_000_000, &k.to_le_bytes(), true);
            if (1..=3).contains(&k) {
                live.offer(1, k * 1_000_000, format!("event {k}").as_bytes(), false);
            }
        }
        let got = receive(&mut ws, &topics, 103);
        let ticks: Vec<(u64, u64)> =
            got.iter().filter(|m| m.0 == "/ticks").map(|m| (m.1, u64::from_le_bytes(m.2[..].try_into().unwrap()))).collect();
        let expected: Vec<(u64, u64)> = (0..100u64).map(|i| (i * 10_000_000, i * 10)).collect();
        assert_eq!(ticks, expected, "every 10th tick, at its log time, its bytes");
        let events: Vec<(u64, Vec<u8>)> = got.iter().filter(|m| m.0 == "/events").map(|m| (m.1, m.2.clone())).collect();
        assert_eq!(events, (1..=3u64).map(|k| (k * 1_000_000, format!("event {k}").into_bytes())).collect::<Vec<_>>());
        assert_eq!(live.finish(), LiveSummary { sent: 103, dropped: 0 });
    }

    #[test]
    fn a_full_queue_drops_and_counts_instead_of_waiting() {
        let mut live = start(0.0, 4);
        let (_ws, _) = subscribe(&live);
        let n = 20_000u64;
        for k in 0..n {
            live.offer(0, k * 1_000_000, &k.to_le_bytes(), true);
        }
        let s = live.finish();
        assert_eq!(s.sent + s.dropped, n, "{s:?}");
        assert!(s.dropped > 0, "4 slots took {n} messages offered back to back: {s:?}");
    }

    #[test]
    fn nothing_is_copied_or_counted_without_a_subscriber() {
        let mut live = start(0.0, 4);
        for k in 0..1000u64 {
            live.offer(0, k * 1_000_000, &k.to_le_bytes(), true);
        }
        assert_eq!(live.finish(), LiveSummary::default());
    }

    #[test]
    fn a_negative_rate_is_refused() {
        let cfg = LiveConfig { rate_hz: -1.0, ..LiveConfig::default() };
        let e = LiveView::start(&cfg, "unit test", &[TICKS]).err().expect("refused");
        assert_eq!(e.to_string(), "live view: --live-rate -1: must be a finite number of Hz >= 0");
    }
}
