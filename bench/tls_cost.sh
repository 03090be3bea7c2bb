#!/usr/bin/env bash
# What TLS costs a node's clients (issue 21): `tessera loadtest` (node in-process, real
# WebSocket clients on loopback) on the pavilion at 1280x720, JPEG q85, AO off, 1 and 3 clients,
# SECONDS of common window each, alternating plain WebSocket and WSS (a self-signed certificate
# from scripts/tls-cert.sh, TLS 1.3 AES-256-GCM as negotiated) with the same binary. Prints one
# JSON line per run (fps_total, median and p90 input-to-frame latency, median pipeline ms) and
# at the end, per client count, the TLS/plain ratio of each figure's median over the pairs.
# Compare only as ratios within one run: the machine is shared. Target: fps within 3%.
# Usage: bench/tls_cost.sh [TESSERA] [PAIRS] [SECONDS]   (default build/app/tessera, 3 pairs, 10 s)
#        TESSERA may be a command with arguments (a loader and the binary), unquoted.
#        TESSERA_AB_WIDTH=640 TESSERA_AB_HEIGHT=360 bench/tls_cost.sh ...   (frames of another size)
#        FRAMES=F bench/tls_cost.sh ...   (each client's F frames after its warm-up instead of a time
#        window: every run renders the same frames of the camera loop, so the loop's varying cost
#        per frame does not enter the ratio)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-build/app/tessera}; PAIRS=${2:-3}; SECS=${3:-10}
W=${TESSERA_AB_WIDTH:-1280}; H=${TESSERA_AB_HEIGHT:-720}
S=${SCENE:-../shared/scenes/pavilion}
out=$(mktemp); certs=${TLS_DIR:-}  # TLS_DIR: node.crt and node.key made before (a machine without the openssl CLI)
if [[ -z $certs ]]; then
  certs=$(mktemp -d)
  trap 'rm -rf "$out" "$certs"' EXIT
  scripts/tls-cert.sh "$certs" > /dev/null
else
  trap 'rm -f "$out"' EXIT
fi
run() {
  local tag=$1 clients=$2 line extra=()
  [[ $tag == tls ]] && extra=(--tls-cert "$certs/node.crt" --tls-key "$certs/node.key")
  local window=(--seconds "$SECS")
  [[ -n ${FRAMES:-} ]] && window=(--frames "$FRAMES")
  line=$($BIN loadtest --scene $S/scene.gltf --camera-loop $S/camera-loop.json --size "$W" "$H" \
         --clients "$clients" --display jpeg "${window[@]}" --warmup 2 "${extra[@]}" 2> /dev/null | grep '"summary": true')
  python3 -c 'import json,sys; d=json.loads(sys.argv[3]); print(json.dumps({"transport": sys.argv[1], "clients": int(sys.argv[2]), "fps_total": d["fps_total"], "latency_ms": d["median_latency_ms"], "p90_latency_ms": d["p90_latency_ms"], "pipeline_ms": d["median_pipeline_ms"], "bytes": d["median_bytes"], "tls": d["tls"], "errors": d["errors"]}))' \
    "$tag" "$clients" "$line" | tee -a "$out"
}
isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"load_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"isa\": \"$isa\", \"cores\": $(nproc), \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')\", \"size\": \"${W}x${H}\", \"seconds\": $SECS, \"frames\": \"${FRAMES:-}\"}"
for p in $(seq "$PAIRS"); do
  for c in 1 3; do
    # Alternate which goes first, so that a drift in the machine does not favour one.
    if (( p % 2 )); then run plain $c; run tls $c; else run tls $c; run plain $c; fi
  done
done
echo "{\"load_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
python3 - "$out" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
for c in sorted({r["clients"] for r in rows}):
    med = lambda t, k: statistics.median(r[k] for r in rows if r["transport"] == t and r["clients"] == c)
    print(json.dumps({"clients": c, "pairs": sum(r["transport"] == "tls" and r["clients"] == c for r in rows),
                      **{f"{k}_tls_over_plain": round(med("tls", k) / med("plain", k), 3)
                         for k in ("fps_total", "latency_ms", "p90_latency_ms", "pipeline_ms")},
                      **{f"{k}_plain": med("plain", k) for k in ("fps_total", "latency_ms")},
                      **{f"{k}_tls": med("tls", k) for k in ("fps_total", "latency_ms")}}))
PY
