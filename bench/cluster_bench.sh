#!/usr/bin/env bash
# Multi-process cluster figures on this machine (paper Table 1 layout): a dedicated master and
# N = 1..4 worker processes on localhost replay a shared scene's camera loop through
# `tessera loadtest`; the master's per-frame `cluster_frame` log lines give each node's kernel
# and rendering time. Kernel efficiency for N = single-node kernel / (N x largest node kernel),
# rendering efficiency likewise, frame by frame against the N=1 run; balance = largest / mean
# node kernel (normalised by the node coefficients), which does not depend on core count.
# Then: heterogeneous nodes (one worker with half the threads and a matching coefficient) and
# three clients on one tree (paper 7.5).
#
#   bench/cluster_bench.sh [SECONDS=20] [SIZE="640 360"] [AO=2] > docs/results/cluster.jsonl
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-20}
SIZE=${2:-"640 360"}
AO=${3:-2}
B=build/app/tessera
SCENE=../shared/scenes/pavilion
TMP=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$TMP"' EXIT

port_of() { # file key -> port from serve's first line
  for _ in $(seq 100); do
    if [ -s "$1" ]; then python3 -c "import json,sys; v=json.loads(open('$1').readline())['$2']; print(v.rsplit(':',1)[1].strip('/'))"; return; fi
    sleep 0.1
  done
  echo "no start line in $1" >&2; exit 1
}

# run NAME CLIENTS "worker-args-1" "worker-args-2" ...
run() {
  local name=$1 clients=$2; shift 2
  local kids="" i=0 pids=()
  for wargs in "$@"; do
    i=$((i + 1))
    # shellcheck disable=SC2086
    $B serve --no-http --cluster-port 0 --tessera.name=w$i $wargs > "$TMP/w$i.out" 2> "$TMP/w$i.err" &
    pids+=($!)
    kids="$kids${kids:+,}127.0.0.1:$(port_of "$TMP/w$i.out" cluster)"
  done
  $B serve --port 0 --no-render --threads 1 --children "$kids" > "$TMP/m.out" 2> "$TMP/m.err" &
  pids+=($!)
  local port; port=$(port_of "$TMP/m.out" listening)
  for _ in $(seq 100); do [ "$(grep -c child_connected "$TMP/m.err" || true)" -ge "$#" ] && break; sleep 0.1; done
  # shellcheck disable=SC2086
  $B loadtest --scene $SCENE/scene.gltf --camera-loop $SCENE/camera-loop.json --clients "$clients" \
     --seconds "$SECS" --warmup 2 --size $SIZE --ao "$AO" --port "$port" > "$TMP/$name.load" 2>/dev/null
  kill "${pids[@]}"; wait "${pids[@]}" 2>/dev/null || true
  python3 - "$name" "$TMP/m.err" "$TMP/$name.load" <<'PY'
import json, sys
name, err, load = sys.argv[1:]
for line in open(err):
    if '"cluster_frame"' in line:
        d = json.loads(line)
        print(json.dumps({"run": name, "session": d["session"], "frame": d["cluster_frame"], "balance": d["balance"],
                          "recovered": d["recovered"], "per_node": d["per_node"]}))
summary = [json.loads(l) for l in open(load) if '"summary"' in l]
if summary: print(json.dumps({"run": name, "loadtest": summary[-1]}))
PY
}

run n1 1 "--threads 2"
run n2 1 "--threads 2" "--threads 2"
run n3 1 "--threads 2" "--threads 2" "--threads 2"
run n4 1 "--threads 2" "--threads 2" "--threads 2" "--threads 2"
run hetero 1 "--threads 2 --tessera.logical-cores=2" "--threads 1 --tessera.logical-cores=1"
run clients3 3 "--threads 2" "--threads 2"
echo "{\"summary\": true, \"seconds\": $SECS, \"size\": \"$SIZE\", \"ao\": $AO, \"scene\": \"$SCENE\", \"cpu\": \"$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)\", \"cores\": $(nproc), \"load\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
