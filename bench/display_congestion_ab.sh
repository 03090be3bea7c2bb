#!/usr/bin/env bash
# The node's TCP congestion control (tessera.tcp-congestion) against the latency a browser-like
# client sees on a slow link: for each name in ORDER, a node in one network namespace with that
# setting, `tessera loadtest --request-hz 30` in another, joined by `tessera linkem` (rate MBIT,
# round trip RTT, no loss; shaped once the scene is up). One JSON line per run. Needs root, `ip`
# and /dev/net/tun; exits 77 without them.
# Usage: ORDER="cubic bbr bbr cubic cubic bbr" bench/display_congestion_ab.sh [TESSERA]
#        SCENE=living-room SIZE="1280 720" D=jpeg MBIT=5 RTT=50
set -uo pipefail
cd "$(dirname "$0")/.."
BIN=$(realpath "${1:-build/app/tessera}"); S=../shared/scenes/${SCENE:-living-room}
ORDER=${ORDER:-cubic bbr bbr cubic cubic bbr}; D=${D:-jpeg}; MBIT=${MBIT:-5}; RTT=${RTT:-50}; SIZE=${SIZE:-1280 720}
[[ $(id -u) == 0 ]] || { echo "SKIP: needs root"; exit 77; }
command -v ip > /dev/null && [[ -c /dev/net/tun ]] || { echo "SKIP: needs ip and /dev/net/tun"; exit 77; }
a=tca$$; b=tcb$$; lk=; node=
cleanup() { [[ -n $node ]] && kill $node 2> /dev/null; [[ -n $lk ]] && kill $lk 2> /dev/null; ip netns del $a 2> /dev/null; ip netns del $b 2> /dev/null; }
trap cleanup EXIT
for cc in $ORDER; do
  ip netns add $a && ip netns add $b && ip -n $a link set lo up && ip -n $b link set lo up || exit 1
  "$BIN" linkem --ns $a $b --addr 10.217.0.1 10.217.0.2 --mbit "$MBIT" --rtt-ms "$RTT" --open-until-signal > /dev/null 2>&1 &
  lk=$!; sleep 0.3
  ip netns exec $a "$BIN" serve --host 0.0.0.0 --port 28555 --tessera.tcp-congestion=$cc > /dev/null 2>&1 &
  node=$!; sleep 1
  ip netns exec $b "$BIN" loadtest --host 10.217.0.1 --port 28555 --scene $S/scene.gltf --camera-loop $S/camera-loop.json \
      --size $SIZE --display "$D" --seconds 6 --warmup 3 --request-hz 30 --on-streaming "kill -USR1 $lk" 2> /dev/null |
    grep '"summary": true' | python3 -c "import json,sys; d=json.loads(sys.stdin.read()); print(json.dumps({'cc': '$cc', 'display': '$D', 'mbit_s': $MBIT, 'rtt_ms': $RTT, 'fps': d['fps_total'], 'median_bytes': d['median_bytes'], 'median_latency_ms': d['median_latency_ms'], 'p90_latency_ms': d['p90_latency_ms'], 'node_dropped': d['node_dropped'], 'rendering_ms': d['median_rendering_ms'], 'errors': d['errors']}))"
  kill $node $lk; wait $node $lk 2> /dev/null; node=; lk=
  ip netns del $a; ip netns del $b
done
