#!/usr/bin/env bash
# Interleaved A/B of `rig timing` between a git revision (A) and the working tree (B).
#
#   tests/ab-timing.sh [-n PAIRS] [-s SECONDS] REV [-- EXTRA rig timing FLAGS]
#
# A is REV built in release in a git worktree kept with its target directory in
# ${AB_CACHE:-$HOME/.cache/rig-ab}/<commit> (so a second comparison against the same revision
# does not rebuild, and A's binaries still find their scenarios); B is this working tree, built in release here. The pairs alternate their
# order (A B, B A, A B, ...) so a drift of the host's load hits both sides alike. Each run's
# summary JSON (`rig timing --json`) is kept in the output directory; at the end the script
# prints, per side, the median over the runs of the round trip p50/p90/p99, the tick-period
# jitter p99 and the misses, and the ratio B/A of each median. EXTRA flags go to both sides
# (both builds must know them: e.g. `--no-host-probe` is newer than 2026-12-03).
# Timing figures mean little on a loaded host: the load average is printed with every run.
set -euo pipefail

pairs=3
seconds=20
while getopts "n:s:h" opt; do
    case $opt in
    n) pairs=$OPTARG ;;
    s) seconds=$OPTARG ;;
    *)
        sed -n '2,14p' "$0"
        exit 2
        ;;
    esac
done
shift $((OPTIND - 1))
[[ $# -ge 1 ]] || {
    echo "ab-timing.sh: which revision is A? (e.g. bc12a3b)" >&2
    exit 2
}
rev=$1
shift
[[ ${1:-} == "--" ]] && shift
extra=("$@")

root=$(git rev-parse --show-toplevel)
commit=$(git -C "$root" rev-parse --verify "$rev^{commit}")
cache=${AB_CACHE:-$HOME/.cache/rig-ab}/$commit
out=$(mktemp -d "${TMPDIR:-/tmp}/ab-timing.XXXXXX")
echo "A = $rev ($commit), B = working tree of $root; $pairs pairs of ${seconds} s; results in $out"

# A: the revision, checked out in the cache beside its target directory and kept there: its
# binaries find the scenarios by the absolute path they were built in.
src=$cache/src
if [[ ! -x $cache/release/rig || ! -d $src/scenarios ]]; then
    mkdir -p "$cache"
    git -C "$root" worktree remove --force "$src" 2>/dev/null || rm -rf "$src"
    git -C "$root" worktree prune
    git -C "$root" worktree add --detach "$src" "$commit" >/dev/null
    echo "building A in $src (target $cache) ..."
    (cd "$src" && CARGO_TARGET_DIR=$cache cargo build --release --workspace --bins -q)
fi
echo "building B ..."
(cd "$root" && cargo build --release --workspace --bins -q)
rig_a=$cache/release/rig
rig_b=$root/target/release/rig

run() { # side, index
    local side=$1 i=$2 bin
    [[ $side == A ]] && bin=$rig_a || bin=$rig_b
    echo "run $i$side: load average $(cut -d' ' -f1-3 /proc/loadavg)"
    "$bin" timing --seconds "$seconds" --out "$out/$side$i" --json "$out/$side$i.json" "${extra[@]}" >"$out/$side$i.log" 2>&1 ||
        echo "  (exit status $?; see $out/$side$i.log)"
}
for ((i = 1; i <= pairs; i++)); do
    if ((i % 2)); then run A "$i" && run B "$i"; else run B "$i" && run A "$i"; fi
done

python3 - "$out" "$pairs" <<'EOF'
import json, statistics, sys
out, pairs = sys.argv[1], int(sys.argv[2])
rows = [("round trip p50", "round_trip", "p50_us"), ("round trip p90", "round_trip", "p90_us"),
        ("round trip p99", "round_trip", "p99_us"), ("jitter p99", "jitter", "p99_us"), ("misses", "misses", None)]
def load(side):
    runs = []
    for i in range(1, pairs + 1):
        try:
            runs.append(json.load(open(f"{out}/{side}{i}.json")))
        except (OSError, ValueError):
            print(f"run {i}{side}: no summary JSON")
    return runs
a, b = load("A"), load("B")
def med(runs, key, q):
    v = [r[key] if q is None else r[key][q] for r in runs]
    return statistics.median(v) if v else float("nan")
print(f"{'median of runs':<16} {'A':>10} {'B':>10} {'B/A':>7}   (A: {len(a)} runs, B: {len(b)} runs)")
for name, key, q in rows:
    ma, mb = med(a, key, q), med(b, key, q)
    ratio = mb / ma if ma else float("nan")
    unit = "" if q is None else " us"
    print(f"{name:<16} {ma:>10.1f} {mb:>10.1f} {ratio:>7.2f}{unit}")
    if q is not None:
        print(f"{'':<16} runs A {[round(r[key][q], 1) for r in a]}, B {[round(r[key][q], 1) for r in b]}")
EOF
