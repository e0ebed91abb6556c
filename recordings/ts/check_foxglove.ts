// Reads a rig recording with Foxglove's own libraries and checks what Foxglove shows
// (recordings/README.md, "Foxglove"). Driven by `tests/tests/foxglove.rs`, which makes the
// recording and the expectations from the robot crate:
//
//   tsx check_foxglove.ts RUN.mcap EXPECT.json
//
// EXPECT.json: { start_window_ns: [before, after], strip_top_nodes, events,
//   tcp: { "<tick>": [x, y, z, qx, qy, qz, qw] },            // robot crate FK of the recorded q
//   poses: [ { tick, q: [6], frames: { "<link>": [x, y, z, qx, qy, qz, qw] } } ] }  // 3 poses
//
// Every message decodes (ros2msg channels with @foxglove/rosmsg2-serialization, protobuf
// channels with the proto definitions generated from @foxglove/schemas, and again with the
// descriptor embedded in the file: both must agree), publish_time <= log_time, the timeline
// starts at the run's date, the URDF's joints give the robot crate's FK at three poses, the
// transforms give its TCP to 1e-9 m, the scene's mesh has the strip's node count and its
// colours follow the recorded pressure. Exit 0 when every check passed, 1 otherwise.

import { readFileSync } from "node:fs";
import { McapStreamReader } from "@mcap/core";
import type { TypedMcapRecord } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { parse as parseMsgDef } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { foxgloveMessageSchemas, foxgloveEnumSchemas, generateProto } from "@foxglove/schemas/internal";
import protobuf from "protobufjs";
import descriptorExt from "protobufjs/ext/descriptor/index.js";
import { XMLParser } from "fast-xml-parser";

const [mcapPath, expectPath] = process.argv.slice(2);
const expect = JSON.parse(readFileSync(expectPath, "utf8"));
let passed = 0;
let failed = 0;
function check(ok: boolean, what: string): void {
  if (ok) {
    passed++;
  } else {
    failed++;
    console.log(`FAIL: ${what}`);
  }
}

// ---- 3D maths (column vectors, quaternions x y z w) ----
type V3 = [number, number, number];
type Q = [number, number, number, number];
type Tf = { p: V3; q: Q };
const qmul = (a: Q, b: Q): Q => [
  a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
  a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
  a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
  a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2],
];
const rot = (q: Q, v: V3): V3 => {
  const r = qmul(qmul(q, [v[0], v[1], v[2], 0]), [-q[0], -q[1], -q[2], q[3]]);
  return [r[0], r[1], r[2]];
};
const compose = (a: Tf, b: Tf): Tf => {
  const r = rot(a.q, b.p);
  return { p: [a.p[0] + r[0], a.p[1] + r[1], a.p[2] + r[2]], q: qmul(a.q, b.q) };
};
const axisAngle = (ax: V3, t: number): Q => [ax[0] * Math.sin(t / 2), ax[1] * Math.sin(t / 2), ax[2] * Math.sin(t / 2), Math.cos(t / 2)];
// URDF rpy: fixed axes x, y, z: R = Rz(y) Ry(p) Rx(r)
const rpy = (r: number, p: number, y: number): Q => qmul(axisAngle([0, 0, 1], y), qmul(axisAngle([0, 1, 0], p), axisAngle([1, 0, 0], r)));
const dist = (a: V3, b: V3) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
// angle between two rotations
// (2 asin of the vector part of a^-1 b: well conditioned near 0, where acos is not)
const qangle = (a: Q, b: Q) => {
  const d = qmul([-a[0], -a[1], -a[2], a[3]], b);
  return 2 * Math.asin(Math.min(1, Math.hypot(d[0], d[1], d[2])));
};

