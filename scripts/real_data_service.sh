#!/usr/bin/env bash
# The "new user" flow on the real SpectraQuest records, through the HTTP service:
# add the gearbox description, wait for its table, point a machine at it, post healthy
# records as its baseline, then post the others and print what each one gets.
#
#   scripts/real_data_service.sh [CHANNEL]      # default a1; "all" diagnoses every channel
#
# Baseline: the healthy records at loads BASELINE_LOADS (default "0 20 60 80"); scored: the
# healthy record at the other loads and every broken record. Sample rate 12 900 Hz (inferred,
# see ../shared/data/spectraquest-gfd/README.md), nominal input shaft 30 Hz. Bodies are the
# files themselves, gzip-compressed (Content-Encoding: gzip). Needs python3 and curl.
set -euo pipefail
cd "$(dirname "$0")/.."
CH=${1:-a1}
DATA=${GFD_DIR:-../shared/data/spectraquest-gfd}
BASELINE_LOADS=${BASELINE_LOADS:-"0 20 60 80"}
TARGET=${CARGO_TARGET_DIR:-target}
# GW_BIN: another binary (e.g. an older build, for a before/after) instead of this tree's.
if [ -z "${GW_BIN:-}" ]; then cargo build --release --quiet --bin gearwear; fi
BIN=${GW_BIN:-$TARGET/release/gearwear}
work=$(mktemp -d /tmp/gearwear-realdata.XXXXXX)
port=$((20000 + RANDOM % 20000))
db="$work/gw.db"
admin=$("$BIN" keys create --scope admin,ingest,read --database-url "$db" | grep -o 'gw_[A-Za-z0-9_-]*' | head -1)
"$BIN" serve --database-url "$db" --address "127.0.0.1:$port" >"$work/serve.log" 2>&1 &
spid=$!
trap 'kill $spid 2>/dev/null; wait $spid 2>/dev/null; rm -rf "$work"' EXIT
url="http://127.0.0.1:$port"
for _ in $(seq 100); do curl -fs "$url/readyz" >/dev/null 2>&1 && break; sleep 0.2; done
H=(-H "Authorization: Bearer $admin")

echo "== gearbox: PUT /v1/gearboxes/spectraquest"
curl -fsS "${H[@]}" -H 'Content-Type: application/toml' --data-binary @configs/gearboxes/spectraquest-gfd.toml \
  -X PUT "$url/v1/gearboxes/spectraquest" | python3 -c 'import json,sys; d=json.load(sys.stdin); print("  status", d["status"], "| assumed values:", len(d["assumed"]))'
t0=$(date +%s.%N)
while :; do
  st=$(curl -fsS "${H[@]}" "$url/v1/gearboxes/spectraquest" | python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["status"], d["progress"])')
  case "$st" in ready*) break ;; failed*) echo "table job failed"; exit 1 ;; esac
  sleep 0.5
done
echo "  table ready after $(python3 -c "import time,sys; print(f'{time.time()-float(sys.argv[1]):.1f}')" "$t0") s"
chans=""
[ "$CH" != all ] && chans=", \"channels\": [\"$CH\"]"
curl -fsS "${H[@]}" -H 'Content-Type: application/json' -X PUT "$url/v1/machines/sq-1" \
  -d "{\"gearbox\": \"spectraquest\", \"input_shaft_hz\": 30$chans}" >/dev/null
echo "== machine sq-1 → gearbox spectraquest, input shaft 30 Hz, channels: $CH"

post() { # post FILE QUERY → one line
  curl -sS "${H[@]}" -H 'Content-Type: text/csv' -H 'Content-Encoding: gzip' --data-binary @"$1" \
    "$url/v1/machines/sq-1/records?sample_rate_hz=12900$2" | python3 -c '
import json, sys
d = json.load(sys.stdin)
if "alert_level" not in d:
    print("  ERROR", d)
    sys.exit()
n = d.get("novelty") or {}
w = d.get("wear_degree") or {}
fit = (d.get("fit") or {}).get("chi2_per_feature")
nov = "%.2f / %.2f" % (n["score"], n["threshold"]) if n else "-"
top = ", ".join(f["name"] for f in n.get("top_features", [])[:3])
print("  %-8s channel %-3s alert %-8s novelty %-13s | wear %.2f, chi2/feature %s%s" % (
    sys.argv[1], d["channel"], d["alert_level"], nov, w.get("estimate", float("nan")),
    "-" if fit is None else "%.1f" % fit, (" | top " + top) if top else ""))' "$(basename "$1" .csv.gz)"
}
echo "== baseline (?baseline=true)"
for l in $BASELINE_LOADS; do post "$DATA/h30hz$l.csv.gz" "&baseline=true"; done
echo "== scored"
for l in 0 20 40 60 80; do
  case " $BASELINE_LOADS " in *" $l "*) ;; *) post "$DATA/h30hz$l.csv.gz" "" ;; esac
done
for l in 0 20 40 60 80; do post "$DATA/b30hz$l.csv.gz" ""; done
echo "== GET /v1/machines"
curl -fsS "${H[@]}" "$url/v1/machines" | python3 -c 'import json,sys; [print("  ", m["id"], m["alert_level"], m["record_count"], "records") for m in json.load(sys.stdin)["machines"]]'
