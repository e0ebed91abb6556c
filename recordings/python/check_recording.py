#!/usr/bin/env python3
"""Check a rig recording with the official MCAP Python readers (`mcap`, `mcap-ros2-support`).

Decodes every message on every channel from its embedded ROS 2 schema and checks that the tick
channels (/joint_state, /joint_torque, /wrench, /strip, /timing) hold the same consecutive ticks
with no gap, that /controller ticks are an increasing subset, that log time is the simulated time
of the tick, and (for a complete file) that the summary's message counts and the recorder's drop
counter agree.

    python3 check_recording.py FILE [--allow-truncated] [--expect-ticks N]

Exit status: 0 ok, 1 a check failed, 2 the file is truncated (and --allow-truncated not given),
3 the file cannot be read as MCAP at all.
"""
import argparse
import sys

from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory

TICK_TOPICS = ["/joint_state", "/joint_torque", "/wrench", "/strip", "/timing"]
ALL_TOPICS = TICK_TOPICS + ["/controller", "/events"]


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("--allow-truncated", action="store_true", help="accept a file without summary/footer (killed run)")
    ap.add_argument("--expect-ticks", type=int, default=None, help="the number of ticks the file must hold")
    args = ap.parse_args()

    with open(args.file, "rb") as f:
        if f.read(8) != b"\x89MCAP0\r\n":
            print(f"ERROR: {args.file} is not an MCAP file (bad magic bytes)")
            sys.exit(3)

    ticks = {t: [] for t in ALL_TOPICS}
    counts = {t: 0 for t in ALL_TOPICS}
    truncated = None
    last_dropped = None
    with open(args.file, "rb") as f:
        reader = NonSeekingReader(f, decoder_factories=[DecoderFactory()])
        try:
            for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
                topic = channel.topic
                if topic not in counts:
                    continue
                counts[topic] += 1
                ticks[topic].append(msg.tick)
                if topic == "/joint_state":
                    if len(msg.q) != 6 or len(msg.qd) != 6:
                        fail(f"/joint_state tick {msg.tick}: q/qd do not have 6 joints")
                    if message.log_time != max(0, round(msg.sim_time * 1e9)):
                        fail(f"/joint_state tick {msg.tick}: log time {message.log_time} is not the simulated time {msg.sim_time} s")
                elif topic == "/timing":
                    last_dropped = msg.recorder_dropped
                    stamp = msg.publish_stamp.sec * 1_000_000_000 + msg.publish_stamp.nanosec
                    if stamp != msg.publish_wall_ns:
                        fail(f"/timing tick {msg.tick}: publish_stamp {stamp} != publish_wall_ns {msg.publish_wall_ns}")
                elif topic == "/strip":
                    if len(msg.centreline_z) not in (0, len(msg.centreline_pressure)):
                        fail(f"/strip tick {msg.tick}: {len(msg.centreline_z)} z values for {len(msg.centreline_pressure)} pressures")
        except Exception as e:  # a cut file ends in a partial record
            truncated = f"{type(e).__name__}: {e}" if str(e) else f"{type(e).__name__} (the last record is cut)"

    ref = ticks["/joint_state"]
    if not ref:
        fail("no /joint_state messages")
    for topic in TICK_TOPICS:
        t = ticks[topic]
        if t != list(range(ref[0], ref[0] + len(t))):
            gap = next((a, b) for a, b in zip(t, t[1:]) if b != a + 1)
            fail(f"{topic}: tick {gap[0]} is followed by {gap[1]}")
        if t[:1] != ref[:1] or len(t) != len(ref):
            fail(f"{topic}: {len(t)} ticks from {t[:1]}, /joint_state has {len(ref)} from {ref[0]}")
    c = ticks["/controller"]
    if any(b <= a for a, b in zip(c, c[1:])) or (c and (c[0] < ref[0] or c[-1] > ref[-1])):
        fail("/controller ticks are not an increasing subset of the tick range")
    if args.expect_ticks is not None and len(ref) != args.expect_ticks:
        fail(f"{len(ref)} ticks, expected {args.expect_ticks}")

    dropped = last_dropped if last_dropped is not None else "unknown"
    if truncated is not None and last_dropped:
        fail(f"the recorder had dropped {last_dropped} records by tick {ref[-1]}")
    if truncated is None:
        with open(args.file, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                fail("complete file without summary statistics")
            by_topic = {ch.topic: summary.statistics.channel_message_counts.get(cid, 0) for cid, ch in summary.channels.items()}
            for topic in ALL_TOPICS:
                if by_topic.get(topic, 0) != counts[topic]:
                    fail(f"{topic}: summary counts {by_topic.get(topic, 0)} messages, {counts[topic]} decoded")
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            if "recording_summary" not in meta:
                fail("no recording_summary metadata")
            s = meta["recording_summary"]
            dropped = int(s["dropped_ticks"]) + int(s["dropped_events"])
            if dropped != 0:
                fail(f"the recorder dropped {dropped} records")

    print(
        f"OK: {len(ref)} ticks ({ref[0]}..{ref[-1]}) on {len(TICK_TOPICS)} tick channels, "
        f"{counts['/controller']} /controller, {counts['/events']} /events, dropped {dropped}"
    )
    if truncated is not None:
        print(f"TRUNCATED: the file ends without summary/footer ({truncated}); the complete chunks above are intact")
        sys.exit(0 if args.allow_truncated else 2)


if __name__ == "__main__":
    main()