// ---- Foxglove's proto definitions, generated from @foxglove/schemas ----
const foxRoot = new protobuf.Root();
foxRoot.addJSON((protobuf as any).common["google/protobuf/timestamp.proto"].nested);
foxRoot.addJSON((protobuf as any).common["google/protobuf/duration.proto"].nested);
for (const schema of Object.values(foxgloveMessageSchemas) as any[]) {
  const enums = (Object.values(foxgloveEnumSchemas) as any[]).filter((e) => e.parentSchemaName === schema.name);
  protobuf.parse(generateProto(schema, enums), foxRoot, { keepCase: true });
}
foxRoot.resolveAll();

// ---- read every record, chunks decompressed and CRC-checked by @mcap/core ----
const reader = new McapStreamReader({ decompressHandlers: await loadDecompressHandlers(), validateCrcs: true });
reader.append(new Uint8Array(readFileSync(mcapPath)));
const schemas = new Map<number, TypedMcapRecord & { type: "Schema" }>();
const channels = new Map<number, TypedMcapRecord & { type: "Channel" }>();
const decoders = new Map<number, (data: Uint8Array) => any>();
const messages: { topic: string; logTime: bigint; publishTime: bigint; msg: any }[] = [];
const metadata = new Map<string, Map<string, string>>();
const attachments: { name: string; data: Uint8Array }[] = [];
let profile = "";
let sawFooter = false;
const plain = (o: any) => JSON.parse(JSON.stringify(o, (_k, v) => (typeof v === "bigint" ? v.toString() : v)));

function decoderFor(channelId: number): (data: Uint8Array) => any {
  const ch = channels.get(channelId)!;
  const schema = schemas.get(ch.schemaId)!;
  if (ch.messageEncoding === "cdr" && schema.encoding === "ros2msg") {
    const r = new MessageReader(parseMsgDef(new TextDecoder().decode(schema.data), { ros2: true }));
    return (d) => r.readMessage(d);
  }
  if (ch.messageEncoding === "protobuf" && schema.encoding === "protobuf") {
    check(schema.name.startsWith("foxglove."), `${ch.topic}: schema ${schema.name} is a Foxglove schema`);
    const foxType = foxRoot.lookupType(schema.name);
    const fds = (descriptorExt as any).FileDescriptorSet.decode(schema.data);
    const embedded = (protobuf.Root as any).fromDescriptor(fds).lookupType(schema.name);
    return (d) => {
      const a = foxType.toObject(foxType.decode(d), { longs: String, enums: Number, defaults: true });
      const b = embedded.toObject(embedded.decode(d), { longs: String, enums: Number, defaults: true });
      if (JSON.stringify(a) !== JSON.stringify(b)) {
        throw new Error(`${ch.topic}: Foxglove's definition and the embedded descriptor decode differently`);
      }
      return a;
    };
  }
  if (ch.messageEncoding === "json" && schema.encoding === "jsonschema") {
    JSON.parse(new TextDecoder().decode(schema.data));
    return (d) => JSON.parse(new TextDecoder().decode(d));
  }
  throw new Error(`${ch.topic}: no decoder for ${ch.messageEncoding} / ${schema.encoding}`);
}

let decodeErrors = 0;
for (let rec; (rec = reader.nextRecord()); ) {
  switch (rec.type) {
    case "Header":
      profile = rec.profile;
      break;
    case "Schema":
      schemas.set(rec.id, rec);
      break;
    case "Channel":
      channels.set(rec.id, rec);
      break;
    case "Metadata":
      metadata.set(rec.name, rec.metadata);
      break;
    case "Attachment":
      attachments.push({ name: rec.name, data: rec.data });
      break;
    case "Footer":
      sawFooter = true;
      break;
    case "Message": {
      const ch = channels.get(rec.channelId)!;
      if (!decoders.has(rec.channelId)) decoders.set(rec.channelId, decoderFor(rec.channelId));
      try {
        messages.push({ topic: ch.topic, logTime: rec.logTime, publishTime: rec.publishTime, msg: decoders.get(rec.channelId)!(rec.data) });
      } catch (e) {
        decodeErrors++;
        if (decodeErrors < 5) console.log(`decode error on ${ch.topic}: ${e}`);
      }
      break;
    }
  }
}
check(reader.done() && sawFooter, "the file is read to its footer");
check(decodeErrors === 0, `every message decodes (${decodeErrors} did not)`);
check(profile.length > 0, `the header's profile is set (${JSON.stringify(profile)})`);
const count = (t: string) => messages.filter((m) => m.topic === t).length;
const counts: Record<string, number> = {};
for (const m of messages) counts[m.topic] = (counts[m.topic] ?? 0) + 1;
console.log(`messages: ${messages.length}`, counts);

