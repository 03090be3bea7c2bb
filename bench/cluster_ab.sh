#!/usr/bin/env bash
# Two builds of tessera, alternating, on the same cluster setup: a dedicated master with two
# workers on localhost (each run on its own ports), `tessera loadtest --clients 3 --size 640 360`
# on the pavilion for 6 s. Prints one line per run: fps_total, median_upload_ms (median time
# from a client's first scene message to its first frame) and the median of the master's
# per-frame balance (max over mean of the nodes' kernel times, its cluster_frame events).
# Compare the two as ratios.
# Usage: bench/cluster_ab.sh OLD_TESSERA NEW_TESSERA [PAIRS]   (default 3 pairs)
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$1; NEW=$2; PAIRS=${3:-3}
S=../shared/scenes/pavilion
port=47200
mlog=$(mktemp)
trap 'rm -f "$mlog"' EXIT
run() {
  local bin=$1 tag=$2
  port=$((port + 10))
  "$bin" serve --no-http --cluster-port $((port + 1)) --tessera.name=w1 > /dev/null 2>&1 & local p1=$!
  "$bin" serve --no-http --cluster-port $((port + 2)) --tessera.name=w2 > /dev/null 2>&1 & local p2=$!
  sleep 1
  "$bin" serve --port $port --no-render --children 127.0.0.1:$((port + 1)),127.0.0.1:$((port + 2)) \
    --tessera.name=master > /dev/null 2> "$mlog" & local p0=$!
  sleep 2
  local out
  out=$("$bin" loadtest --host 127.0.0.1 --port $port --scene $S/scene.gltf --camera-loop $S/camera-loop.json \
        --clients 3 --size 640 360 --seconds 6 2> /dev/null | tail -1)
  python3 -c '
import json, statistics, sys
d = json.loads(sys.argv[2])
bal = []
for l in open(sys.argv[3]):
    try: e = json.loads(l)
    except ValueError: continue
    if "cluster_frame" in e and "balance" in e: bal.append(e["balance"])
print(json.dumps({"build": sys.argv[1], "fps_total": d["fps_total"], "median_upload_ms": d["median_upload_ms"],
                  "median_balance": statistics.median(bal) if bal else None, "frames": len(bal), "errors": d["errors"]}))' "$tag" "$out" "$mlog"
  kill $p0 $p1 $p2; wait $p0 $p1 $p2 2> /dev/null || true
  sleep 1
}
isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"load_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"isa\": \"$isa\", \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')\"}"
for _ in $(seq "$PAIRS"); do
  run "$OLD" old
  run "$NEW" new
done
echo "{\"load_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
