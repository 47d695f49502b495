#!/usr/bin/env bash
# PostgreSQL stopped while `gearwear serve` runs, then started again — on a PRIVATE cluster
# (default 15/gwfault on port 5433, trust auth), never the shared 5432 one. Needs root (or the
# postgres tools' rights) and a release build (`cargo build --release`).
#
#   scripts/fault_pg_stop.sh                      # two outages: `stop -m fast`, `stop -m immediate`
#   OUTAGE_S=30 MODES="fast" scripts/fault_pg_stop.sh
#
# Load during the run: INGEST_CLIENTS loops POST a 1 s WAV record every INTERVAL_S s, each
# request with its own Idempotency-Key; one loop GETs the machine; one polls /readyz. Every
# request's start, end and status go to a log; the figures printed at the end come from it:
# status codes while the database is down, time from its return to the first 201, anything
# but 201/200 after the return, and records stored versus 201 answers (nothing half-written).
set -euo pipefail

PGVER=${PGVER:-15}
CLUSTER=${CLUSTER:-gwfault}
PGPORT=${PGPORT:-5433}
MODES=${MODES:-"fast immediate"}
BEFORE_S=${BEFORE_S:-8}
OUTAGE_S=${OUTAGE_S:-20}
AFTER_S=${AFTER_S:-15}
INTERVAL_S=${INTERVAL_S:-0.2}
INGEST_CLIENTS=${INGEST_CLIENTS:-2}
BIN=${GEARWEAR_BIN:-${CARGO_TARGET_DIR:-target}/release/gearwear}
PORT=${PORT:-18089}

if [ "$PGPORT" = 5432 ]; then
    echo "refusing to stop the cluster on 5432: it is shared" >&2
    exit 2
fi
[ -x "$BIN" ] || { echo "no binary at $BIN: cargo build --release (or set GEARWEAR_BIN)" >&2; exit 2; }

work=$(mktemp -d /tmp/gearwear-pgstop.XXXXXX)
now() { date +%s.%N; }
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    wait 2>/dev/null || true
}
trap cleanup EXIT

# --- the private cluster
if ! pg_lsclusters -h | awk '{print $1"/"$2}' | grep -qx "$PGVER/$CLUSTER"; then
    pg_createcluster "$PGVER" "$CLUSTER" -p "$PGPORT" -- --auth=trust >/dev/null
fi
if [ "$(pg_lsclusters -h | awk -v c="$PGVER/$CLUSTER" '$1"/"$2==c {print $3}')" != "$PGPORT" ]; then
    echo "cluster $PGVER/$CLUSTER is not on port $PGPORT" >&2
    exit 2
fi
pg_ctlcluster "$PGVER" "$CLUSTER" start 2>/dev/null || true
db="gwfault_$(date +%s)"
psql -q -h 127.0.0.1 -p "$PGPORT" -U postgres -d postgres -c "CREATE DATABASE $db"
url="postgres://postgres@127.0.0.1:$PGPORT/$db"
psql_db() { psql -qtA -h 127.0.0.1 -p "$PGPORT" -U postgres -d "$db" -c "$1"; }

# --- the service
"$BIN" synth --ea 0.6 --output "$work/record.wav" >/dev/null 2>&1
key=$("$BIN" keys create --scope ingest,read --database-url "$url" 2>/dev/null)
"$BIN" serve --address "127.0.0.1:$PORT" --database-url "$url" --allow-stale-table \
    >"$work/serve.log" 2>&1 &
serve_pid=$!
pids+=("$serve_pid")
base="http://127.0.0.1:$PORT"
for _ in $(seq 300); do
    curl -fs "$base/readyz" >/dev/null 2>&1 && break
    sleep 0.1
done
curl -fs "$base/readyz" >/dev/null || { echo "serve did not start:"; cat "$work/serve.log"; exit 1; }

