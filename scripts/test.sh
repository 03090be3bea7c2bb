#!/usr/bin/env bash
# Command two: installs what is missing, builds (warnings are errors) and runs the whole suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh --browser
scripts/build.sh -DTESSERA_WERROR=ON
cd "${TESSERA_BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)" --timeout 900 "$@"
