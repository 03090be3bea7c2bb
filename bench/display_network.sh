#!/usr/bin/env bash
# Every display over emulated real links (issue 19): a node (`tessera serve`) in one network
# namespace and its clients (`tessera loadtest`) in another. For each link (bandwidth 5, 20 and
# 100 Mbit/s; round-trip time 10, 50 and 100 ms; loss 0 and 1%, in each direction) and display
# (jpeg, s3tc, mjpeg, h264) it prints one JSON line:
# - frames/s delivered, bytes per frame, encode and pipeline ms, with two render requests
#   outstanding (the node renders a frame while the one before is encoded and sent), and that
#   run's latency, which includes the wait behind the frame before;
# - input-to-frame latency with one request outstanding (the same session's next
#   LATENCY_SECONDS, loadtest --latency-seconds: camera and render request sent to frame
#   received, nothing queued ahead), and its bound, the issue's RTT + rendering + 30 ms, with
#   that phase's median rendering time.
# REQUEST_HZ=R: instead, each client asks for a frame every 1/R s whatever arrives (loadtest
# --request-hz, as the web client does during a drag), and latency_2_ms is from a frame's own
# request to the frame, with the requests the node merged into newer frames (node_dropped).
# Each run uploads the scene on an open link, and the link is shaped once the first frame has
# arrived (loadtest --on-streaming; the warm-up frames then cross the shaped link): uploading a
# 26 MB scene would take 40 s at 5 Mbit/s, and minutes at 1% loss and 100 ms.
#
# The link (LINK=auto, the default, takes the first that works here):
# - netem: a veth pair, both ends shaped with `tc qdisc ... netem delay RTT/2 loss P rate R`;
# - linkem: `tessera linkem` (app/cmd_linkem.cpp), a TUN device in each namespace and the same
#   model in user space, for kernels without sch_netem (this project's VMs);
# - tbf: a veth pair shaped with tbf, bandwidth only (the RTT and loss rows are skipped).
# MJPEG's pictures travel on the session's HTTP stream, which loadtest reads as a browser's <img>
# would: its row counts the parts that arrived and times each from the request of the frame it
# shows (the part's X-Tessera-Frame header), while the WebSocket carries the requests and each
# frame's record.
#
# Needs root and iproute2's ip (and tc, or /dev/net/tun); exits 77 (skipped) without them.
# Usage: bench/display_network.sh [TESSERA] [SECONDS]   (default build/app/tessera, 10 s a run)
#        SCENE=../shared/scenes/pavilion SIZE="1280 720" AO=0 DISPLAYS="jpeg h264" RATES="20"
#        RTTS="50" LOSSES="0 1" LINK=linkem LATENCY_SECONDS=5 ...
set -uo pipefail
cd "$(dirname "$0")/.."
BIN=$(realpath "${1:-build/app/tessera}"); SECS=${2:-10}; LSECS=${LATENCY_SECONDS:-$SECS}
S=${SCENE:-../shared/scenes/living-room}; SIZE=${SIZE:-1280 720}; AO=${AO:-0}
DISPLAYS=${DISPLAYS:-jpeg s3tc mjpeg h264}; RATES=${RATES:-5 20 100}; RTTS=${RTTS:-10 50 100}; LOSSES=${LOSSES:-0 1}
LINK=${LINK:-auto}; REQUEST_HZ=${REQUEST_HZ:-0}
skip() { echo "SKIP: $*"; exit 77; }
[[ $(id -u) == 0 ]] || skip "needs root (network namespaces, tc or TUN devices)"
command -v ip > /dev/null || skip "needs iproute2's ip"
[[ -x $BIN ]] || skip "no tessera binary at $BIN (build it first)"
ns_a=tdn$$a; ns_b=tdn$$b; node_pid=; link_pid=
cleanup() {
  [[ -n $node_pid ]] && kill "$node_pid" 2> /dev/null
  [[ -n $link_pid ]] && kill "$link_pid" 2> /dev/null && wait "$link_pid" 2> /dev/null
  ip netns del "$ns_a" 2> /dev/null; ip netns del "$ns_b" 2> /dev/null
  rm -f /tmp/tdn$$.linkem /tmp/tdn$$.shape.sh /tmp/tdn$$.log
}
trap cleanup EXIT
ip netns add "$ns_a" && ip netns add "$ns_b" || skip "cannot make network namespaces"
for n in "$ns_a" "$ns_b"; do ip -n "$n" link set lo up; done
addr_a=10.214.0.1; addr_b=10.214.0.2

