#!/usr/bin/env bash
# Does a connected live view cost the 1 kHz loop anything? Interleaved `rig timing` runs on this
# machine: "none" (no live view, as without --live) and "client" (--live on a loopback port with
# tests/live/live_client.mjs subscribed to every channel for the whole run), one after the other,
# RUNS times each; prints round-trip p50/p99/max, misses and the live view's sent/dropped counts
# of every run. The issue's bar: "client" no worse than the run-to-run spread of "none".
#
# usage: tests/live/measure.sh [SECONDS (60)] [RUNS (2)] [LIVE_RATE_HZ (100)]
# Needs the release binaries (cargo build --release --workspace --bins), node and `npm ci` here.
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds=${1:-60}
runs=${2:-2}
rate=${3:-100}
rig=target/release/rig
out=$(mktemp -d /tmp/live-measure.XXXXXX)
[ -x "$rig" ] || { echo "measure.sh: $rig missing: cargo build --release --workspace --bins" >&2; exit 1; }
[ -d tests/live/node_modules/@foxglove/ws-protocol ] || { echo "measure.sh: run npm ci in tests/live" >&2; exit 1; }

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

one() { # one() KIND N: one timing run, its summary JSON in $out/KIND-N.json
  local kind=$1 n=$2 dir="$out/$1-$2"
  if [ "$kind" = none ]; then
    "$rig" timing --seconds "$seconds" --out "$dir" --json "$dir.json" >"$dir.log" 2>&1
  else
    local port; port=$(free_port)
    "$rig" timing --seconds "$seconds" --out "$dir" --json "$dir.json" --live "127.0.0.1:$port" --live-rate "$rate" >"$dir.log" 2>&1 &
    local rig_pid=$!
    # connect as soon as the plant listens; stay subscribed until the run ends
    for _ in $(seq 1 300); do
      (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
      sleep 0.1
    done
    (cd tests/live && node live_client.mjs "ws://127.0.0.1:$port" all $((seconds + 120))) >"$dir.client.json" 2>"$dir.client.err" &
    local client_pid=$!
    wait "$rig_pid" || true
    wait "$client_pid" || echo "measure.sh: the live client of $kind-$n failed: $(cat "$dir.client.err")" >&2
  fi
  echo "$kind $n $(cat /proc/loadavg | cut -d' ' -f1-3)" >>"$out/load"
}

for n in $(seq 1 "$runs"); do
  one none "$n"
  one client "$n"
done

python3 - "$out" "$runs" <<'EOF'
import json, sys, os
out, runs = sys.argv[1], int(sys.argv[2])
load = {tuple(l.split()[:2]): " ".join(l.split()[2:]) for l in open(os.path.join(out, "load"))}
print(f"{'run':<10} {'ticks':>6} {'misses':>6} {'miss %':>7} {'p50 us':>7} {'p99 us':>7} {'max us':>7} {'live sent':>9} {'dropped':>7} {'client got':>10}  load after (1/5/15 min)")
for n in range(1, runs + 1):
    for kind in ("none", "client"):
        p = os.path.join(out, f"{kind}-{n}.json")
        if not os.path.exists(p):
            print(f"{kind}-{n}: no summary (see {out}/{kind}-{n}.log)")
            continue
        v = json.load(open(p))
        live = v.get("live") or {}
        got = "-"
        cj = os.path.join(out, f"{kind}-{n}.client.json")
        if os.path.exists(cj) and os.path.getsize(cj) > 0:
            got = sum(t["count"] for t in json.load(open(cj))["topics"].values())
        miss = 100.0 * v["misses"] / max(v["ticks"], 1)
        print(f"{kind + '-' + str(n):<10} {v['ticks']:>6} {v['misses']:>6} {miss:>7.3f} {v['rt_p50_us']:>7.1f} {v['rt_p99_us']:>7.1f} {v['rt_max_us']:>7.1f} "
              f"{live.get('sent', '-'):>9} {live.get('dropped', '-'):>7} {got:>10}  {load.get((kind, str(n)), '?')}")
print(f"runs and logs in {out}")
EOF
