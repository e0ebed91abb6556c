#!/usr/bin/env python3
"""Check a rig recording with the official MCAP Python readers (`mcap`, `mcap-ros2-support`).

Reads the file record by record with every CRC checked (`StreamReader(validate_crcs=True)`: each
chunk is decompressed and checked before any of its messages is used, and the data section CRC
at its end), decodes every message on every channel from its embedded ROS 2 schema and checks
that the tick channels (/joint_state, /joint_torque, /wrench, /strip, /timing) hold the same
consecutive ticks with no gap, that /controller ticks are an increasing subset, that log time is
the simulated time of the tick, and (for a complete file with a summary) that the summary's
message counts and the recorder's drop counter agree.

It says how the file ends, as the project's reader does:
  complete       footer and end magic, every CRC good
  STOPPED EARLY  complete and intact, but the plant ended the recording on purpose (disk full,
                 write error): the reason from the `recording_summary` metadata
  TRUNCATED      cut short, no footer (a killed run): the ticks before the cut are intact
  CORRUPT        a chunk fails its CRC or does not decompress (or another record is damaged):
                 reading stops there, the ticks before it are intact

    python3 check_recording.py FILE [--allow-truncated] [--allow-damaged] [--expect-ticks N] [--dump JSON]

Exit status: 0 ok (also stopped early), 1 a check failed, 2 the file is cut short (and
--allow-truncated not given), 3 the file cannot be read as MCAP at all, 4 the file is corrupt (and
--allow-damaged not given). --dump writes what was read, per topic, for tests to compare.
"""
import argparse
import json
import struct
import sys

from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory

TICK_TOPICS = ["/joint_state", "/joint_torque", "/wrench", "/strip", "/timing"]
ALL_TOPICS = TICK_TOPICS + ["/controller", "/events"]
MAGIC = b"\x89MCAP0\r\n"
FOOTER_TAIL = 1 + 8 + 20 + len(MAGIC)  # footer record (opcode, length, 20 bytes) and end magic


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def ends_with_footer(data):
    """A complete MCAP file ends with a footer record and the magic."""
    if len(data) < len(MAGIC) + FOOTER_TAIL or not data.endswith(MAGIC):
        return False
    opcode, length = struct.unpack_from("<BQ", data, len(data) - FOOTER_TAIL)
    return opcode == 0x02 and length == 20


class Walk:
    """What one pass of StreamReader found, record by record."""

    def __init__(self):
        self.schemas, self.channels, self.metadata = {}, {}, {}
        self.rows = {t: [] for t in ALL_TOPICS}  # per topic: [tick, log_time, publish_time]
        self.decoded = {t: [] for t in ALL_TOPICS}
        self.chunks = 0
        self.error = None


def records(reader, walk):
    """The file's records, each chunk broken up (and its CRC checked) before any of it is used."""
    for r in reader.records:
        if isinstance(r, Chunk):
            inner = breakup_chunk(r, validate_crc=True)
            walk.chunks += 1
            yield from inner
        else:
            yield r


