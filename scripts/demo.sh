#!/usr/bin/env bash
# Command one: installs what is missing, builds in Release and starts a Tessera node that serves
# the demo pages and ray-traces the pavilion for every browser that connects.
#   open http://127.0.0.1:${PORT:-8080}/demo/pavilion.html?server=127.0.0.1:${PORT:-8080}
# (without ?server= the same page renders locally with WebGL; the page has a switch).
# TLS_DIR=DIR scripts/demo.sh serves it over https:// and wss:// with a self-signed certificate.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh --web
scripts/build.sh
PORT=${PORT:-8080}
T=${TESSERA_BUILD_DIR:-build}/app/tessera
# TLS_DIR=DIR: HTTPS and WSS with a self-signed certificate made once in DIR (scripts/tls-cert.sh).
scheme=http tls=()
if [[ -n ${TLS_DIR:-} ]]; then
  [[ -e $TLS_DIR/node.crt ]] || scripts/tls-cert.sh "$TLS_DIR" > /dev/null
  scheme=https tls=(--tessera.tls-cert="$TLS_DIR/node.crt" --tessera.tls-key="$TLS_DIR/node.key")
fi
echo "Tessera node: open $scheme://127.0.0.1:$PORT/demo/pavilion.html?server=127.0.0.1:$PORT"
echo "(living room and kitchen: /demo/living-room.html, /demo/kitchen.html; Ctrl-C stops the node)"
exec "$T" serve --port "$PORT" --scene ../shared/scenes/pavilion/scene.gltf "${tls[@]}"
