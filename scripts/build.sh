#!/usr/bin/env bash
# Configures and builds Tessera in Release into build/ (or $TESSERA_BUILD_DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${TESSERA_BUILD_DIR:-build}
gen=(); command -v ninja >/dev/null && gen=(-G Ninja)
[[ -f "$dir/CMakeCache.txt" ]] && gen=()
launcher=(); command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)  # used when present
cmake -S . -B "$dir" "${gen[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
cmake --build "$dir" -j "${TESSERA_JOBS:-$(nproc)}"
