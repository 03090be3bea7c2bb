#!/usr/bin/env bash
# Regenerates docs/results/node-loadtest.jsonl: frames per second delivered to 1, 2 and 3
# simultaneous clients over a common window, and pipeline time per frame, for each display
# method (JPEG q85, S3TC/DXT1, MJPEG) at 1280x720 on the pavilion (AO off, depth 4).
# Usage: bench/node_loadtest.sh [SECONDS]   (default 20; each run adds upload and warm-up time)
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-20}
S=../shared/scenes/pavilion
out=docs/results/node-loadtest.jsonl
: > "$out"
for display in jpeg s3tc mjpeg; do
  for clients in 1 2 3; do
    nice build/app/tessera loadtest --scene $S/scene.gltf --camera-loop $S/camera-loop.json --size 1280 720 \
      --clients $clients --display $display --seconds "$SECS" --warmup 2 | grep '"summary": true' | tee -a "$out"
  done
done
# The table of docs/results/node.md.
python3 - "$out" <<'PY'
import json, sys
print("| display | clients | window s | frames in window | fps per client | fps total | rendering ms | encode ms | pipeline ms | bytes/frame |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for l in open(sys.argv[1]):
    r = json.loads(l)
    per = ", ".join(f"{x:.2f}" for x in r["fps_per_client"])
    print(f"| {r['display']} | {r['clients']} | {r['window_s']:.1f} | {r['frames_in_window']} | {per} | {r['fps_total']:.2f} | "
          f"{r['median_rendering_ms']:.0f} | {r['median_encode_ms']:.1f} | {r['median_pipeline_ms']:.1f} | {r['node_bytes_per_frame']:,.0f} |")
PY
