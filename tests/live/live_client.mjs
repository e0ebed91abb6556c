// A Foxglove WebSocket client built from Foxglove's own libraries (@foxglove/ws-protocol over the
// `ws` package, @foxglove/rosmsg + @foxglove/rosmsg2-serialization for the ros2msg/CDR channels):
// connects to `rig run --live`, subscribes to every channel the server advertises, decodes every
// message it receives and stops once /joint_state has spanned SECONDS of log time. Checks what it
// can know by itself (every message decodes, ticks increase per channel, 6 joints, finite values)
// and prints one JSON line for tests/tests/live_view.rs to compare with the recording.
//
// usage: node live_client.mjs ws://127.0.0.1:PORT SECONDS|all [TIMEOUT_S]
// (`all`: stay subscribed until the server closes at the end of the run; measure.sh uses it)
import wsProtocol from "@foxglove/ws-protocol";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";
import protobuf from "protobufjs";
import descriptorExt from "protobufjs/ext/descriptor/index.js";

const { FoxgloveClient } = wsProtocol; // a CommonJS package

const [url, secondsArg, timeoutArg] = process.argv.slice(2);
if (!url || !secondsArg) {
  console.error("usage: node live_client.mjs ws://HOST:PORT SECONDS [TIMEOUT_S]");
  process.exit(2);
}
const untilClose = secondsArg === "all";
const wantNs = untilClose ? null : BigInt(Math.round(Number(secondsArg) * 1e9));
const timeoutMs = Number(timeoutArg ?? 60) * 1000;

function fail(why) {
  console.error(`live_client: ${why}`);
  process.exit(1);
}

// One decoder per message encoding; a channel in any other encoding fails the check (a new
// encoding needs its decoder here).
function decoderFor(ch) {
  if (ch.encoding === "cdr" && ch.schemaEncoding === "ros2msg") {
    const reader = new MessageReader(parse(ch.schema, { ros2: true }));
    return (data) => reader.readMessage(data);
  }
  if (ch.encoding === "protobuf" && ch.schemaEncoding === "protobuf") {
    // The advertised schema of a binary schema encoding is the FileDescriptorSet in base64.
    const fds = descriptorExt.FileDescriptorSet.decode(Buffer.from(ch.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(fds).lookupType(ch.schemaName);
    return (data) => type.toObject(type.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)), { longs: String });
  }
  if (ch.encoding === "json") {
    const text = new TextDecoder();
    return (data) => JSON.parse(text.decode(data));
  }
  return null;
}

// The foxglove crate's server names the protocol of ws-protocol's spec "foxglove.sdk.v1" (channel
// advertisements with inline schemas, as in "foxglove.websocket.v1"); offer both names.
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const advertised = [];
const bySubscription = new Map();
const topics = {};
const samples = [];
let serverName = null;
let done = false;

const timer = setTimeout(() => fail(`timed out after ${timeoutMs / 1000} s: ${JSON.stringify(topics)}`), timeoutMs);

client.on("error", (e) => fail(`connection error: ${e?.message ?? e}`));
client.on("serverInfo", (info) => {
  serverName = info.name;
});
client.on("close", () => {
  if (untilClose && !done) finish();
  if (!done) fail(`the server closed the connection before ${secondsArg} s of /joint_state: ${JSON.stringify(topics)}`);
});
client.on("advertise", (channels) => {
  for (const ch of channels) {
    advertised.push({ topic: ch.topic, schemaName: ch.schemaName, schemaEncoding: ch.schemaEncoding ?? "", encoding: ch.encoding });
    const decode = decoderFor(ch);
    if (!decode) fail(`channel ${ch.topic}: no decoder for encoding ${ch.encoding} (schema ${ch.schemaEncoding})`);
    const sub = client.subscribe(ch.id);
    bySubscription.set(sub, { topic: ch.topic, decode });
    topics[ch.topic] = { count: 0, firstTick: null, lastTick: null, minTickStep: null, maxTickStep: null, firstLogNs: null, lastLogNs: null };
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  if (done) return;
  const sub = bySubscription.get(subscriptionId);
  if (!sub) fail(`a message on unknown subscription ${subscriptionId}`);
  let msg;
  try {
    msg = sub.decode(data);
  } catch (e) {
    fail(`${sub.topic}: message ${topics[sub.topic].count} does not decode: ${e.message}`);
  }
  const t = topics[sub.topic];
  t.count += 1;
  t.firstLogNs ??= timestamp.toString();
  t.lastLogNs = timestamp.toString();
  if (msg.tick !== undefined && sub.topic !== "/events") {
    const tick = Number(msg.tick);
    if (t.lastTick !== null) {
      const step = tick - t.lastTick;
      if (step <= 0) fail(`${sub.topic}: tick ${tick} after ${t.lastTick}`);
      t.minTickStep = t.minTickStep === null ? step : Math.min(t.minTickStep, step);
      t.maxTickStep = t.maxTickStep === null ? step : Math.max(t.maxTickStep, step);
    }
    t.firstTick ??= tick;
    t.lastTick = tick;
  }
  if (sub.topic === "/joint_state") {
    for (const key of ["q", "qd", "tau_applied"]) {
      const v = Array.from(msg[key]);
      if (v.length !== 6) fail(`/joint_state tick ${msg.tick}: ${key} has ${v.length} joints, not 6`);
      if (!v.every(Number.isFinite)) fail(`/joint_state tick ${msg.tick}: ${key} not finite: ${v}`);
    }
    if (samples.length < 200) samples.push({ tick: Number(msg.tick), sim_time: msg.sim_time, q: Array.from(msg.q) });
  }
  // Done once every per-tick channel received so far spans the wanted log time (each starts when
  // its subscription does, and a tick's channels arrive one after the other).
  const spans = Object.values(topics).filter((x) => x.firstTick !== null);
  if (!untilClose && spans.length > 0 && spans.every((x) => BigInt(x.lastLogNs) - BigInt(x.firstLogNs) >= wantNs)) finish();
});

function finish() {
  done = true;
  clearTimeout(timer);
  client.close();
  // exit once the report is out: a pipe takes 64 KiB at once, process.exit would cut the rest
  process.stdout.write(JSON.stringify({ serverName, advertised, topics, samples }) + "\n", () => process.exit(0));
}