# Which link: probe netem on a veth pair, then linkem.
va=tdn$$x; vb=tdn$$y
make_veth() {
  ip link add "$va" type veth peer name "$vb" || return 1
  ip link set "$va" netns "$ns_a"; ip link set "$vb" netns "$ns_b"
  ip -n "$ns_a" addr add $addr_a/24 dev "$va"; ip -n "$ns_b" addr add $addr_b/24 dev "$vb"
  ip -n "$ns_a" link set "$va" up; ip -n "$ns_b" link set "$vb" up
}
if [[ $LINK == auto || $LINK == netem ]]; then
  if command -v tc > /dev/null && make_veth && ip netns exec "$ns_a" tc qdisc add dev "$va" root netem delay 1ms 2> /dev/null; then
    ip netns exec "$ns_a" tc qdisc del dev "$va" root 2> /dev/null; LINK=netem
  elif [[ $LINK == netem ]]; then skip "no sch_netem in this kernel (LINK=linkem emulates the link in user space)"
  else ip -n "$ns_a" link del "$va" 2> /dev/null; LINK=auto; fi
fi
if [[ $LINK == auto || $LINK == linkem ]]; then
  if [[ -c /dev/net/tun ]]; then LINK=linkem
  elif [[ $LINK == linkem ]]; then skip "no /dev/net/tun for tessera linkem"
  else LINK=tbf; fi
fi
if [[ $LINK == tbf ]]; then
  command -v tc > /dev/null || skip "needs tc for a tbf link"
  ip -n "$ns_a" link show "$va" > /dev/null 2>&1 || make_veth || skip "cannot make a veth pair"
fi

# open RATE_MBIT RTT_MS LOSS_PERCENT: an open link now, and in $shape_cmd the command that
# shapes it (both directions alike).
shape_cmd=
open_link() {
  local rate=$1 rtt=$2 loss=$3
  if [[ $LINK == linkem ]]; then
    if [[ -n $link_pid ]]; then kill "$link_pid"; wait "$link_pid" 2> /dev/null; fi
    local out=/tmp/tdn$$.linkem
    "$BIN" linkem --ns "$ns_a" "$ns_b" --addr $addr_a $addr_b --mbit "$rate" --rtt-ms "$rtt" \
      --loss-percent "$loss" --seed "$((rate * 1000 + rtt * 10 + loss))" --open-until-signal > "$out" 2>&1 &
    link_pid=$!
    for _ in $(seq 100); do grep -q '"ready"' "$out" 2> /dev/null && break; sleep 0.05; done
    grep -q '"ready"' "$out" || { echo "{\"error\": \"tessera linkem did not start: $(head -c 300 "$out")\"}"; exit 1; }
    shape_cmd="kill -USR1 $link_pid"
    return
  fi
  local script=/tmp/tdn$$.shape.sh
  : > "$script"
  for pair in "$ns_a $va" "$ns_b $vb"; do
    set -- $pair
    ip netns exec "$1" tc qdisc del dev "$2" root 2> /dev/null
    if [[ $LINK == netem ]]; then
      echo "ip netns exec $1 tc qdisc add dev $2 root netem delay $((rtt / 2))ms loss ${loss}% rate ${rate}mbit limit 10000" >> "$script"
    else
      # tbf: the bucket holds ~10 ms of the rate (at least 32 KB), and a packet waits at most 200 ms.
      local burst=$(( rate * 1250 > 32768 ? rate * 1250 : 32768 ))
      echo "ip netns exec $1 tc qdisc add dev $2 root tbf rate ${rate}mbit burst $burst latency 200ms" >> "$script"
    fi
  done
  shape_cmd="bash -e $script"
}

