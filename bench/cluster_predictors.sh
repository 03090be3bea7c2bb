#!/usr/bin/env bash
# The balancer's predictors in a real multi-process cluster (issue 22): the same frames balanced
# from the previous frame's cost maps as they are (the paper) and from the previous frame's cost
# carried into the new camera (lb/reproject.h), one run after the other, on the scene's shared
# camera loop and on the fast loops of tests/data/camera-loops (a 90-degree turn in 2 s, a walk).
# Each loop is one bench/cluster_scaling.sh run (VARIANTS="previous reproject"); its table and
# per-frame jsonl are written beside it by bench/cluster_scaling_report.py.
#
#   bench/cluster_predictors.sh OUTDIR [SIZES="640x360 1280x720"] [FRAMES="24 12"] [WORKERS="1 8 15"]
#
# SCENE (default ../shared/scenes/pavilion), TESSERA, AO, PIN as for cluster_scaling.sh.
# SHARED_REPS (2) and FAST_REPS (1): runs of each predictor per loop (alternating).
# DEADLINE: seconds after which no further loop is started (default: none).
set -uo pipefail
OUT=$1
SIZES=${2:-"640x360 1280x720"}
FRAMES=${3:-"24 12"}
WORKERS=${4:-"1 8 15"}
SCENE=${SCENE:-../shared/scenes/pavilion}
name=$(basename "$SCENE")
start=$(date +%s)
mkdir -p "$OUT"
for loop in shared turn90 walk; do
  if [[ -n ${DEADLINE:-} ]] && (($(date +%s) - start > DEADLINE)); then
    echo "deadline: $loop not run" >&2
    continue
  fi
  case $loop in
    shared) file=$SCENE/camera-loop.json reps=${SHARED_REPS:-2} ;;
    *) file=tests/data/camera-loops/$name-$loop.json reps=${FAST_REPS:-1} ;;
  esac
  t0=$(date +%s)
  LOOP=$file VARIANTS="previous reproject" REPS=$reps bench/cluster_scaling.sh "$OUT/$loop" "$SIZES" "$FRAMES" "$WORKERS"
  python3 bench/cluster_scaling_report.py "$OUT/$loop" --jsonl "$OUT/$loop.jsonl" > "$OUT/$loop.md"
  echo "$loop: $(($(date +%s) - t0)) s" >&2
  cat "$OUT/$loop.md"
done
