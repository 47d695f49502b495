#!/usr/bin/env bash
# Instructions per record on the server's record path, a figure the machine's load
# does not move: `gearwear serve` (release) under `valgrind --tool=callgrind` on a fresh SQLite
# file, collection switched on after WARMUP records, then N records posted one at a time by
# `examples/loadgen --requests`, then the counts dumped. Prints, per record: all user-space
# instructions of the server (every thread), the inclusive count of the diagnosis
# (`diagnose_with_spectrum`, what `gearwear diagnose` runs, or `diagnose_inner`, its body, where
# it is inlined), their ratio, and the largest
# inclusive entries outside the diagnosis. Kernel work (loopback TCP, fsync) is not counted:
# `scripts/service_bench.sh` gives the CPU time with it.
#
#   scripts/record_path_profile.sh [BINARY] [LABEL]
#
# Environment: N [20], WARMUP [8], FORMATS [f32 json], EA [0.5] (the `synth` record),
# SERVE_ARGS [none], KEEP [unset: the callgrind files are deleted; a directory: kept there],
# DESCRIBED [unset; a gearbox description file, e.g. configs/gearboxes/spectraquest-gfd.toml: it
# is PUT as gearbox `described`, its table waited for, and the load generator's machines name
# it, so that the record's baseline features include an order analysis].
set -euo pipefail
cd "$(dirname "$0")/.."
GW_BIN=${1:-${CARGO_TARGET_DIR:-target}/release/gearwear}
label=${2:-this}
command -v valgrind >/dev/null || { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y valgrind; }
cargo build --release --quiet --bin gearwear --example loadgen
LG=${CARGO_TARGET_DIR:-target}/release/examples/loadgen
. scripts/lib/serve.sh
n=${N:-20} warm=${WARMUP:-8}
trap gw_cleanup EXIT
for fmt in ${FORMATS:-f32 json}; do
  gw_fresh_store sqlite prof
  d=$GW_DIR
  "$GW_BIN" synth --ea "${EA:-0.5}" --output "$d/model.wav" >/dev/null 2>&1
  key=$(gw_key ingest,read,admin)
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
  # shellcheck disable=SC2086
  valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file="$d/cg.out" \
    "$GW_BIN" serve --address "127.0.0.1:$port" --database-url "$GW_DB" \
    --rate-per-second 100000 --rate-burst 100000 ${SERVE_ARGS:-} >"$d/serve.log" 2>&1 &
  GW_PID=$!
  for _ in $(seq 600); do
    curl -fs "http://127.0.0.1:$port/readyz" >/dev/null 2>&1 && break
    sleep 0.5
  done
  curl -fs "http://127.0.0.1:$port/readyz" >/dev/null || { cat "$d/serve.log" >&2; exit 1; }
  if [ -n "${DESCRIBED:-}" ]; then
    curl -fsS -X PUT -H "Authorization: Bearer $key" -H 'Content-Type: application/toml' \
      --data-binary @"$DESCRIBED" "http://127.0.0.1:$port/v1/gearboxes/described" >/dev/null
    for _ in $(seq 600); do
      st=$(curl -fsS -H "Authorization: Bearer $key" "http://127.0.0.1:$port/v1/gearboxes/described" |
        python3 -c 'import json,sys; print(json.load(sys.stdin)["status"])')
      [ "$st" = ready ] && break
      [ "$st" = failed ] && { echo "the gearbox's table failed" >&2; exit 1; }
      sleep 1
    done
    for m in 0 1 2 3; do
      curl -fsS -X PUT -H "Authorization: Bearer $key" -H 'Content-Type: application/json' \
        -d '{"gearbox": "described"}' "http://127.0.0.1:$port/v1/machines/load-$m" >/dev/null
    done
  fi
  common=(--url "http://127.0.0.1:$port" --key "$key" --concurrency 1 --seconds 3600
    --format "$fmt" --record "$d/model.wav")
  "$LG" "${common[@]}" --requests "$warm" >/dev/null
  callgrind_control -i on "$GW_PID" >/dev/null 2>&1
  "$LG" "${common[@]}" --requests "$n" | tail -1 >"$d/run.json"
  callgrind_control -d "$GW_PID" >/dev/null 2>&1
  callgrind_control -i off "$GW_PID" >/dev/null 2>&1
  kill "$GW_PID" 2>/dev/null || true
  wait "$GW_PID" 2>/dev/null || true
  GW_PID=""
  out=$(ls "$d"/cg.out.* 2>/dev/null | head -1 || ls "$d"/cg.out)
  callgrind_annotate --inclusive=yes --threshold=100 "$out" >"$d/annotate.txt" 2>/dev/null || true
  if [ -n "${KEEP:-}" ]; then mkdir -p "$KEEP"; cp "$out" "$KEEP/cg.$label.$fmt.out"; cp "$d/annotate.txt" "$KEEP/annotate.$label.$fmt.txt"; fi
  python3 - "$d/annotate.txt" "$d/run.json" "$n" "$label" "$fmt" <<'PY'
import json, re, sys
ann, run, n, label, fmt = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
ok = json.load(open(run))["records"]
total = None
rows = []
for line in open(ann):
    m = re.match(r"\s*([\d,]+)\s+(?:\([^)]*\)\s+)?(?:\*\s+)?(\S.*)$", line)
    if not m:
        continue
    v = int(m.group(1).replace(",", ""))
    name = m.group(2)
    if "PROGRAM TOTALS" in name:
        total = v
    else:
        rows.append((v, name))
# The diagnosis: `diagnose_with_spectrum`, or its body when the compiler inlined it.
diag = max((v for v, f in rows
            if "diagnose_with_spectrum" in f or "diagnosis::diagnose_inner" in f), default=0)
print(f"{label} {fmt}: {ok}/{n} records; per record: server {total / ok / 1e6:.2f} M instructions, "
      f"diagnosis {diag / ok / 1e6:.2f} M, ratio {total / diag:.3f}")
seen = set()
print("  largest inclusive entries (M instructions per record), outside the diagnosis's callees:")
k = 0
for v, f in sorted(rows, reverse=True):
    short = re.sub(r"^\S*:", "", f).strip()[:110]
    if short in seen:
        continue
    seen.add(short)
    print(f"    {v / ok / 1e6:8.2f}  {short}")
    k += 1
    if k >= 40:
        break
PY
  rm -rf "$d"
done
