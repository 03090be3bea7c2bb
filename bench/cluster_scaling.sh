#!/usr/bin/env bash
# A real multi-process cluster, one single-threaded worker per core (paper Table 1): a dedicated
# master (`--no-render`, 1 thread, on core 0 with the client) and N = 1, 2, 4, 8, 15 workers
# (`--threads 1`, worker i pinned to core i when `taskset` is there and the machine has the
# cores). `tessera loadtest --frames F` replays the same F frames of the camera loop after its
# warm-up on every tree, so frame k of run nN can be compared with frame k of run n1. The
# master's `cluster_frame` lines (each node's kernel and rendering time) and the loadtest
# output are kept in OUTDIR; bench/cluster_scaling_report.py OUTDIR makes the table.
#
# The control: N processes on the same cores each render the whole of one loop frame at once
# (`tessera render --threads 1`, no cluster). On a shared machine (a VM's cores, one package's
# turbo and caches) each is slower than one alone; that slowdown is the machine's, not the
# balancer's, and the report shows it beside the efficiency.
#
#   bench/cluster_scaling.sh OUTDIR [SIZES="640x360 1280x720"] [FRAMES="12 6"] [WORKERS="1 2 4 8 15"]
#
# TESSERA: how to run the binary (default build/app/tessera; a bundle run by its own loader
# works too, e.g. "bundle/ld.so --library-path bundle/lib bundle/tessera"). SCENE: a folder with
# scene.gltf and camera-loop.json (default ../shared/scenes/pavilion). AO: AO samples (2).
# PIN=0: no taskset. WORKER_ARGS: more options for every worker (e.g. CAF's scheduler threads).
# LOOP: the camera loop (default $SCENE/camera-loop.json). VARIANTS: the balancer's predictors to
# compare, run one after the other on the same frames (e.g. "previous reproject": the master with
# --tessera.reproject=false / true; runs named SIZE-nN-VARIANT-rK); REPS: how many times each
# (alternating). The 1-worker reference runs once, without a variant. MASTER_ARGS: more options
# for the master.
set -euo pipefail
OUT=$1
SIZES=${2:-"640x360 1280x720"}
FRAMES=(${3:-12 6})
WORKERS=${4:-"1 2 4 8 15"}
TESSERA=${TESSERA:-build/app/tessera}
SCENE=${SCENE:-../shared/scenes/pavilion}
LOOP=${LOOP:-$SCENE/camera-loop.json}
VARIANTS=${VARIANTS:-}
REPS=${REPS:-1}
AO=${AO:-2}
mkdir -p "$OUT"
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
read -r -a T <<< "$TESSERA"
cores=$(nproc)
pin() {  # core -> prefix
  if [[ ${PIN:-1} != 0 ]] && command -v taskset > /dev/null && (( $1 < cores )); then echo "taskset -c $1"; fi
}
pids=()
cleanup() { kill "${pids[@]}" 2> /dev/null || true; wait 2> /dev/null || true; }
trap cleanup EXIT

wait_line() {  # file pattern count timeout_s
  local i
  for ((i = 0; i < $4 * 10; ++i)); do
    [[ -f $1 ]] && (( $(grep -c "$2" "$1" || true) >= $3 )) && return 0
    sleep 0.1
  done
  echo "timed out waiting for $3 x '$2' in $1" >&2
  return 1
}

run() {  # name size frames workers [master options]
  local name=$1 size=$2 frames=$3 n=$4 extra=${5:-} base=$((20000 + RANDOM % 1000 * 40)) kids="" i
  pids=()
  for ((i = 1; i <= n; ++i)); do
    # shellcheck disable=SC2086
    $(pin "$i") "${T[@]}" serve --no-http --cluster-port $((base + i)) --threads 1 --tessera.name=w$i ${WORKER_ARGS:-} \
      > "$OUT/$name.w$i.out" 2> "$OUT/$name.w$i.err" &
    pids+=($!)
    kids="$kids${kids:+,}127.0.0.1:$((base + i))"
  done
  for ((i = 1; i <= n; ++i)); do wait_line "$OUT/$name.w$i.out" cluster 1 60; done
  # shellcheck disable=SC2086
  $(pin 0) "${T[@]}" serve --port "$base" --no-render --threads 1 --children "$kids" --tessera.name=master ${MASTER_ARGS:-} $extra \
    > "$OUT/$name.master.out" 2> "$OUT/$name.master.err" &
  pids+=($!)
  wait_line "$OUT/$name.master.err" child_connected "$n" 60
  $(pin 0) "${T[@]}" loadtest --scene "$SCENE/scene.gltf" --camera-loop "$LOOP" --port "$base" \
    --frames "$frames" --warmup 2 --size "${size%x*}" "${size#*x}" --ao "$AO" > "$OUT/$name.load" 2> "$OUT/$name.load.err" || true
  cleanup
  echo "$name: $(grep -c cluster_frame "$OUT/$name.master.err" || true) frames" >&2
}

control() {  # size workers: N concurrent whole-frame renders of loop frame 10, pinned like the workers
  local size=$1 n=$2 i
  for ((i = 1; i <= n; ++i)); do
    $(pin "$i") "${T[@]}" render --threads 1 --size "${size%x*}" "${size#*x}" --ao "$AO" --scene "$SCENE/scene.gltf" \
      --camera-loop "$LOOP" --frame 10 --out "$OUT/control-$i.png" > "$OUT/control-$i.json" 2> /dev/null &
  done
  wait
  cat "$OUT"/control-*.json > "$OUT/$size-control-n$n.json"
  rm -f "$OUT"/control-*
}

k=0
for size in $SIZES; do
  f=${FRAMES[$k]:-${FRAMES[0]}}
  k=$((k + 1))
  for n in $WORKERS; do
    if [[ -z $VARIANTS || $n == 1 ]]; then run "$size-n$n" "$size" "$f" "$n"; continue; fi
    for ((rep = 1; rep <= REPS; ++rep)); do
      for v in $VARIANTS; do
        case $v in
          previous) opt=--tessera.reproject=false ;;
          reproject) opt=--tessera.reproject=true ;;
          *) echo "unknown variant $v" >&2; exit 2 ;;
        esac
        run "$size-n$n-$v-r$rep" "$size" "$f" "$n" "$opt"
      done
    done
  done
  for n in $WORKERS; do control "$size" "$n"; done
done
isa=$(grep -m1 -o -w 'avx512f' /proc/cpuinfo || grep -m1 -o -w 'avx2' /proc/cpuinfo || echo sse)
printf '{"summary": true, "scene": "%s", "loop": "%s", "variants": "%s", "reps": %s, "ao": %s, "sizes": "%s", "frames": "%s", "workers": "%s", "cpu": "%s", "cores": %s, "isa": "%s", "load_before": "%s", "load_after": "%s", "pinned": %s}\n' \
  "$SCENE" "$LOOP" "$VARIANTS" "$REPS" "$AO" "$SIZES" "${FRAMES[*]}" "$WORKERS" "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)" "$cores" "$isa" \
  "$load_before" "$(cut -d' ' -f1-3 /proc/loadavg)" "$([[ ${PIN:-1} != 0 ]] && command -v taskset > /dev/null && echo true || echo false)" > "$OUT/summary.json"