# --- load: each line "start end status seconds key"
ingest_loop() {
    local c=$1 j=0
    while [ ! -e "$work/stop" ]; do
        local k="c$c-$j" t0 out
        t0=$(now)
        out=$(curl -s -o /dev/null -w '%{http_code} %{time_total}' --max-time 30 \
            -H "Authorization: Bearer $key" -H 'Content-Type: audio/wav' \
            -H "Idempotency-Key: $k" --data-binary @"$work/record.wav" \
            "$base/v1/machines/pgstop/records?shaft_hz=30" || true)
        echo "$t0 $(now) ${out:-000 0} $k"
        j=$((j + 1))
        sleep "$INTERVAL_S"
    done
}
get_loop() {
    local path=$1 auth=$2
    while [ ! -e "$work/stop" ]; do
        local t0 out
        t0=$(now)
        if [ "$auth" = 1 ]; then
            out=$(curl -s -o /dev/null -w '%{http_code} %{time_total}' --max-time 30 \
                -H "Authorization: Bearer $key" "$base$path" || true)
        else
            out=$(curl -s -o /dev/null -w '%{http_code} %{time_total}' --max-time 30 \
                "$base$path" || true)
        fi
        echo "$t0 $(now) ${out:-000 0} -"
        sleep "$INTERVAL_S"
    done
}
for c in $(seq "$INGEST_CLIENTS"); do
    ingest_loop "$c" >"$work/ingest.$c.log" &
    pids+=("$!")
done
get_loop /v1/machines/pgstop 1 >"$work/read.log" &
pids+=("$!")
get_loop /readyz 0 >"$work/readyz.log" &
pids+=("$!")

# --- the outages
: >"$work/events"
sleep "$BEFORE_S"
for mode in $MODES; do
    t_stop=$(now)
    pg_ctlcluster "$PGVER" "$CLUSTER" stop -m "$mode"
    t_down=$(now)
    sleep "$OUTAGE_S"
    t_start=$(now)
    pg_ctlcluster "$PGVER" "$CLUSTER" start &
    start_pid=$!
    # The database is back when it answers a query (pg_ctlcluster returns somewhat later).
    until psql -qtA -h 127.0.0.1 -p "$PGPORT" -U postgres -d postgres -c 'SELECT 1' >/dev/null 2>&1; do
        sleep 0.02
    done
    t_back=$(now)
    wait "$start_pid"
    t_started=$(now)
    echo "$mode $t_stop $t_down $t_start $t_back $t_started" >>"$work/events"
    sleep "$AFTER_S"
done
# Let every loop finish its request (a killed loop would leave a stored record unlogged).
touch "$work/stop"
for p in "${pids[@]:1}"; do wait "$p" || true; done
cat "$work"/ingest.*.log >"$work/ingest.log"