// ---- time ----
const late = messages.filter((m) => m.publishTime > m.logTime);
check(late.length === 0, `publish_time <= log_time for every message (${late.length} later)`);
const start = BigInt(metadata.get("rig")?.get("start_wall_ns") ?? "0");
const first = messages.reduce((a, m) => (m.logTime < a ? m.logTime : a), messages[0].logTime);
const [before, after] = expect.start_window_ns.map(BigInt);
check(first === start, `the timeline starts at the start stamp (${first} vs ${start})`);
check(start >= before && start <= after, `the start stamp ${start} lies within the run (${before}..${after}): ${new Date(Number(start / 1000000n)).toISOString()}`);
const states = messages.filter((m) => m.topic === "/joint_state");
check(
  states.every((m) => m.logTime - start === BigInt(Math.round(m.msg.sim_time * 1e9))),
  "log time = start + simulated time on /joint_state",
);

// ---- URDF ----
const descr = messages.filter((m) => m.topic === "/robot_description");
check(descr.length === 1, "one /robot_description message");
const urdfText: string = descr[0]?.msg.data ?? "";
const att = attachments.find((a) => a.name.endsWith(".urdf"));
check(att !== undefined && new TextDecoder().decode(att.data) === urdfText, "the URDF attachment is the /robot_description text");
const xml = new XMLParser({ ignoreAttributes: false, attributeNamePrefix: "", isArray: (n, _path, _leaf, isAttribute) => !isAttribute && ["link", "joint", "visual"].includes(n) }).parse(urdfText);
const joints: any[] = xml.robot.joint;
const links: any[] = xml.robot.link;
check(links.length === 9 && joints.length === 8, `URDF has 9 links and 8 joints (${links.length}, ${joints.length})`);
const nums = (s: string) => s.trim().split(/\s+/).map(Number);
function urdfWorld(q: number[]): Map<string, Tf> {
  const world = new Map<string, Tf>([["base", { p: [0, 0, 0], q: [0, 0, 0, 1] }]]);
  let revolute = 0;
  // joints are listed parent-first along the chain
  for (let pass = 0; pass < joints.length; pass++) {
    for (const j of joints) {
      const parent = world.get(j.parent.link);
      if (!parent || world.has(j.child.link)) continue;
      const [x, y, z] = nums(j.origin?.xyz ?? "0 0 0");
      const [r, p, yw] = nums(j.origin?.rpy ?? "0 0 0");
      let t = compose(parent, { p: [x, y, z], q: rpy(r, p, yw) });
      if (j.type === "revolute") {
        const ax = nums(j.axis.xyz) as V3;
        const idx = Number(j.name.replace("joint", "")) - 1;
        t = compose(t, { p: [0, 0, 0], q: axisAngle(ax, q[idx]) });
        revolute++;
      }
      world.set(j.child.link, t);
    }
  }
  return world;
}
check(expect.poses.length === 3, "three poses to check the URDF at");
for (const pose of expect.poses) {
  const w = urdfWorld(pose.q);
  for (const [name, f] of Object.entries(pose.frames) as [string, number[]][]) {
    const t = w.get(name);
    const ok = t !== undefined && dist(t.p, f.slice(0, 3) as V3) < 1e-9 && qangle(t.q, f.slice(3) as Q) < 1e-9;
    check(ok, `URDF frame ${name} at tick ${pose.tick} equals the robot crate's FK (${JSON.stringify(t)} vs ${JSON.stringify(f)})`);
  }
}