port=28411
# 0.0.0.0: linkem's devices (and their addresses) come and go with each link.
ip netns exec "$ns_a" "$BIN" serve --host 0.0.0.0 --port "$port" > /tmp/tdn$$.log 2>&1 &
node_pid=$!
open_link "${RATES%% *}" "${RTTS%% *}" 0
for _ in $(seq 50); do ip netns exec "$ns_b" bash -c "exec 3<>/dev/tcp/$addr_a/$port" 2> /dev/null && break; sleep 0.2; done

isa=AVX2; grep -qw avx512f /proc/cpuinfo && isa=AVX-512
echo "{\"load_start\": \"$(cut -d' ' -f1-3 /proc/loadavg)\", \"isa\": \"$isa\", \"cores\": $(nproc), \"link\": \"$LINK\", \"scene\": \"$S\", \"size\": \"$SIZE\", \"ao\": $AO, \"seconds\": $SECS, \"latency_seconds\": $LSECS, \"request_hz\": $REQUEST_HZ}"
[[ $LINK == tbf ]] && echo "{\"note\": \"no sch_netem and no /dev/net/tun: bandwidth shaped with tbf, no delay or loss (RTT is the veth's, ~0.05 ms)\"}"
pacing="--latency-seconds $LSECS"; [[ $REQUEST_HZ != 0 ]] && pacing="--request-hz $REQUEST_HZ"
loadtest() {  # DISPLAY: loadtest's summary line
  ip netns exec "$ns_b" "$BIN" loadtest --host $addr_a --port "$port" --scene "$S/scene.gltf" \
    --camera-loop "$S/camera-loop.json" --size $SIZE --ao "$AO" --display "$1" --seconds "$SECS" \
    --warmup 3 $pacing --on-streaming "$shape_cmd" 2> /dev/null | grep '"summary": true'
}
for rate in $RATES; do
  for rtt in $RTTS; do
    for loss in $LOSSES; do
      if [[ $LINK == tbf ]] && [[ $rtt != "${RTTS%% *}" || $loss != 0 ]]; then continue; fi
      for d in $DISPLAYS; do
        open_link "$rate" "$rtt" "$loss"
        line=$(loadtest "$d")
        python3 -c 'import json,sys
d = json.loads(sys.argv[5]) if sys.argv[5] else {}
o = d.get("one_outstanding") or {}
m = d.get("mjpeg_stream")
if m:  # what the stream showed, not the WebSocket records
    d.update({"fps_total": m["fps"], "median_latency_ms": m["median_latency_ms"], "p90_latency_ms": m["p90_latency_ms"]})
    o = dict(o, median_latency_ms=m["one_outstanding_median_latency_ms"], p90_latency_ms=m["one_outstanding_p90_latency_ms"])
shaped = sys.argv[6] != "tbf"
rtt = float(sys.argv[3]) if shaped else None
bound = (rtt or 0) + o["median_rendering_ms"] + 30 if o.get("frames") else None
print(json.dumps({"display": sys.argv[1], "mbit_s": float(sys.argv[2]), "rtt_ms": rtt,
  "loss_percent": float(sys.argv[4]) if shaped else None, "link": sys.argv[6], "fps": d.get("fps_total"),
  "bytes_per_frame": d.get("node_bytes_per_frame"), "encode_ms": d.get("median_encode_ms"),
  "pipeline_ms": d.get("median_pipeline_ms"), "rendering_ms": d.get("median_rendering_ms"),
  "latency_2_ms": d.get("median_latency_ms"), "p90_latency_2_ms": d.get("p90_latency_ms"),
  "latency_ms": o.get("median_latency_ms"), "p90_latency_ms": o.get("p90_latency_ms"),
  "latency_rendering_ms": o.get("median_rendering_ms"), "latency_bound_ms": bound,
  "within_bound": (o["median_latency_ms"] <= bound) if o.get("frames") else None,
  "latency_frames": o.get("frames"), "node_frames": d.get("node_frames"), "node_dropped": d.get("node_dropped"),
  "errors": d.get("errors", "no summary")}))' \
          "$d" "$rate" "$rtt" "$loss" "$line" "$LINK"
      done
    done
  done
done
echo "{\"load_end\": \"$(cut -d' ' -f1-3 /proc/loadavg)\"}"