# --- figures
echo "== fault_pg_stop $(date -u +%Y-%m-%dT%H:%M:%SZ)  cluster $PGVER/$CLUSTER port $PGPORT  work dir $work"
echo "load: $INGEST_CLIENTS ingest loops + 1 read loop + 1 /readyz loop, ${INTERVAL_S} s pause between requests"
while read -r mode t_stop t_down t_start t_back t_started; do
    printf '\n-- outage (pg_ctlcluster stop -m %s): %.1f s from the stop command to the first answered query (stop command %.2f s; answers a query %.2f s after the start command, which returns after %.2f s)\n' \
        "$mode" "$(echo "$t_back - $t_stop" | bc)" "$(echo "$t_down - $t_stop" | bc)" "$(echo "$t_back - $t_start" | bc)" "$(echo "$t_started - $t_start" | bc)"
    for kind in ingest read readyz; do
        # answers that arrived while the stop command ran, and while the database was down
        # (from the stop command's return to its first answered query)
        stopping=$(awk -v a="$t_stop" -v b="$t_down" '$2 > a && $2 <= b {n[$3]++} END {for (s in n) printf "%s×%d ", s, n[s]}' "$work/$kind.log")
        during=$(awk -v a="$t_down" -v b="$t_back" '$2 > a && $2 <= b {n[$3]++; if ($4 > m) m = $4} END {for (s in n) printf "%s×%d ", s, n[s]; printf "(slowest %.2f s)", m}' "$work/$kind.log")
        echo "  $kind: while stopping ${stopping:-none}; while down $during"
    done
    # Signed: psql's probe lags the database by up to ~0.1 s, so the service's first 201 can
    # come slightly before the probe's first answer.
    first=$(awk -v a="$t_down" -v b="$t_back" '$2 > a && $3 == 201 {printf "%.3f\n", $2 - b}' "$work/ingest.log" | sort -g | head -1)
    first_new=$(awk -v b="$t_back" '$1 > b && $3 == 201 {printf "%.3f\n", $2 - b}' "$work/ingest.log" | sort -g | head -1)
    first_ready=$(awk -v a="$t_down" -v b="$t_back" '$2 > a && $3 == 200 {printf "%.3f\n", $2 - b}' "$work/readyz.log" | sort -g | head -1)
    echo "  after the database returned: first 201 at ${first:-none} s (of a request sent after the return: ${first_new:-none} s); first /readyz 200 at ${first_ready:-none} s"
    # after the first 201: anything else is an error after recovery (until the next outage)
    next_stop=$(awk -v b="$t_back" '$2 > b {print $2}' "$work/events" | head -1)
    next_stop=${next_stop:-9e18}
    if [ -n "$first" ]; then
        t_ok=$(echo "$t_back + $first" | bc)
        after=$(awk -v a="$t_ok" -v z="$next_stop" '$1 > a && $1 < z && $3 != 201 {n++} $1 > a && $1 < z {m++} END {printf "%d of %d", n, m}' "$work/ingest.log")
        after_r=$(awk -v a="$t_ok" -v z="$next_stop" '$1 > a && $1 < z && $3 != 200 {n++} $1 > a && $1 < z {m++} END {printf "%d of %d", n, m}' "$work/read.log")
        echo "  errors after the first 201: ingest $after, reads $after_r"
    fi
done <"$work/events"

answered=$(awk '$3 == 201 {print $5}' "$work/ingest.log" | sort -u)
n201=$(printf '%s\n' "$answered" | grep -c . || true)
nreq=$(wc -l <"$work/ingest.log")
stored=$(psql_db "SELECT COUNT(*) FROM records")
keys_stored=$(psql_db "SELECT idem_key FROM idempotency_keys" | sort -u)
not_acked_keys=$(comm -13 <(printf '%s\n' "$answered") <(printf '%s\n' "$keys_stored") | grep . || true)
not_acked=$(printf '%s\n' "$not_acked_keys" | grep -c . || true)
missing=$(comm -23 <(printf '%s\n' "$answered") <(printf '%s\n' "$keys_stored") | grep -c . || true)
dups=$(psql_db "SELECT COALESCE(SUM(n - 1), 0) FROM (SELECT COUNT(*) AS n FROM idempotency_keys GROUP BY key_id, idem_key) s")
codes=$(awk '{n[$3]++} END {for (s in n) printf "%s×%d ", s, n[s]}' "$work/ingest.log")
echo
echo "-- whole run: $nreq ingest requests ($codes), $n201 answered 201"
echo "  records stored: $stored; 201s missing from the store: $missing; stored without a 201 (commit whose answer was lost): $not_acked; duplicate idempotency keys: $dups"
for k in $not_acked_keys; do
    awk -v k="$k" '$5 == k {print "    stored without a 201: " k " answered " $3 " after " $4 " s"}' "$work/ingest.log"
done
echo "  service process still the first one: $(kill -0 "$serve_pid" 2>/dev/null && echo yes || echo NO)"
grep -c "store unavailable" "$work/serve.log" | sed 's/^/  "store unavailable" warnings in the log: /'
psql -q -h 127.0.0.1 -p "$PGPORT" -U postgres -d postgres -c "DROP DATABASE $db WITH (FORCE)" >/dev/null 2>&1 || true
