#!/usr/bin/env bash
# Service throughput on loopback: one `gearwear serve` on a
# fresh SQLite file, then `examples/loadgen` closed loop, 4 clients, 15 s per case, for two
# records × two body formats:
#   model — a 1 s, 25.6 kHz record of the model itself (`gearwear synth --ea 0.5`): the
#           diagnosis's usual path;
#   four  — loadgen's built-in four-sine record: a poor fit (χ²/feature ≈ 87), which makes the
#           diagnosis try every f1 candidate — its slowest path.
# One line per case: records/s, p50/p99 latency, server CPU per record (user and kernel), errors, RSS.
#
#   scripts/service_bench.sh [BINARY] [LABEL]      # default: target/release/gearwear, "this"
#
# Environment (defaults in brackets): BENCH_RECORDS [model four], BENCH_FORMATS [json f32],
# BENCH_SECONDS [15], BENCH_CONCURRENCY [4], BENCH_STORE [sqlite; or postgres: a fresh database on
# 127.0.0.1:5432, and the PostgreSQL processes' CPU per record is printed], BENCH_SERVE_ARGS [none; e.g.
# "--raw-retention-days 0"]. When `perf` can count hardware events, each case also prints the
# whole machine's user-space instructions and user/kernel cycles per record (server, load
# generator and anything else running): a load-independent figure for A/B comparisons on a
# machine whose clock and neighbours vary (`perf stat -a`).
#
# For an A/B, build the other commit in a worktree and run this script with each binary in
# turn, twice, on an otherwise idle machine (the load generator shares the two cores).
set -euo pipefail
cd "$(dirname "$0")/.."
GW_BIN=${1:-${CARGO_TARGET_DIR:-target}/release/gearwear}
B=$GW_BIN
label=${2:-this}
cargo build --release --quiet --bin gearwear --example loadgen
LG=${CARGO_TARGET_DIR:-target}/release/examples/loadgen
. scripts/lib/serve.sh
gw_fresh_store "${BENCH_STORE:-sqlite}" bench
trap gw_cleanup EXIT
"${CARGO_TARGET_DIR:-target}"/release/gearwear synth --ea 0.5 --output "$GW_DIR/model.wav" >/dev/null
key=$(gw_key ingest,read)
# shellcheck disable=SC2086
gw_serve "$GW_DIR/serve.log" --allow-stale-table ${BENCH_SERVE_ARGS:-}
pid=$GW_PID port=$GW_PORT
# CPU seconds of the PostgreSQL server's processes (0 for SQLite, which runs in the server).
db_cpu() {
  if [ "${BENCH_STORE:-sqlite}" = postgres ]; then
    # shellcheck disable=SC2046
    python3 scripts/lib/cluster_tool.py cpu $(pgrep -x postgres) |
      python3 -c 'import json,sys; print(sum(json.load(sys.stdin).values()))'
  else
    echo 0
  fi
}
d=$GW_DIR
echo "# $label: $B, $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg)"
secs=${BENCH_SECONDS:-15}
perf_ok=false
perf stat -a -x, -e instructions:u -o /dev/null -- true >/dev/null 2>&1 && perf_ok=true
for rec in ${BENCH_RECORDS:-model four}; do
  for fmt in ${BENCH_FORMATS:-json f32}; do
    extra=()
    [ "$rec" = model ] && extra=(--record "$d/model.wav")
    stat="$d/perf.stat"
    rm -f "$stat"
    perf_pid=""
    if $perf_ok; then
      perf stat -a -x, -e instructions:u,cycles:u,cycles:k -o "$stat" -- sleep "$((secs + 1))" &
      perf_pid=$!
    fi
    curl -fs "http://127.0.0.1:$port/metrics" >"$d/metrics.before" || true
    mach0=$(python3 scripts/lib/cluster_tool.py machine_cpu) db0=$(db_cpu)
    "$LG" --url "http://127.0.0.1:$port" --key "$key" --concurrency "${BENCH_CONCURRENCY:-4}" \
      --seconds "$secs" --format "$fmt" --pid "$pid" "${extra[@]}" 2>&1 | tail -1 >"$d/run.json"
    [ -n "$perf_pid" ] && wait "$perf_pid"
    curl -fs "http://127.0.0.1:$port/metrics" >"$d/metrics.after" || true
    mach1=$(python3 scripts/lib/cluster_tool.py machine_cpu) db1=$(db_cpu)
    MACH="$mach0 $mach1" DB="$db0 $db1" STAT="$stat" python3 -c "
import json, os
s = json.load(open('$d/run.json'))
line = (f\"$label $rec {s['format']:4} {s['records_per_second']:6.1f} rec/s  p50 {s['p50_ms']:5.1f} ms  p99 {s['p99_ms']:5.1f} ms  \"
        f\"server CPU {s['server_cpu_ms_per_record']:5.2f} ms/record \"
        f\"(user {s.get('server_user_ms_per_record', float('nan')):.2f}, kernel {s.get('server_kernel_ms_per_record', float('nan')):.2f})  errors {s['errors']}  \"
        f\"RSS end {s['rss_end_kb']/1024:.1f} MB (peak {s['rss_peak_kb']/1024:.1f})\")
if os.path.exists(os.environ['STAT']) and s['records']:
    ev = {}
    for l in open(os.environ['STAT']):
        p = l.split(',')
        if len(p) > 2 and p[0].replace('.', '').isdigit():
            ev[p[2]] = float(p[0]) / s['records'] / 1e6
    line += (f\"  per record: instructions {ev.get('instructions:u', float('nan')):.1f} M, cycles \"
             f\"user {ev.get('cycles:u', float('nan')):.1f} M kernel {ev.get('cycles:k', float('nan')):.1f} M\")
print(line)
# The record path's CPU by stage (thread CPU time, /metrics; absent in binaries before it).
def stages(p):
    out = {}
    try:
        for l in open(p):
            if l.startswith('gearwear_record_stage_cpu_seconds_total{'):
                out[l.split('\"')[1]] = float(l.split()[-1])
            if l.startswith('gearwear_records_accepted_total '):
                out['_records'] = float(l.split()[-1])
    except OSError:
        pass
    return out
a, b = stages('$d/metrics.before'), stages('$d/metrics.after')
n = b.get('_records', 0) - a.get('_records', 0)
if n > 0 and len(b) > 1:
    parts = [(k, (b[k] - a.get(k, 0.0)) / n * 1e3) for k in sorted(b) if k != '_records']
    tot = sum(v for _, v in parts)
    print('    stages, CPU ms/record: ' + ', '.join(f'{k} {v:.2f}' for k, v in parts)
          + f'; sum {tot:.2f} of {s[\"server_cpu_ms_per_record\"]:.2f} (the rest: HTTP, store threads, kernel)')
    dg = dict(parts).get('diagnosis')
    m = [float(x) for x in os.environ['MACH'].split()]
    db = [float(x) for x in os.environ['DB'].split()]
    if dg:
        print(f'    server CPU / diagnosis stage {s[\"server_cpu_ms_per_record\"] / dg:.2f}; '
              f'whole machine {(m[3] - m[0]) / s[\"records\"] * 1e3:.2f} ms/record of CPU'
              + (f', database server {(db[1] - db[0]) / s[\"records\"] * 1e3:.2f}' if db[1] > 0 else ''))"
  done
done
