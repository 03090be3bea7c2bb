#!/usr/bin/env bash
# Command one: installs what is missing, builds in Release and runs Tessera on a real scene.
# For now it renders the pavilion's camera loop (frame times as JSON lines) and writes one
# frame to out/pavilion.png.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh
S=../shared/scenes/pavilion
mkdir -p out
T=${TESSERA_BUILD_DIR:-build}/app/tessera
"$T" bench --scene $S/scene.gltf --camera-loop $S/camera-loop.json --size 1280 720 --ao 4 --frames ${FRAMES:-24} --step 10
"$T" render --scene $S/scene.gltf --camera-loop $S/camera-loop.json --frame 0 --size 1280 720 --ao 8 --out out/pavilion.png
echo "wrote out/pavilion.png"
