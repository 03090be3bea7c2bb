#!/usr/bin/env bash
# Installs what Tessera needs on a Debian 12 machine, and nothing that is already there.
# Usage: scripts/install-deps.sh [--web|--browser]
#   --web      adds Node.js/npm and the web client's npm packages (three.js), for serving demo pages
#   --browser  --web plus Debian's chromium, for the browser tests
set -euo pipefail
cd "$(dirname "$0")/.."

pkgs=(build-essential cmake ninja-build pkg-config
      libcaf-dev libembree-dev libtbb-dev libturbojpeg0-dev libjpeg62-turbo-dev
      libsquish-dev libwebsocketpp-dev libasio-dev zlib1g-dev catch2
      libssl-dev  # libcrypto: HMAC-SHA256 of the access tokens (net/admission.h); libssl: HTTPS/WSS (net/tls.h), cluster TLS
      openssl     # the CLI: scripts/tls-cert.sh and scripts/cluster-certs.sh (certificates for tests and the demo)
      libopenh264-dev  # the H.264 video display (codecs/h264.h; BSD-2-Clause)
      libtinygltf-dev nlohmann-json3-dev libstb-dev clang libclang-rt-14-dev
      libegl-dev libgles-dev libegl-mesa0  # the rasterizer: EGL + GLES 3 headers, Mesa's EGL (llvmpipe)
      python3)  # tests/check_layers.py (CTest), bench report scripts
mode=${1:-}
if [[ "$mode" == "--browser" ]]; then pkgs+=(chromium nodejs npm); fi
if [[ "$mode" == "--web" ]]; then pkgs+=(nodejs npm); fi

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# nodejs/npm may come from outside Debian's packages on some images: accept any working node.
if command -v node >/dev/null && command -v npm >/dev/null; then
  missing=("${missing[@]/nodejs}"); missing=("${missing[@]/npm}")
fi
read -r -a missing <<< "${missing[*]:-}"
if (( ${#missing[@]} )); then
  echo "installing: ${missing[*]}"
  SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi

if [[ ( "$mode" == "--browser" || "$mode" == "--web" ) && -f web/package.json ]]; then
  (cd web && { [[ -d node_modules ]] || npm ci --no-audit --no-fund || npm install --no-audit --no-fund; })
fi
