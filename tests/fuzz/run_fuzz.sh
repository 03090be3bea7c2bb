#!/bin/sh
# Runs one libFuzzer target (built by a TESSERA_FUZZ build, e.g. build-asan/tests/fuzz_<name>)
# for a bounded time, starting from its checked-in seed corpus:
#   tests/fuzz/run_fuzz.sh <fuzzer> <seed-corpus-dir> <work-dir> [seconds] [extra libFuzzer flags...]
# The seed corpus is read, never written: new inputs go to <work-dir>/corpus, crashes to
# <work-dir>/crash-* (re-run one with `<fuzzer> <work-dir>/crash-...`). Exit status: 0 when
# nothing was found, else libFuzzer's (non-zero on a crash, a leak, a timeout or an OOM).
set -eu
fuzzer=${1:?usage: run_fuzz.sh <fuzzer> <seed-corpus-dir> <work-dir> [seconds] [libFuzzer flags]}
seeds=${2:?seed corpus directory}
work=${3:?work directory}
secs=${4:-20}
shift 3
[ $# -ge 1 ] && shift
mkdir -p "$work/corpus"
echo "fuzzing $(basename "$fuzzer") for ${secs}s from $seeds"
exec "$fuzzer" "$work/corpus" "$seeds" -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 \
  -print_final_stats=1 -artifact_prefix="$work/" "$@"
