#!/usr/bin/env bash
# Loading a big glTF scene, before and after (issue 20: "a San Miguel-sized glTF loads on the
# node at least 3x faster than today, measured in the same run"). Runs `tessera render` of a
# 64x36 image (the load, the renderer's sync with its BVH builds and texel conversion, then a
# frame that takes milliseconds) with the old binary and the new one at each BVH quality
# (--bvh-quality medium, the default, and high, the old binary's) in turns, RUNS times each,
# and prints one JSON line per run (wall seconds, peak memory), then a summary with the
# medians, the old one's over each new one's, and the new binary's own breakdown at each
# quality (`tessera bench`'s "load").
#
# Usage: bench/load_before_after.sh [OLD] [SCENE_DIR] [RUNS] [THREADS]
#   OLD       a tessera binary, or a commit to build one from (default a1eaed9: the tree
#             before the faster-loading work of issue 20, built in /tmp/tessera-load-base)
#   SCENE_DIR a folder with scene.gltf and camera-loop.json (default: a San Miguel-sized
#             scene written by `tessera make-scene` into /tmp/tessera-sanmiguel-size)
#   RUNS      runs of each binary (default 3); THREADS render threads (default 2)
# The new binary is build/app/tessera (build it first). Measure on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=${1:-a1eaed9}
SCENE=${2:-/tmp/tessera-sanmiguel-size}
RUNS=${3:-3}
THREADS=${4:-2}
NEW=build/app/tessera
[ -x "$NEW" ] || { echo "build $NEW first (scripts/build.sh)" >&2; exit 2; }

if [ ! -x "$OLD" ]; then
  base=/tmp/tessera-load-base
  if [ ! -x "$base/build/app/tessera" ]; then
    echo "building tessera at $OLD in $base (minutes)" >&2
    rm -rf "$base"
    git worktree add -f "$base/src" "$OLD" >&2
    cmake -S "$base/src" -B "$base/build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTESSERA_BUILD_TESTS=OFF >&2
    ninja -C "$base/build" tessera >&2
  fi
  OLD_NAME="$OLD"
  OLD="$base/build/app/tessera"
else
  OLD_NAME="$OLD"
fi

if [ ! -f "$SCENE/scene.gltf" ]; then
  echo "writing a San Miguel-sized scene into $SCENE" >&2
  "$NEW" make-scene --out "$SCENE" >&2
fi

out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
one() {  # $1 = label, $2 = binary, then its further options
  local label=$1 bin=$2
  shift 2
  /usr/bin/time -f "%e %M" -o "$out/time" "$bin" render --scene "$SCENE/scene.gltf" --size 64 36 --threads "$THREADS" \
    --out "$out/frame.png" "$@" > /dev/null 2> "$out/err" || { cat "$out/err" >&2; exit 1; }
  read -r wall rss < "$out/time"
  printf '{"binary": "%s", "wall_s": %s, "peak_rss_mb": %d}\n' "$label" "$wall" $((rss / 1024))
  echo "$label $wall" >> "$out/walls"
}
for ((r = 0; r < RUNS; r++)); do
  one "old ($OLD_NAME)" "$OLD"
  one "new-medium" "$NEW" --bvh-quality medium
  one "new-high" "$NEW" --bvh-quality high
done
median() { grep "^$1 " "$out/walls" | awk '{print $NF}' | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
old_m=$(median old); med_m=$(median new-medium); high_m=$(median new-high)
breakdown() {
  "$NEW" bench --scene "$SCENE/scene.gltf" --camera-loop "$SCENE/camera-loop.json" --frames 1 --threads "$THREADS" \
    --size 64 36 --bvh-quality "$1" 2>/dev/null | grep -o '"load": {[^}]*}' | sed "s/\"load\"/\"load_$1\"/" || echo "\"load_$1\": null"
}
ratio() { awk -v a="$1" -v b="$2" 'BEGIN {printf "%.2f", a / b}'; }
printf '{"summary": true, "bench": "load_before_after", "scene": "%s", "old": "%s", "runs": %d, "threads": %d, ' \
  "$SCENE" "$OLD_NAME" "$RUNS" "$THREADS"
printf '"old_median_s": %s, "new_medium_median_s": %s, "new_high_median_s": %s, "speedup_medium": %s, "speedup_high": %s, %s, %s, ' \
  "$old_m" "$med_m" "$high_m" "$(ratio "$old_m" "$med_m")" "$(ratio "$old_m" "$high_m")" "$(breakdown medium)" "$(breakdown high)"
printf '"cpu": "%s", "load_average": "%s"}\n' \
  "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')" "$(cut -d' ' -f1-3 /proc/loadavg)"
