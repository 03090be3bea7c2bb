#!/usr/bin/env bash
# Command one: installs what is missing, builds in Release and starts a Tessera node that serves
# the demo pages and ray-traces the pavilion for every browser that connects.
#   open http://127.0.0.1:${PORT:-8080}/demo/pavilion.html?server=127.0.0.1:${PORT:-8080}
# (without ?server= the same page renders locally with WebGL; the page has a switch).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh --web
scripts/build.sh
PORT=${PORT:-8080}
T=${TESSERA_BUILD_DIR:-build}/app/tessera
echo "Tessera node: open http://127.0.0.1:$PORT/demo/pavilion.html?server=127.0.0.1:$PORT"
echo "(living room and kitchen: /demo/living-room.html, /demo/kitchen.html; Ctrl-C stops the node)"
exec "$T" serve --port "$PORT" --scene ../shared/scenes/pavilion/scene.gltf