def walk(path):
    walk = Walk()
    factory = DecoderFactory()
    decoders = {}
    with open(path, "rb") as f:
        try:
            for r in records(StreamReader(f, emit_chunks=True, validate_crcs=True), walk):
                if isinstance(r, Schema):
                    walk.schemas[r.id] = r
                elif isinstance(r, Channel):
                    walk.channels[r.id] = r
                elif isinstance(r, Metadata):
                    walk.metadata[r.name] = dict(r.metadata)
                elif isinstance(r, Message):
                    ch = walk.channels[r.channel_id]
                    if ch.topic not in walk.rows:
                        continue
                    if r.channel_id not in decoders:
                        decoders[r.channel_id] = factory.decoder_for(ch.message_encoding, walk.schemas.get(ch.schema_id))
                    msg = decoders[r.channel_id](r.data)
                    walk.rows[ch.topic].append([msg.tick, r.log_time, r.publish_time])
                    walk.decoded[ch.topic].append(msg)
        except struct.error as e:  # the data ran out inside a record's fixed-size fields: cut there
            walk.error = f"EndOfFile: the last record is cut ({e})"
        except Exception as e:  # a cut file ends in a partial record; a bad chunk raises on its CRC
            walk.error = f"{type(e).__name__}: {e}" if str(e) else f"{type(e).__name__} (the last record is cut)"
    return walk


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("--allow-truncated", action="store_true", help="accept a file cut short (killed run)")
    ap.add_argument("--allow-damaged", action="store_true", help="accept a corrupt file (its ticks before the bad chunk)")
    ap.add_argument("--expect-ticks", type=int, default=None, help="the number of ticks the file must hold")
    ap.add_argument("--dump", default=None, help="write what was read (per topic: tick, log time, publish time) to this JSON file")
    args = ap.parse_args()

    with open(args.file, "rb") as f:
        data = f.read()
    if not data.startswith(MAGIC):
        print(f"ERROR: {args.file} is not an MCAP file (bad magic bytes)")
        sys.exit(3)
    complete = ends_with_footer(data)
    w = walk(args.file)
    cut_short = w.error is not None and "EndOfFile" in w.error
    if w.error is None and complete:
        stopped = w.metadata.get("recording_summary", {}).get("stopped_early", "")
        kind, detail = ("stopped_early", stopped) if stopped else ("complete", None)
    elif w.error is None or (cut_short and not complete):
        kind, detail = "cut", w.error or "the file ends without a footer"
    else:
        kind, detail = "corrupt", w.error + ("" if complete else " (the file has no footer either)")
    if args.dump:
        timing = [m.publish_wall_ns for m in w.decoded["/timing"]]
        events = [m.text for m in w.decoded["/events"]]
        with open(args.dump, "w") as f:
            json.dump({"kind": kind, "detail": detail, "chunks_read": w.chunks, "rows": w.rows,
                       "timing_publish_wall_ns": timing, "event_texts": events}, f)

    ticks = {t: [r[0] for r in w.rows[t]] for t in ALL_TOPICS}
    ref = ticks["/joint_state"]
    if not ref and kind in ("complete", "stopped_early"):
        fail("no /joint_state messages")
    for topic in TICK_TOPICS:
        t = ticks[topic]
        gap = next(((a, b) for a, b in zip(t, t[1:]) if b != a + 1), None)
        if gap:
            fail(f"{topic}: tick {gap[0]} is followed by {gap[1]}")
        if t[:1] != ref[:1] or len(t) != len(ref):
            fail(f"{topic}: {len(t)} ticks from {t[:1]}, /joint_state has {len(ref)} from {ref[:1]}")
    # log time = the run's wall-clock start (metadata rig/start_wall_ns) + simulated time
    start = int(w.metadata.get("rig", {}).get("start_wall_ns", "0"))
    for msg, (tick, log_time, _) in zip(w.decoded["/joint_state"], w.rows["/joint_state"]):
        if len(msg.q) != 6 or len(msg.qd) != 6:
            fail(f"/joint_state tick {tick}: q/qd do not have 6 joints")
        if log_time != start + max(0, round(msg.sim_time * 1e9)):
            fail(f"/joint_state tick {tick}: log time {log_time} is not the start {start} + the simulated time {msg.sim_time} s")
    for topic, rows in w.rows.items():
        late = next((r for r in rows if r[2] > r[1]), None)
        if late:
            fail(f"{topic} tick {late[0]}: publish time {late[2]} is later than the log time {late[1]}")
    for msg in w.decoded["/timing"]:
        stamp = msg.publish_stamp.sec * 1_000_000_000 + msg.publish_stamp.nanosec
        if stamp != msg.publish_wall_ns:
            fail(f"/timing tick {msg.tick}: publish_stamp {stamp} != publish_wall_ns {msg.publish_wall_ns}")
    for msg in w.decoded["/strip"]:
        if len(msg.centreline_z) not in (0, len(msg.centreline_pressure)):
            fail(f"/strip tick {msg.tick}: {len(msg.centreline_z)} z values for {len(msg.centreline_pressure)} pressures")
    c = ticks["/controller"]
    if any(b <= a for a, b in zip(c, c[1:])) or (c and (c[0] < ref[0] or c[-1] > ref[-1])):
        fail("/controller ticks are not an increasing subset of the tick range")
    if args.expect_ticks is not None and len(ref) != args.expect_ticks:
        fail(f"{len(ref)} ticks, expected {args.expect_ticks}")

    last_dropped = w.decoded["/timing"][-1].recorder_dropped if w.decoded["/timing"] else None
    dropped = last_dropped if last_dropped is not None else "unknown"
    if kind in ("cut", "corrupt") and last_dropped:
        fail(f"the recorder had dropped {last_dropped} records by tick {ref[-1]}")
    if kind in ("complete", "stopped_early"):
        with open(args.file, "rb") as f:
            from mcap.reader import make_reader

            summary = make_reader(f).get_summary()
        if summary is None and kind == "complete":
            fail("complete file without a summary section")
        if summary is not None:
            if summary.statistics is None:
                fail("summary without statistics")
            by_topic = {ch.topic: summary.statistics.channel_message_counts.get(cid, 0) for cid, ch in summary.channels.items()}
            for topic in ALL_TOPICS:
                if by_topic.get(topic, 0) != len(w.rows[topic]):
                    fail(f"{topic}: summary counts {by_topic.get(topic, 0)} messages, {len(w.rows[topic])} decoded")
        if "recording_summary" not in w.metadata:
            fail("no recording_summary metadata")
        s = w.metadata["recording_summary"]
        dropped = int(s["dropped_ticks"]) + int(s["dropped_events"])
        if dropped != 0:
            fail(f"the recorder dropped {dropped} records")
        if int(s["ticks_written"]) != len(ref):
            fail(f"recording_summary says {s['ticks_written']} ticks written, the file holds {len(ref)}")

    span = f"({ref[0]}..{ref[-1]}) " if ref else ""
    print(
        f"OK: {len(ref)} ticks {span}on {len(TICK_TOPICS)} tick channels, "
        f"{len(w.rows['/controller'])} /controller, {len(w.rows['/events'])} /events, dropped {dropped}"
    )
    if kind == "stopped_early":
        print(f"STOPPED EARLY: the plant ended the recording on purpose: {detail}; the file is complete and every CRC is good")
    elif kind == "cut":
        print(f"TRUNCATED: the file is cut short, without footer ({detail}); the {len(ref)} ticks above are intact")
        sys.exit(0 if args.allow_truncated else 2)
    elif kind == "corrupt":
        print(f"CORRUPT: reading stopped after {w.chunks} intact chunks: {detail}; the {len(ref)} ticks above are intact")
        sys.exit(0 if args.allow_damaged else 4)


if __name__ == "__main__":
    main()
