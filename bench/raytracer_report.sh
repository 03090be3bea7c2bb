#!/usr/bin/env bash
# Regenerates the ray tracer's throughput figures (docs/results/raytracer.jsonl): per shared
# scene at 1280x720, 1 and 2 threads: marginal Mrays/s per ray kind (breakdown), ours vs the
# bare Embree kernel (bare), the cost map's overhead (costmap) and general vs compiled-out
# kernel on the plain scene (specialised). Usage: bench/raytracer_report.sh [frames]
set -euo pipefail
cd "$(dirname "$0")/.."
F=${1:-3}
T=build/app/tessera
S=../shared/scenes
out=docs/results/raytracer.jsonl
: > "$out"
for sc in pavilion living-room kitchen; do
  ao=8; [[ $sc == pavilion ]] && ao=16
  for th in 1 2; do
    common=(--scene $S/$sc/scene.gltf --camera-loop $S/$sc/camera-loop.json --size 1280 720 --frames "$F" --step 80 --threads $th)
    $T bench "${common[@]}" --ao $ao --compare breakdown | tail -1 >> "$out"
    $T bench "${common[@]}" --depth 1 --shadows 0 --compare bare | tail -1 >> "$out"
  done
  $T bench --scene $S/$sc/scene.gltf --camera-loop $S/$sc/camera-loop.json --size 1280 720 --frames "$F" --step 80 --ao 4 --compare costmap | tail -1 >> "$out"
  $T bench --scene $S/$sc/scene.gltf --camera-loop $S/$sc/camera-loop.json --size 1280 720 --frames $((F*2)) --step 40 --plain --compare specialised | tail -1 >> "$out"
done
echo "wrote $out"