// ---- transforms: the TCP against the robot crate's FK of the recorded q ----
const tfs = messages.filter((m) => m.topic === "/tf");
check(tfs.length > 0 && tfs.length === Object.keys(expect.tcp).length, `one /tf per scene tick (${tfs.length} vs ${Object.keys(expect.tcp).length})`);
let worstTcp = 0;
let tcpChecked = 0;
const tickOf = (m: { logTime: bigint }) => Number((m.logTime - start) / 1000000n);
for (const m of tfs) {
  const edges = new Map<string, { parent: string; t: Tf }>();
  for (const t of m.msg.transforms) {
    const tr = t.translation;
    const ro = t.rotation;
    edges.set(t.child_frame_id, { parent: t.parent_frame_id, t: { p: [tr.x, tr.y, tr.z], q: [ro.x, ro.y, ro.z, ro.w] } });
    check(BigInt(t.timestamp.seconds) * 1000000000n + BigInt(t.timestamp.nanos) === m.logTime, "transform stamp = log time");
  }
  const worldOf = (frame: string): Tf => {
    const e = edges.get(frame);
    return e ? compose(worldOf(e.parent), e.t) : { p: [0, 0, 0], q: [0, 0, 0, 1] };
  };
  for (const f of ["link1", "link2", "link3", "link4", "link5", "link6", "flange", "tcp", "task"]) {
    check(edges.has(f), `/tf carries ${f}`);
  }
  const want = expect.tcp[String(tickOf(m))];
  if (!want) {
    check(false, `expected TCP for tick ${tickOf(m)}`);
    continue;
  }
  const tcp = worldOf("tcp");
  const d = dist(tcp.p, want.slice(0, 3));
  worstTcp = Math.max(worstTcp, d);
  check(d < 1e-9 && qangle(tcp.q, want.slice(3)) < 1e-9, `TCP of /tf at tick ${tickOf(m)} is the robot crate's FK (${d} m)`);
  tcpChecked++;
}
console.log(`TCP from /tf vs robot crate FK: ${tcpChecked} transforms, worst ${worstTcp.toExponential(2)} m`);

// ---- scene: node count and colours against the recorded pressure ----
const strips = new Map<number, any>();
for (const m of messages.filter((m) => m.topic === "/strip")) strips.set(Number(m.msg.tick), m.msg);
const scenes = messages.filter((m) => m.topic === "/strip_scene");
check(scenes.length === tfs.length, "one /strip_scene per /tf");
// The documented colour map (recordings/README.md): blue below 100 kPa, yellow to red above.
const colourOf = (p: number): number[] => {
  if (p < 100e3) {
    const t = Math.min(1, Math.max(0, p / 100e3));
    return [0.1 + 0.5 * t, 0.2 + 0.6 * t, 0.6 + 0.4 * t, 1];
  }
  const t = Math.min(1, Math.max(0, (p - 100e3) / 100e3));
  return [1, 0.9 * (1 - t), 0.1 * (1 - t), 1];
};
const interp = (z: number[], v: number[], x: number) => {
  if (x <= z[0]) return v[0];
  for (let i = 1; i < z.length; i++) {
    if (x <= z[i]) {
      const s = (x - z[i - 1]) / (z[i] - z[i - 1]);
      return (1 - s) * v[i - 1] + s * v[i];
    }
  }
  return v[v.length - 1];
};
let worstColour = 0;
let bonded = 0;
for (const m of scenes) {
  const tick = tickOf(m);
  const strip = strips.get(tick);
  const ent = m.msg.entities.find((e: any) => e.id === "strip");
  if (!ent || !strip) {
    check(false, `scene at tick ${tick} has the strip and a /strip message`);
    continue;
  }
  const tri = ent.triangles[0];
  check(tri.points.length === expect.strip_top_nodes, `mesh of tick ${tick} has the strip's ${expect.strip_top_nodes} top nodes (${tri.points.length})`);
  check(tri.colors.length === tri.points.length, "one colour per vertex");
  check(tri.indices.length > 0 && tri.indices.every((i: number) => i < tri.points.length), "triangle indices within the mesh");
  const z = Array.from(strip.centreline_z as Float32Array);
  const p = Array.from(strip.centreline_pressure as Float32Array);
  tri.points.forEach((pt: any, i: number) => {
    const want = colourOf(interp(z, p, pt.z));
    const c = tri.colors[i];
    const got = [c.r, c.g, c.b, c.a];
    const err = Math.max(...want.map((w, k) => Math.abs(w - got[k])));
    worstColour = Math.max(worstColour, err);
    if (c.b < 0.5) bonded++;
  });
}
check(worstColour <= 0.5 / 256 + 1e-12, `vertex colours follow the recorded pressure (worst ${worstColour})`);
check(bonded > 0, `some vertices show the bond (>= 100 kPa) colour (${bonded})`);
console.log(`scene: ${scenes.length} updates, colour error worst ${worstColour.toExponential(2)}, ${bonded} bonded vertex samples`);

