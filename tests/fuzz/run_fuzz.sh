#!/bin/sh
# Builds the protocol fuzzer with clang (libFuzzer + ASan + UBSan) and runs it.
#   tests/fuzz/run_fuzz.sh <build-dir> [seconds] [extra libFuzzer flags...]
# Exit 77 (CTest SKIP_RETURN_CODE) when clang or libFuzzer is not installed.
# The checked-in corpus (tests/fuzz/corpus) is read, never written: new inputs go to
# <build-dir>/corpus, crashes to <build-dir>/crash-*.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
out=${1:?usage: run_fuzz.sh <build-dir> [seconds] [libFuzzer flags]}
secs=${2:-25}
[ $# -ge 2 ] && shift 2 || shift $#
CXX=${FUZZ_CXX:-clang++}
if ! command -v "$CXX" >/dev/null 2>&1; then
  echo "SKIP: $CXX not found (apt-get install -y clang libclang-rt-14-dev)"
  exit 77
fi
if ! echo 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }' |
     "$CXX" -x c++ -fsanitize=fuzzer - -o /dev/null 2>/dev/null; then
  echo "SKIP: $CXX cannot link libFuzzer (apt-get install -y libclang-rt-14-dev)"
  exit 77
fi
mkdir -p "$out/obj" "$out/corpus"
flags="-std=c++17 -O1 -g -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -I$root -I/usr/include/stb"
objs=""
for src in net/protocol.cpp codecs/jpeg.cpp codecs/dxt1.cpp codecs/deflate.cpp renderer/scene.cpp renderer/math.cpp \
           renderer/image.cpp tests/fuzz/fuzz_protocol.cpp; do
  obj="$out/obj/$(echo "$src" | tr / _).o"
  # Rebuild when the source or any header of ours is newer than the object.
  if [ ! -f "$obj" ] || [ -n "$(find "$root/$src" "$root/net" "$root/codecs" "$root/renderer" -name '*.h' -newer "$obj" -o -path "$root/$src" -newer "$obj" | head -1)" ]; then
    echo "compiling $src"
    $CXX $flags -c "$root/$src" -o "$obj"
  fi
  objs="$objs $obj"
done
$CXX -fsanitize=fuzzer,address,undefined $objs -o "$out/fuzz_protocol" -lturbojpeg -lsquish -lz -ltbb -lpthread
echo "running fuzz_protocol for ${secs}s"
exec "$out/fuzz_protocol" "$out/corpus" "$root/tests/fuzz/corpus" -max_total_time="$secs" -rss_limit_mb=2048 \
  -max_len=65536 -timeout=10 -print_final_stats=1 -artifact_prefix="$out/" "$@"
