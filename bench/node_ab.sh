#!/usr/bin/env bash
# Two builds of tessera, alternating, on the same single-node load: `tessera loadtest` (node
# in-process, real WebSocket clients on loopback) on the pavilion at 1280x720, JPEG q85, AO off,
# 1 and 3 clients, SECONDS of common window each. Prints one JSON line per run (fps_total and the
# median rendering and pipeline ms) and, at the end, the new/old ratio of each figure's median
# over the pairs. Compare only as ratios within one run: the machine is shared.
# Usage: bench/node_ab.sh OLD_TESSERA NEW_TESSERA [PAIRS] [SECONDS]   (default 3 pairs, 10 s)
#        TESSERA_AB_WIDTH=64 TESSERA_AB_HEIGHT=36 bench/node_ab.sh ...   (frames of another size)
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$1; NEW=$2; PAIRS=${3:-3}; SECS=${4:-10}
W=${TESSERA_AB_WIDTH:-1280}; H=${TESSERA_AB_HEIGHT:-720}  # a small frame measures the pipeline, not the kernel
S=../shared/scenes/pavilion
out=$(mktemp)
run() {
  local bin=$1 tag=$2 clients=$3 line
  line=$("$bin" loadtest --scene $S/scene.gltf --camera-loop $S/camera-loop.json --size "$W" "$H" \
         --clients "$clients" --display jpeg --seconds "$SECS" --warmup 2 2> /dev/null | grep '"summary": true')
  python3 -c 'import json,sys; d=json.loads(sys.argv[3]); print(json.dumps({"build": sys.argv[1], "clients": int(sys.argv[2]), "fps_total": d["fps_total"], "rendering_ms": d["median_rendering_ms"], "pipeline_ms": d["median_pipeline_ms"]}))' \
    "$tag" "$clients" "$line" | tee -a "$out"
}
isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"load_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"isa\": \"$isa\", \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')\"}"
for _ in $(seq "$PAIRS"); do
  for c in 1 3; do
    run "$OLD" old $c
    run "$NEW" new $c
  done
done
echo "{\"load_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
python3 - "$out" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
for c in sorted({r["clients"] for r in rows}):
    med = lambda b, k: statistics.median(r[k] for r in rows if r["build"] == b and r["clients"] == c)
    print(json.dumps({"clients": c, **{f"{k}_new_over_old": round(med("new", k) / med("old", k), 3)
                                        for k in ("fps_total", "rendering_ms", "pipeline_ms")},
                      **{f"{k}_old": med("old", k) for k in ("fps_total", "pipeline_ms")},
                      **{f"{k}_new": med("new", k) for k in ("fps_total", "pipeline_ms")}}))
PY
rm -f "$out"
