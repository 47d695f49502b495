#!/usr/bin/env bash
# How long a gearbox's table takes to cover where its machine runs: the PHM 2009 spur gearbox
# described WITHOUT its nominal_input_hz (configs/gearboxes/phm09-spur.toml less that line), a
# machine PUT on it with input_shaft_hz 40, polled until the gearbox's table is ready with no
# extension pending and covers 34–46 Hz (40 Hz ± 15 %). Prints the time from the machine's PUT
# and the table jobs the service logged.
#
#   scripts/table_time.sh [RUNS]      (default 1; builds the release binary first)
#
# Fresh SQLite database in a temporary directory, `gearwear serve` on a free loopback port, all
# removed afterwards. Needs curl and python3.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-1}
cargo build --release -q
bin=${CARGO_TARGET_DIR:-target}/release/gearwear
for run in $(seq "$runs"); do
  dir=$(mktemp -d)
  db=$dir/gearwear.db
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  url=http://127.0.0.1:$port
  key=$("$bin" keys create --scope admin,read --database-url "$db" 2>/dev/null)
  sed '/^nominal_input_hz/d' configs/gearboxes/phm09-spur.toml > "$dir/spur.toml"
  "$bin" serve --address "127.0.0.1:$port" --database-url "$db" > "$dir/serve.log" 2>&1 &
  serve=$!
  for _ in $(seq 100); do curl -fsS "$url/healthz" > /dev/null 2>&1 && break; sleep 0.1; done
  curl -fsS -o /dev/null -X PUT -H "Authorization: Bearer $key" \
    -H 'Content-Type: application/toml' --data-binary @"$dir/spur.toml" "$url/v1/gearboxes/spur"
  t0=$(date +%s.%N)
  curl -fsS -o /dev/null -X PUT -H "Authorization: Bearer $key" \
    -H 'Content-Type: application/json' -d '{"gearbox": "spur", "input_shaft_hz": 40}' \
    "$url/v1/machines/m40"
  while :; do
    g=$(curl -fsS -H "Authorization: Bearer $key" "$url/v1/gearboxes/spur")
    if python3 -c '
import json, sys
g = json.loads(sys.argv[1]); c = g.get("covers") or {}
sys.exit(0 if g["status"] == "ready" and g["extension"] is None
         and c.get("lo_hz", 1e9) <= 34.001 and c.get("hi_hz", 0) >= 45.999 else 1)' "$g"; then
      break
    fi
    sleep 0.2
  done
  t1=$(date +%s.%N)
  python3 -c '
import json, sys
g = json.loads(sys.argv[1]); c = g["covers"]
print("run %s: ready over %.2f-%.2f Hz (%d columns) %.1f s after the machine PUT (load %s)"
      % (sys.argv[4], c["lo_hz"], c["hi_hz"], c["columns"], float(sys.argv[3]) - float(sys.argv[2]),
         open("/proc/loadavg").read().split()[0]))' "$g" "$t0" "$t1" "$run"
  sed -E 's/\x1b\[[0-9;]*m//g' "$dir/serve.log" | grep -E "table (job|extension) (started|finished)" \
    | sed -E 's/^([^ ]+) +INFO [^ ]+ /  \1 /'
  kill "$serve"
  wait "$serve" 2> /dev/null || true
  rm -rf "$dir"
done
