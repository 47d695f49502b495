#!/usr/bin/env bash
# Load and soak run of `gearwear serve` (issue 7, item 3).
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
B=target/release/gearwear
LG=target/release/examples/loadgen
dir=$(mktemp -d /tmp/gearwear-soak.XXXXXX)
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
case "$store" in
  sqlite) db="$dir/soak.db" ;;
  postgres)
    name="gw_soak_$(date +%s)_$$"
    psql -q -h 127.0.0.1 -U postgres -d test -c "CREATE DATABASE $name" >/dev/null
    db="postgres://postgres@127.0.0.1:5432/$name" ;;
  *) echo "--store is sqlite or postgres" >&2; exit 2 ;;
esac
key=$($B keys create --scope ingest,read --database-url "$db" 2>/dev/null | grep -o 'gw_[A-Za-z0-9_-]*' | head -1)
$B serve --address "127.0.0.1:$port" --database-url "$db" \
  --rate-per-second 100000 --rate-burst 100000 >"$dir/serve.log" 2>&1 &
pid=$!
cleanup() {
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  if [ "$store" = postgres ]; then
    psql -q -h 127.0.0.1 -U postgres -d test -c "DROP DATABASE IF EXISTS $name WITH (FORCE)" >/dev/null || true
  fi
  rm -rf "$dir"
}
trap cleanup EXIT
for _ in $(seq 100); do
  curl -fs "http://127.0.0.1:$port/readyz" >/dev/null 2>&1 && break
  sleep 0.2
done
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
