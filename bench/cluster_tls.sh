#!/usr/bin/env bash
# The cost of mutual TLS between nodes on a cluster's frame time (docs/operations.md, "Running a
# cluster across hosts securely"). One tree, a dedicated master and two workers on localhost,
# started plain and over mutual TLS in turn (plain, tls, plain, tls, ...: the same machine
# state for both), each run streaming the same frames of the pavilion's camera loop to one client
# (`tessera loadtest --warmup 3 --frames F`, two requests outstanding). Per run: frame_ms
# (the window over its frames: the time per frame the client sees), fps, the median rendering
# and pipeline times of the frames, the nodes' CPU seconds over the run; then per mode the
# medians of the runs' frame_ms and CPU seconds, tls / plain, and the median over pairs of a
# tls run's frame_ms over the plain run's before it (target: frame time +3% at most). Load (uptime), CPU and ISA at the start and the end. Certificates come from
# scripts/cluster-certs.sh in a temporary folder.
#
#   bench/cluster_tls.sh [PAIRS=3] [FRAMES=60] [SIZE="1280 720"] [THREADS=1] [WORKERS=2]
#   TESSERA (a command, may hold a loader), SCENE (folder of scene.gltf and camera-loop.json) and
#   CLUSTER_CERTS (made before by scripts/cluster-certs.sh DIR master w1 ... wN, for a machine
#   without the openssl command) override the defaults. The pairs alternate which mode runs first.
set -euo pipefail
cd "$(dirname "$0")/.."
PAIRS=${1:-3}
FRAMES=${2:-60}
SIZE=${3:-"1280 720"}
THREADS=${4:-1}
WORKERS=${5:-2}
B=${TESSERA:-build/app/tessera}
SCENE=${SCENE:-../shared/scenes/pavilion}
TMP=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null || true; done
  rm -rf "$TMP"
}
trap cleanup EXIT
CERTS=${CLUSTER_CERTS:-$TMP/certs}
[ -n "${CLUSTER_CERTS:-}" ] || scripts/cluster-certs.sh "$CERTS" master $(seq -f 'w%g' 1 "$WORKERS") > /dev/null

port_of() { # file key -> port from serve's first line
  for _ in $(seq 200); do
    if [ -s "$1" ]; then python3 -c "import json,sys; v=json.loads(open('$1').readline())['$2']; print(v.rsplit(':',1)[1].strip('/'))"; return; fi
    sleep 0.1
  done
  echo "no start line in $1" >&2; exit 1
}
tls_args() { # node -> its TLS settings
  echo "--tessera.cluster-tls-cert=$CERTS/$1.pem --tessera.cluster-tls-key=$CERTS/$1.key --tessera.cluster-tls-ca=$CERTS/ca.pem"
}

# run MODE (plain | tls) -> one JSON line
run() {
  local mode=$1 kids="" i
  pids=()
  for i in $(seq "$WORKERS"); do
    local extra=""
    [ "$mode" = tls ] && extra=$(tls_args w$i)
    # shellcheck disable=SC2086
    $B serve --no-http --cluster-port 0 --threads "$THREADS" --tessera.name=w$i --tessera.log-frames=false $extra \
      > "$TMP/w$i.out" 2> "$TMP/w$i.err" &
    pids+=($!)
    kids="$kids${kids:+,}127.0.0.1:$(port_of "$TMP/w$i.out" cluster)"
  done
  local extra=""
  [ "$mode" = tls ] && extra=$(tls_args master)
  # shellcheck disable=SC2086
  $B serve --port 0 --no-render --threads 1 --tessera.log-frames=false --children "$kids" $extra \
    > "$TMP/m.out" 2> "$TMP/m.err" &
  pids+=($!)
  local port; port=$(port_of "$TMP/m.out" listening)
  for _ in $(seq 200); do [ "$(grep -c child_connected "$TMP/m.err" || true)" -ge "$WORKERS" ] && break; sleep 0.1; done
  grep -q "\"cluster_security\": \"$([ "$mode" = tls ] && echo mutual_tls || echo none)\"" "$TMP/m.err" ||
    { echo "master not in mode $mode:" >&2; cat "$TMP/m.err" >&2; exit 1; }
  # shellcheck disable=SC2086
  $B loadtest --scene $SCENE/scene.gltf --camera-loop $SCENE/camera-loop.json --clients 1 --warmup 3 \
     --frames "$FRAMES" --size $SIZE --port "$port" > "$TMP/load" 2> /dev/null
  # CPU time of the three nodes over the whole run (start, scene, warm-up and frames): what TLS
  # costs shows here even when a busy machine blurs the frame times.
  local ticks=0 p
  for p in "${pids[@]}"; do ticks=$((ticks + $(awk '{print $14 + $15}' "/proc/$p/stat"))); done
  kill "${pids[@]}"; wait "${pids[@]}" 2> /dev/null || true
  pids=()
  python3 - "$mode" "$TMP/load" "$TMP/m.err" "$ticks" "$(getconf CLK_TCK)" <<'PY'
import json, sys
mode, load, err, ticks, hz = sys.argv[1:]
s = [json.loads(l) for l in open(load) if '"summary"' in l][-1]
recovered = sum(1 for l in open(err) if '"recovering"' in l)
print(json.dumps({"mode": mode, "frame_ms": round(1000 * s["window_s"] / max(1, s["frames_in_window"]), 3),
                  "fps": s["fps_total"], "frames": s["frames_in_window"], "median_rendering_ms": s["median_rendering_ms"],
                  "median_pipeline_ms": s["median_pipeline_ms"], "nodes_cpu_s": round(int(ticks) / int(hz), 2),
                  "errors": s["errors"], "recovered": recovered}))
PY
}

isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"start\": true, \"uptime\": \"$(uptime)\", \"isa\": \"$isa\", \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)\", \"cores\": $(nproc), \"size\": \"$SIZE\", \"frames\": $FRAMES, \"worker_threads\": $THREADS, \"workers\": $WORKERS, \"scene\": \"$SCENE\"}"
for p in $(seq "$PAIRS"); do
  if (( p % 2 )); then run plain | tee -a "$TMP/runs"; run tls | tee -a "$TMP/runs"
  else run tls | tee -a "$TMP/runs"; run plain | tee -a "$TMP/runs"; fi
done
python3 - "$TMP/runs" <<'PY'
import json, statistics, sys
runs = [json.loads(l) for l in open(sys.argv[1])]
med = {m: statistics.median(r["frame_ms"] for r in runs if r["mode"] == m) for m in ("plain", "tls")}
cpu = {m: statistics.median(r["nodes_cpu_s"] for r in runs if r["mode"] == m) for m in ("plain", "tls")}
# Each pair's tls run over its plain run (the order alternates): drift in the machine's load cancels out.
pairs = [tuple(sorted(runs[i:i + 2], key=lambda r: r["mode"])) for i in range(0, len(runs) - 1, 2)]
pair_ratio = statistics.median(t["frame_ms"] / p["frame_ms"] for p, t in pairs)
print(json.dumps({"summary": True, "median_frame_ms_plain": med["plain"], "median_frame_ms_tls": med["tls"],
                  "tls_over_plain": round(med["tls"] / med["plain"], 4), "median_pair_ratio": round(pair_ratio, 4),
                  "median_nodes_cpu_s_plain": round(cpu["plain"], 2), "median_nodes_cpu_s_tls": round(cpu["tls"], 2),
                  "cpu_tls_over_plain": round(cpu["tls"] / cpu["plain"], 4), "pairs": len(pairs)}))
PY
echo "{\"end\": true, \"uptime\": \"$(uptime)\"}"