// ---- the pressure under the wheel beside the bond line (for the layout's plot) ----
const under = messages.filter((m) => m.topic === "/pressure_under_wheel");
check(under.length === scenes.length, "one /pressure_under_wheel per scene");
let worstUnder = 0;
for (const m of under) {
  const s = strips.get(Number(m.msg.tick));
  const want = interp(Array.from(s.centreline_z as Float32Array), Array.from(s.centreline_pressure as Float32Array), s.wheel_z);
  worstUnder = Math.max(worstUnder, Math.abs(m.msg.pressure_pa - want));
  check(m.msg.bond_line_pa === 100e3, "bond line 100 kPa");
}
check(worstUnder < 1e-6, `/pressure_under_wheel is the recorded pressure at the wheel (worst ${worstUnder} Pa)`);

// ---- events as foxglove.Log ----
const events = messages.filter((m) => m.topic === "/events");
const logs = messages.filter((m) => m.topic === "/log");
check(events.length === expect.events && logs.length === events.length, `/log has every /events entry (${logs.length} / ${events.length} / ${expect.events})`);
const levelOf: Record<string, number> = { fault: 4, recording_error: 4, version_mismatch: 4, torque_refused: 4, controller_ended: 4, safe_stop: 3, reflex: 3, end_stop: 3, miss: 3, foreign_torque: 3 };
events.forEach((e, i) => {
  const l = logs[i]?.msg;
  check(l !== undefined && l.name === e.msg.kind_name && l.level === (levelOf[e.msg.kind_name] ?? 2) && l.message.includes(e.msg.text), `/log ${i} is /events ${e.msg.kind_name}`);
});

// ---- the shipped layout refers to topics and fields the recording has ----
const layout = JSON.parse(readFileSync(new URL("../foxglove/layout.json", import.meta.url), "utf8"));
for (const [id, cfg] of Object.entries(layout.configById) as [string, any][]) {
  for (const p of cfg.paths ?? []) {
    const m = /^(\/[a-z_]+)\.([a-z_]+)(?:\[(\d+)\])?$/.exec(p.value);
    const msg = m && messages.find((x) => x.topic === m[1])?.msg;
    const v = msg && (m[3] === undefined ? msg[m[2]] : msg[m[2]]?.[Number(m[3])]);
    check(v !== undefined && v !== null, `layout ${id}: ${p.value} is in the recording`);
  }
  if (cfg.topicToRender) check(count(cfg.topicToRender) > 0, `layout ${id}: ${cfg.topicToRender} is in the recording`);
  for (const layer of Object.values(cfg.layers ?? {}) as any[]) {
    if (layer.topic) check(count(layer.topic) > 0, `layout ${id}: ${layer.topic} is in the recording`);
  }
}

console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
