#!/usr/bin/env bash
# The gateway's two targets, measured on this machine: 4 daemon + plant pairs (namespaces
# gwb-1 … gwb-4), two gateways on the loopback standing in for two hosts (host-a serves 1 and 2,
# host-b serves 3 and 4 and connects to host-a), then `chaosd-gateway bench` through host-b:
# remote status round trip (to gwb-1 on host-a, so across both gateways) and every telemetry
# sample of all 4 controllers (20 Hz each) for SECONDS.
#
#   cargo build --release --workspace --bins && scripts/gateway-bench.sh [SECONDS] [REQUESTS]
#
# Loops use sleeping waits (not spins) so 4 pairs fit on 2 cores. Everything started here is
# stopped on exit.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_TO_COUNT=${1:-60}
REQUESTS=${2:-2000}
BIN=target/release
OUT=out/gateway-bench
mkdir -p "$OUT"
PIDS=()
cleanup() {
    for p in "${PIDS[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    wait 2>/dev/null || true
}
trap cleanup EXIT

for i in 1 2 3 4; do
    ns=gwb-$i
    cfg=$OUT/$ns.toml
    cat >"$cfg" <<TOML
[daemon]
namespace = "$ns"
output_dir = "$OUT/$ns"
wait = "sleep"
lock_memory = false
[plant]
namespace = "$ns"
output_dir = "$OUT/$ns"
wait = "sleep"
lock_memory = false
TOML
    "$BIN/chaosd-plant" --config "$cfg" >"$OUT/$ns-plant.log" 2>&1 & PIDS+=($!)
    "$BIN/chaosd" run --fresh --config "$cfg" >"$OUT/$ns-daemon.log" 2>&1 & PIDS+=($!)
done
A=tcp/127.0.0.1:17447
B=tcp/127.0.0.1:17448
"$BIN/chaosd-gateway" serve --host host-a --namespace gwb-1 --namespace gwb-2 --listen "$A" \
    >"$OUT/gateway-a.log" 2>&1 & PIDS+=($!)
"$BIN/chaosd-gateway" serve --host host-b --namespace gwb-3 --namespace gwb-4 --listen "$B" \
    --connect "$A" >"$OUT/gateway-b.log" 2>&1 & PIDS+=($!)

for _ in $(seq 1 60); do
    if "$BIN/chaosd-gateway" fleet --remote "$B" 2>/dev/null | grep -q "4 controller(s)"; then break; fi
    sleep 0.5
done
"$BIN/chaosd-gateway" fleet --remote "$B"
echo "== chaosd-gateway bench ($(date -u +%FT%TZ), $(nproc) cores) =="
"$BIN/chaosd-gateway" bench --remote "$B" --namespace gwb-1 --requests "$REQUESTS" \
    --seconds "$SECONDS_TO_COUNT" | tee "$OUT/bench.txt"
