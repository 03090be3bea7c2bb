#!/usr/bin/env bash
# The sync channel's apply() before and after the O(log n) per-record checks: compiles the
# applybench core (app/apply_bench.h) against renderer/scene.* and net/protocol.* of a base
# commit (default bc6a3c8, before the change) and of the working tree, with the same flags,
# and runs both in one go. Needs build/ (the codec and image libraries) built first.
# Usage: bench/apply_before_after.sh [BASE_COMMIT] [MESH_COUNTS]   (default bc6a3c8 5000,10000,20000)
# Written for the layout before the layer folders (renderer/scene.*, net/protocol.*): it
# reproduces docs/results/node.md's apply figures from a checkout of bedf1d3 or earlier, e.g.
#   git worktree add /tmp/pre-layers bedf1d3 && cd /tmp/pre-layers && cmake ... && bench/apply_before_after.sh
set -euo pipefail
cd "$(dirname "$0")/.."
BASE=${1:-bc6a3c8}; LIST=${2:-5000,10000,20000}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/main.cpp" <<'CPP'
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include "app/apply_bench.h"
int main(int argc, char** argv) {
  std::stringstream list(argv[2]);
  std::string n;
  while (std::getline(list, n, ',')) {
    auto f = tessera::bench::apply_meshes(std::stoul(n), std::stoul(argv[3]));
    std::printf("{\"version\": \"%s\", \"meshes\": %zu, \"shared_vertices\": %s, \"records\": %zu, \"apply_total_ms\": %.3f, "
                "\"first_1k_mesh_records_ms\": %.3f, \"last_1k_mesh_records_ms\": %.3f}\n",
                argv[1], f.meshes, argv[3], f.records, f.total_ms, f.first_ms_per_1k, f.last_ms_per_1k);
    std::fflush(stdout);
  }
}
CPP
libs="build/codecs/libtessera_codecs.a build/renderer/libtessera_scene.a -lturbojpeg -lsquish -lz -ltbb -lpng"
build_one() {  # $1 = name, $2 = source root holding renderer/scene.* and net/protocol.*
  g++ -std=c++17 -O2 -DNDEBUG -I"$2" -I. "$tmp/main.cpp" "$2/renderer/scene.cpp" "$2/net/protocol.cpp" $libs -o "$tmp/$1.bin"
}
mkdir -p "$tmp/before/renderer" "$tmp/before/net" "$tmp/after/renderer" "$tmp/after/net"
for f in renderer/scene.h renderer/scene.cpp net/protocol.h net/protocol.cpp; do
  git show "$BASE:$f" > "$tmp/before/$f"
  cp "$f" "$tmp/after/$f"
done
build_one before "$tmp/before"
build_one after "$tmp/after"
for shared in 0 3000; do
  nice "$tmp/before.bin" "before ($BASE)" "$LIST" $shared
  nice "$tmp/after.bin" "after" "$LIST" $shared
done
printf '{"summary": true, "bench": "apply_before_after", "base": "%s", "cpu": "%s", "threads": 1}\n' \
  "$BASE" "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
