#!/usr/bin/env bash
# Every display over emulated real links (issue 19): a node (`tessera serve`) in one network
# namespace and its clients (`tessera loadtest`) in another, joined by a veth pair whose two ends
# are shaped with tc: bandwidth (5, 20, 100 Mbit/s) and, where the kernel has sch_netem, one-way
# delay (half the round-trip time: 10, 50, 100 ms) and loss (0, 1%). For each link and display
# (jpeg, s3tc, mjpeg, h264) it prints one JSON line: frames/s delivered, bytes per frame, encode
# and pipeline ms, and input-to-frame latency (loadtest's latency_ms: camera and render request
# sent to frame received, two requests outstanding).
#
# Without netem (this project's 2-core VM: "Specified qdisc kind is unknown") only the bandwidth
# is shaped, with tbf, and the delay and loss rows are skipped with a line saying so. MJPEG's
# frames travel on HTTP, which nobody reads here: its row measures the WebSocket's Frame records.
#
# Needs root and iproute2's ip and tc; exits 77 (skipped) without them.
# Usage: bench/display_network.sh [TESSERA] [SECONDS]   (default build/app/tessera, 10 s a run)
#        SCENE=../shared/scenes/pavilion SIZE="1280 720" AO=0 DISPLAYS="jpeg h264" RATES="20" ...
set -uo pipefail
cd "$(dirname "$0")/.."
BIN=$(realpath "${1:-build/app/tessera}"); SECS=${2:-10}
S=${SCENE:-../shared/scenes/living-room}; SIZE=${SIZE:-1280 720}; AO=${AO:-0}
DISPLAYS=${DISPLAYS:-jpeg s3tc mjpeg h264}; RATES=${RATES:-5 20 100}; RTTS=${RTTS:-10 50 100}; LOSSES=${LOSSES:-0 1}
skip() { echo "SKIP: $*"; exit 77; }
[[ $(id -u) == 0 ]] || skip "needs root (network namespaces, tc)"
command -v ip > /dev/null && command -v tc > /dev/null || skip "needs iproute2's ip and tc"
[[ -x $BIN ]] || skip "no tessera binary at $BIN (build it first)"
ns_a=tdn$$a; ns_b=tdn$$b; node_pid=
cleanup() {
  [[ -n $node_pid ]] && kill "$node_pid" 2> /dev/null
  ip netns del "$ns_a" 2> /dev/null; ip netns del "$ns_b" 2> /dev/null
}
trap cleanup EXIT
ip netns add "$ns_a" && ip netns add "$ns_b" || skip "cannot make network namespaces"
va=tdn$$x; vb=tdn$$y
ip link add "$va" type veth peer name "$vb" || skip "cannot make a veth pair"
ip link set "$va" netns "$ns_a"; ip link set "$vb" netns "$ns_b"
ip -n "$ns_a" addr add 10.214.0.1/24 dev "$va"; ip -n "$ns_b" addr add 10.214.0.2/24 dev "$vb"
for n in "$ns_a" "$ns_b"; do ip -n "$n" link set lo up; done
ip -n "$ns_a" link set "$va" up; ip -n "$ns_b" link set "$vb" up
netem=1
ip netns exec "$ns_a" tc qdisc add dev "$va" root netem delay 1ms 2> /dev/null || netem=0
ip netns exec "$ns_a" tc qdisc del dev "$va" root 2> /dev/null

# shape RATE_MBIT RTT_MS LOSS_PERCENT: both directions (each end delays half the round trip).
shape() {
  local rate=$1 rtt=$2 loss=$3 dev
  for pair in "$ns_a $va" "$ns_b $vb"; do
    set -- $pair
    ip netns exec "$1" tc qdisc del dev "$2" root 2> /dev/null
    if (( netem )); then
      ip netns exec "$1" tc qdisc add dev "$2" root netem delay "$((rtt / 2))ms" loss "${loss}%" rate "${rate}mbit" limit 10000
    else
      # tbf: the bucket holds ~10 ms of the rate (at least 32 KB), and a packet waits at most 200 ms.
      local burst=$(( rate * 1250 > 32768 ? rate * 1250 : 32768 ))
      ip netns exec "$1" tc qdisc add dev "$2" root tbf rate "${rate}mbit" burst "$burst" latency 200ms
    fi
  done
}

port=28411
ip netns exec "$ns_a" "$BIN" serve --host 10.214.0.1 --port "$port" > /tmp/tdn$$.log 2>&1 &
node_pid=$!
for _ in $(seq 50); do ip netns exec "$ns_b" bash -c "exec 3<>/dev/tcp/10.214.0.1/$port" 2> /dev/null && break; sleep 0.2; done

isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"load_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"isa\": \"$isa\", \"cores\": $(nproc), \"netem\": $netem, \"scene\": \"$S\", \"size\": \"$SIZE\", \"ao\": $AO, \"seconds\": $SECS}"
(( netem )) || echo "{\"note\": \"no sch_netem in this kernel: bandwidth shaped with tbf, no delay or loss (RTT is the veth's, ~0.05 ms)\"}"
for rate in $RATES; do
  for rtt in $RTTS; do
    for loss in $LOSSES; do
      if (( ! netem )) && [[ $rtt != "${RTTS%% *}" || $loss != 0 ]]; then continue; fi
      shape "$rate" "$rtt" "$loss"
      for d in $DISPLAYS; do
        line=$(ip netns exec "$ns_b" "$BIN" loadtest --host 10.214.0.1 --port "$port" --scene "$S/scene.gltf" \
               --camera-loop "$S/camera-loop.json" --size $SIZE --ao "$AO" --display "$d" --seconds "$SECS" \
               --warmup 3 2> /dev/null | grep '"summary": true')
        python3 -c 'import json,sys
d = json.loads(sys.argv[5]) if sys.argv[5] else {}
print(json.dumps({"display": sys.argv[1], "mbit_s": float(sys.argv[2]), "rtt_ms": float(sys.argv[3]) if sys.argv[6] == "1" else None,
  "loss_percent": float(sys.argv[4]) if sys.argv[6] == "1" else None, "fps": d.get("fps_total"),
  "bytes_per_frame": d.get("node_bytes_per_frame"), "encode_ms": d.get("median_encode_ms"),
  "pipeline_ms": d.get("median_pipeline_ms"), "latency_ms": d.get("median_latency_ms"),
  "p90_latency_ms": d.get("p90_latency_ms"), "rendering_ms": d.get("median_rendering_ms"),
  "upload_ms": d.get("median_upload_ms"), "errors": d.get("errors", "no summary")}))' \
          "$d" "$rate" "$rtt" "$loss" "$line" "$netem"
      done
    done
  done
done
echo "{\"load_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
