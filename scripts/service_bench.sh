#!/usr/bin/env bash
# Service throughput on loopback (issue 5's performance figures): one `gearwear serve` on a
# fresh SQLite file, then `examples/loadgen` closed loop, 4 clients, 15 s per case, for two
# records × two body formats:
#   model — a 1 s, 25.6 kHz record of the model itself (`gearwear synth --ea 0.5`): the
#           diagnosis's usual path;
#   four  — loadgen's built-in four-sine record: a poor fit (χ²/feature ≈ 87), which makes the
#           diagnosis try every f1 candidate — its slowest path.
# One line per case: records/s, p50/p99 latency, server CPU per record, errors, RSS.
#
#   scripts/service_bench.sh [BINARY] [LABEL]      # default: target/release/gearwear, "this"
#
# For an A/B, build the other commit in a worktree and run this script with each binary in
# turn, twice, on an otherwise idle machine (the load generator shares the two cores).
set -euo pipefail
cd "$(dirname "$0")/.."
GW_BIN=${1:-target/release/gearwear}
B=$GW_BIN
label=${2:-this}
cargo build --release --quiet --bin gearwear --example loadgen
LG=target/release/examples/loadgen
. scripts/lib/serve.sh
gw_fresh_store sqlite bench
trap gw_cleanup EXIT
target/release/gearwear synth --ea 0.5 --output "$GW_DIR/model.wav" >/dev/null
key=$(gw_key ingest,read)
gw_serve "$GW_DIR/serve.log" --allow-stale-table
pid=$GW_PID port=$GW_PORT
d=$GW_DIR
echo "# $label: $B, $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)"
for rec in model four; do
  for fmt in json f32; do
    extra=()
    [ "$rec" = model ] && extra=(--record "$d/model.wav")
    "$LG" --url "http://127.0.0.1:$port" --key "$key" --concurrency 4 --seconds 15 \
      --format "$fmt" --pid "$pid" "${extra[@]}" 2>&1 | tail -1 | python3 -c "
import json, sys
s = json.load(sys.stdin)
print(f\"$label $rec {s['format']:4} {s['records_per_second']:6.1f} rec/s  p50 {s['p50_ms']:5.1f} ms  p99 {s['p99_ms']:5.1f} ms  \"
      f\"server CPU {s['server_cpu_ms_per_record']:5.2f} ms/record  errors {s['errors']}  \"
      f\"RSS end {s['rss_end_kb']/1024:.1f} MB (peak {s['rss_peak_kb']/1024:.1f})\")"
  done
done
