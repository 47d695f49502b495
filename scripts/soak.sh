#!/usr/bin/env bash
# Load and soak run of `gearwear serve`.
#
#   scripts/soak.sh [--store sqlite|postgres] [--seconds 600] [--fraction 0.8] [--rate R]
#                   [--capacity-seconds 20] [--format json|f32]
#
# 1. starts the release binary on a fresh database (a temp SQLite file, or a fresh database on
#    the PostgreSQL at 127.0.0.1:5432) with one ingest+read key;
# 2. measures capacity: closed loop, 4 clients, --capacity-seconds (skipped with --rate);
# 3. soaks: open loop at --fraction of that capacity (or --rate) for --seconds, one report line
#    a minute (records, errors, p50/p99, server RSS);
# 4. exits non-zero if any request failed (`late` counts records that found all 16 slots busy).
# The last line of each loadgen run is a JSON summary. Needs `cargo build --release` and
# `cargo build --release --example loadgen` (done here).
set -euo pipefail
cd "$(dirname "$0")/.."

store=sqlite seconds=600 fraction=0.8 rate="" capsecs=20 format=json
while [ $# -gt 0 ]; do
  case "$1" in
    --store) store=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    --fraction) fraction=$2; shift 2 ;;
    --rate) rate=$2; shift 2 ;;
    --capacity-seconds) capsecs=$2; shift 2 ;;
    --format) format=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done

cargo build --release --quiet --bin gearwear --example loadgen
LG=${CARGO_TARGET_DIR:-target}/release/examples/loadgen
. scripts/lib/serve.sh
gw_fresh_store "$store" soak
trap gw_cleanup EXIT
key=$(gw_key ingest,read)
gw_serve "$GW_DIR/serve.log"
pid=$GW_PID port=$GW_PORT
echo "store $store, server pid $pid, port $port, $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)"

if [ -z "$rate" ]; then
  echo "== capacity (closed loop, 4 clients, ${capsecs} s)"
  cap=$($LG --url "http://127.0.0.1:$port" --key "$key" --concurrency 4 --seconds "$capsecs" \
    --format "$format" --pid "$pid" | tee -a /dev/stderr | tail -1 | python3 -c 'import json,sys; print(json.load(sys.stdin)["records_per_second"])')
  rate=$(python3 -c "print(round($cap * $fraction, 1))")
fi
echo "== soak (open loop, $rate records/s, ${seconds} s)"
out=$($LG --url "http://127.0.0.1:$port" --key "$key" --concurrency 16 --rate "$rate" \
  --seconds "$seconds" --report-every "$(python3 -c "print(min(60, max(5, $seconds // 10)))")" \
  --format "$format" --pid "$pid" | tee -a /dev/stderr | tail -1)
python3 - "$out" <<'EOF'
import json, sys
s = json.loads(sys.argv[1])
bad = s["errors"] > 0
print(f"summary: {s['records']} records, {s['errors']} errors, {s['late']} late, "
      f"p99 {s['p99_ms']:.1f} ms, RSS {s['rss_start_kb']/1024:.1f} -> {s['rss_end_kb']/1024:.1f} MB")
sys.exit(1 if bad else 0)
EOF
