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
B=${1:-target/release/gearwear}
label=${2:-this}
cargo build --release --quiet --bin gearwear --example loadgen
LG=target/release/examples/loadgen
d=$(mktemp -d /tmp/gearwear-bench.XXXXXX)
target/release/gearwear synth --ea 0.5 --output "$d/model.wav" >/dev/null
key=$("$B" keys create --scope ingest,read --database-url "$d/p.db" 2>/dev/null | tail -1)
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
"$B" serve --address "127.0.0.1:$port" --database-url "$d/p.db" --rate-per-second 100000 \
  --rate-burst 100000 --allow-stale-table >"$d/serve.log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$d"' EXIT
for _ in $(seq 100); do curl -fs "http://127.0.0.1:$port/readyz" >/dev/null 2>&1 && break; sleep 0.1; done
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
