#!/usr/bin/env bash
# Tests of the replicated topology, each on a cluster started by scripts/cluster.sh
# (fresh PostgreSQL database, replicas, nginx) and stopped after it:
#
#   1 race      the same Idempotency-Key POSTed at once to two replicas (their own ports,
#               not through nginx), TRIALS times: one record stored per key, equal answers;
#   2 webhooks  a webhook subscribed, RECORDS records through nginx: every delivery answered
#               2xx exactly once across the replicas, every signature valid;
#   3 lease     (same cluster) the receiver holds deliveries; the replica holding one is
#               SIGKILLed and kept down: another replica delivers what it had claimed once
#               the lease (2 × 10 s attempt timeout + 1 s) runs out;
#   4 kill9     at least KILL_RECORDS records (more, until the kills are done) through nginx
#               from 6 clients that re-send with the same Idempotency-Key until answered,
#               while replicas are SIGKILLed KILLS times
#               (cluster.sh restarts them): every acknowledged record stored once, what nginx
#               did with the requests, the restarted replicas serving again;
#   5 scale     examples/loadgen through nginx with 1 and with 2 replicas (closed loop,
#               SCALE_CONCURRENCY clients, SCALE_SECONDS s, the model's record as f32): records/s
#               and CPU per record of replicas, nginx, PostgreSQL (this database's backends
#               + its writer processes) and the load generator; then pgbench on the INSERT
#               path alone (the database's own limit per record).
#
#   6 tablejob  a gearbox PUT through nginx: its table job runs on exactly one replica (the
#               claim in the store); that replica is SIGKILLed mid-job and kept down: the
#               other claims the job when its lease (30 s) has run out and finishes it; the
#               table is stored once, by the replica that holds the job;
#
#   scripts/cluster_test.sh [1 2 3 4 5 6]        # default: all; 2 and 3 run together
#
# Environment: TRIALS [30], RECORDS [300], KILL_RECORDS [3000], KILLS [4], SCALE_SECONDS [20],
# KEEP_WORK [unset: the work files — logs, receiver log, nginx access log — are removed
# unless a check failed], SCALE_CONCURRENCY [4], SCALE_FORMAT [f32; or json], SCALE_SERVE_ARGS [none; e.g.
# "--raw-retention-days 0"], PGBENCH_SECONDS [15]. Prints the figures; exits non-zero when a
# check fails. Needs python3 and PostgreSQL at 127.0.0.1:5432; cluster.sh installs nginx.
set -euo pipefail
cd "$(dirname "$0")/.."

tests=("$@")
[ ${#tests[@]} -eq 0 ] && tests=(1 2 3 4 5 6)
want() { local t; for t in "${tests[@]}"; do [ "$t" = "$1" ] && return 0; done; return 1; }

TARGET=${CARGO_TARGET_DIR:-target}
GW_BIN=${GW_BIN:-$TARGET/release/gearwear}
export GW_BIN
# Always the same targets: building the binary alone resolves dependency features without the
# example's dev-dependencies and compiles a second variant of the crate (minutes).
cargo build --release --quiet --bin gearwear --example loadgen
TOOL=(python3 scripts/lib/cluster_tool.py)
work=$(mktemp -d /tmp/gearwear-cluster-test.XXXXXX)
chmod 755 "$work"
cluster_pid="" recv_pid="" failed=0
SERVE=(--allow-stale-table --rate-per-second 100000 --rate-burst 100000)

# shellcheck disable=SC2317  # called by the trap
finish() {
  local rc=$?
  if [ -n "$recv_pid" ]; then kill "$recv_pid" 2>/dev/null || true; fi
  stop_cluster
  wait 2>/dev/null || true
  if [ "$rc" = 0 ] && [ "$failed" = 0 ] && [ -z "${KEEP_WORK:-}" ]; then rm -rf "$work"; else echo "work files kept in $work" >&2; fi
}
trap finish EXIT
trap 'exit 143' TERM
trap 'exit 130' INT

say() { echo "$*"; }
check() { # check NAME CONDITION-RESULT(0/1) DETAIL
  if [ "$2" = 0 ]; then say "  ok   $1: $3"; else say "  FAIL $1: $3"; failed=1; fi
}
now() { date +%s.%N; }
since() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.2f}')" "$1" "$(now)"; }

start_cluster() { # start_cluster N NAME
  local envf="$work/$2.env"
  scripts/cluster.sh --no-build --replicas "$1" --dir "$work/$2" --env-file "$envf" \
    -- "${SERVE[@]}" >"$work/$2.cluster.log" 2>&1 &
  cluster_pid=$!
  local t
  for t in $(seq 300); do
    [ -s "$envf" ] && break
    if ! kill -0 "$cluster_pid" 2>/dev/null; then
      cat "$work/$2.cluster.log" >&2
      echo "cluster.sh failed" >&2
      exit 1
    fi
    sleep 0.2
  done
  [ -s "$envf" ] || { echo "cluster not ready in 60 s" >&2; exit 1; }
  # shellcheck disable=SC1090
  . "$envf"
  say "  cluster: $CLUSTER_REPLICAS replica(s) on ports ${CLUSTER_PORTS[*]}, nginx $CLUSTER_URL, database $CLUSTER_DB_NAME"
}
stop_cluster() {
  if [ -n "$cluster_pid" ]; then
    kill -TERM "$cluster_pid" 2>/dev/null || true
    wait "$cluster_pid" 2>/dev/null || true
    cluster_pid=""
  fi
}
replica_pid() { cat "$CLUSTER_DIR/replica-$1.pid"; }
# Errors of this database in the PostgreSQL server log (Debian's place and log_line_prefix
# "%m [%p] %q%u@%d "); empty when there is no readable log.
pglog_count() {
  local f
  f=$(find /var/log/postgresql -maxdepth 1 -name 'postgresql-*-main.log' 2>/dev/null | head -1)
  [ -n "$f" ] && [ -r "$f" ] || return 0
  grep -c "@$CLUSTER_DB_NAME ERROR:  $1" "$f" || true
}
q() { psql -X -At -h 127.0.0.1 -U "${PGUSER:-postgres}" -d "$CLUSTER_DB_NAME" -c "$1"; }
key() { "$GW_BIN" keys create --scope "$1" --database-url "$CLUSTER_DB" 2>/dev/null | grep -o 'gw_[A-Za-z0-9_-]*' | head -1; }
wait_ready() { # wait_ready PORT SECONDS → prints seconds waited, fails after
  local t0 t
  t0=$(now)
  for t in $(seq "$(($2 * 10))"); do
    if curl -fs -m 1 "http://127.0.0.1:$1/readyz" >/dev/null 2>&1; then since "$t0"; return 0; fi
    sleep 0.1
  done
  return 1
}

"$GW_BIN" synth --ea 0.5 --output "$work/model.f32" >/dev/null
"$GW_BIN" synth --ea 0.5 --output "$work/model.wav" >/dev/null
say "== cluster_test $(date -u +%FT%TZ), $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"

# ---------------------------------------------------------------------------------------
if want 1; then
  trials=${TRIALS:-30}
  say "== 1. the same Idempotency-Key to two replicas at once ($trials trials)"
  start_cluster 2 race
  k=$(key ingest,read)
  before=$(pglog_count "duplicate key value violates unique constraint \"idempotency_keys_pkey\"")
  out=$("${TOOL[@]}" race "http://127.0.0.1:${CLUSTER_PORTS[0]}" "http://127.0.0.1:${CLUSTER_PORTS[1]}" \
    "$k" "$work/model.f32" "$trials")
  say "  $out"
  recs=$(q "SELECT count(*) FROM records WHERE machine_id = 'race-1'")
  idem=$(q "SELECT count(*) FROM idempotency_keys WHERE idem_key LIKE 'race-%'")
  diags=$(q "SELECT count(*) FROM diagnoses WHERE machine_id = 'race-1'")
  after=$(pglog_count "duplicate key value violates unique constraint \"idempotency_keys_pkey\"")
  conflicts=unknown
  [ -n "$before" ] && [ -n "$after" ] && conflicts=$((after - before))
  read -r both same one distinct < <(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print(d["both_2xx"], d["same_body"], d["one_replayed"], d["distinct_record_ids"])' "$out")
  check "both answered 201" "$([ "$both" = "$trials" ] && echo 0 || echo 1)" "$both / $trials"
  check "identical answers" "$([ "$same" = "$trials" ] && echo 0 || echo 1)" "$same / $trials (one of the two marked Idempotent-Replayed in $one)"
  check "one record per key" "$([ "$recs" = "$trials" ] && [ "$idem" = "$trials" ] && [ "$diags" = "$trials" ] && [ "$distinct" = "$trials" ] && echo 0 || echo 1)" \
    "records $recs, diagnoses $diags, idempotency rows $idem, distinct record ids in answers $distinct"
  say "  unique-key conflicts in the PostgreSQL log for this database (both replicas diagnosed, the second insert lost): $conflicts of $trials"
  stop_cluster
fi

# ---------------------------------------------------------------------------------------
if want 2 || want 3; then
  records=${RECORDS:-300}
  say "== 2. webhook deliveries across 2 replicas ($records records through nginx)"
  start_cluster 2 hooks
  admin=$(key admin)
  "${TOOL[@]}" receiver "$work/recv.port" "$work/recv.log" "$CLUSTER_DIR" 2>"$work/recv.err" &
  recv_pid=$!
  for _ in $(seq 50); do [ -s "$work/recv.port" ] && break; sleep 0.1; done
  rport=$(cat "$work/recv.port")
  secret=$(curl -fsS -H "Authorization: Bearer $admin" -H 'Content-Type: application/json' \
    -d "{\"url\": \"http://127.0.0.1:$rport/hook\", \"events\": [\"diagnosis.created\", \"wear.threshold_crossed\"]}" \
    "$CLUSTER_URL/v1/webhooks" | python3 -c 'import json,sys; print(json.load(sys.stdin)["secret"])')
  out=$("${TOOL[@]}" ingest "$CLUSTER_URL" "$admin" "$work/model.f32" "$records" 4 "$work/hooks.acked")
  say "  ingest: $out"
  t0=$(now)
  for _ in $(seq 600); do
    [ "$(q "SELECT count(*) FROM deliveries WHERE status <> 'delivered'")" = 0 ] && break
    sleep 0.1
  done
  say "  all deliveries delivered $(since "$t0") s after the last record was acknowledged"
  total=$(q "SELECT count(*) FROM deliveries")
  byev=$(q "SELECT event || ' ' || count(*) FROM deliveries GROUP BY event ORDER BY event" | paste -sd, -)
  ndelivered=$(q "SELECT count(*) FROM deliveries WHERE status = 'delivered'")
  attempts=$(q "SELECT count(*) FROM delivery_attempts")
  dres=$("${TOOL[@]}" deliveries "$work/recv.log" "$secret")
  say "  database: $total deliveries ($byev), $ndelivered delivered, $attempts attempts recorded"
  say "  receiver: $dres"
  read -r ans dans twice rtwice badsig < <(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print(d["answered_2xx"], d["distinct_answered_2xx"], d["answered_more_than_once"], d["received_more_than_once"], d["bad_signatures"])' "$dres")
  creates=$(q "SELECT count(*) FROM deliveries WHERE event = 'diagnosis.created'")
  check "one diagnosis.created per record" "$([ "$creates" = "$records" ] && echo 0 || echo 1)" "$creates for $records records"
  check "every delivery answered exactly once" "$([ "$ans" = "$total" ] && [ "$dans" = "$total" ] && [ "$twice" = 0 ] && [ "$rtwice" = 0 ] && [ "$ndelivered" = "$total" ] && [ "$attempts" = "$total" ] && echo 0 || echo 1)" \
    "$ans answers, $dans distinct, $twice answered twice, $rtwice received twice, of $total"
  check "signatures" "$([ "$badsig" = 0 ] && echo 0 || echo 1)" "$badsig bad"
  split=$(python3 - "$work/recv.log" <<'EOF'
import json, sys, collections
c = collections.Counter()
for l in open(sys.argv[1]):
    e = json.loads(l)
    if e["ev"] == "recv":
        c[f"replica {e['sender']['replica']}" if e.get("sender") else "unknown"] += 1
print(", ".join(f"{k} {v}" for k, v in sorted(c.items())))
EOF
)
  say "  sent by: $split"

  if want 3; then
    say "== 3. a replica killed while it holds leased deliveries (the webhook delivery lease)"
    # Recent "recv" lines of the receiver's log: "replica delivery" pairs after line $1.
    senders() {
      python3 - "$work/recv.log" "$1" <<'EOF'
import json, sys
for l in open(sys.argv[1]).readlines()[int(sys.argv[2]):]:
    e = json.loads(l)
    if e["ev"] == "recv" and e.get("sender"):
        print(e["sender"]["replica"], e["delivery"])
EOF
    }
    due() { q "SELECT count(*) FROM deliveries WHERE status = 'pending' AND next_attempt_at <= (extract(epoch from now()) * 1000)::bigint"; }
    leased() { q "SELECT count(*) FROM deliveries WHERE status = 'pending' AND next_attempt_at > (extract(epoch from now()) * 1000)::bigint"; }
    # a. Hold the receiver's answers until both replicas' workers are stuck sending one delivery
    #    each (one record at a time through nginx, at most 12).
    curl -fsS "http://127.0.0.1:$rport/_hang?on=1" >/dev/null
    mark=$(wc -l <"$work/recv.log")
    for n in $(seq 12); do
      "${TOOL[@]}" ingest "$CLUSTER_URL" "$admin" "$work/model.f32" 1 1 "$work/lease0.acked" >/dev/null
      sleep 0.3
      [ "$(senders "$mark" | cut -d' ' -f1 | sort -u | wc -l)" = 2 ] && break
    done
    stuck=$(senders "$mark")
    if [ "$(echo "$stuck" | cut -d' ' -f1 | sort -u | wc -l)" != 2 ]; then
      check "both workers held" 1 "senders seen: $(echo "$stuck" | tr '\n' ' ')"
    else
      # b. Records whose deliveries queue up unclaimed (both workers are busy).
      n3=30
      "${TOOL[@]}" ingest "$CLUSTER_URL" "$admin" "$work/model.f32" "$n3" 4 "$work/lease.acked" >"$work/lease.out"
      queued=$(due)
      # c. Let the victim's stuck delivery through: its worker leases a batch of the queued
      #    ones and gets stuck on the first of them.
      victim=1
      vfirst=$(echo "$stuck" | awk -v v="$victim" '$1 == v { print $2; exit }')
      mark2=$(wc -l <"$work/recv.log")
      curl -fsS "http://127.0.0.1:$rport/_release?d=$vfirst" >/dev/null
      for _ in $(seq 50); do
        senders "$mark2" | grep -q "^$victim " && break
        sleep 0.1
      done
      vheld=$(senders "$mark2" | awk -v v="$victim" '$1 == v { print $2 }' | paste -sd, -)
      nleased=$(leased)
      vpid=$(replica_pid "$victim")
      touch "$CLUSTER_DIR/hold-$victim"
      kill -9 "$vpid"
      tkill=$(now)
      curl -fsS "http://127.0.0.1:$rport/_hang?on=0" >/dev/null
      say "  $n3 records queued $queued due deliveries while both workers were held; replica $victim's worker, let go, leased a batch and was held again sending $vheld"
      say "  replica $victim (pid $vpid) SIGKILLed then (kept down); $nleased deliveries were leased at that moment (the victim's batch + the other replica's held one)"
      done3=""
      for _ in $(seq 600); do
        if [ "$(q "SELECT count(*) FROM deliveries WHERE status <> 'delivered'")" = 0 ]; then done3=yes; break; fi
        sleep 0.1
      done
      # Deliveries first answered after the kill, and by whom: the survivor's held one at once,
      # the victim's batch when its lease has run out.
      res=$(python3 - "$work/recv.log" "$tkill" "$victim" <<'EOF'
import json, sys
tkill, victim = float(sys.argv[2]), int(sys.argv[3])
recv_by, ok_t = {}, {}
gone = 0
for l in open(sys.argv[1]):
    e = json.loads(l)
    if e["ev"] == "recv":
        recv_by[e["delivery"]] = (e.get("sender") or {}).get("replica")
    elif e["ev"] == "ok" and e["t"] > tkill:
        ok_t[e["delivery"]] = (e["t"] - tkill, recv_by.get(e["delivery"]))
    elif e["ev"] == "gone" and e["t"] > tkill:
        gone += 1
late = [t for t, _ in ok_t.values() if t > 5]
by_late = sorted({str(b) for t, b in ok_t.values() if t > 5})
print(len(ok_t), len(late), f"{min(late):.1f}" if late else "-", f"{max(late):.1f}" if late else "-",
      "+".join(by_late) or "-", gone, "bad" if str(victim) in by_late else "ok")
EOF
)
      read -r nafter nlate tmin tmax by gone verdict <<<"$res"
      check "the victim's leased deliveries delivered by the other replica" \
        "$([ -n "$done3" ] && [ "$nlate" -ge "$((nleased - 1))" ] && [ "$nlate" -gt 0 ] && [ "$verdict" = ok ] && echo 0 || echo 1)" \
        "$nafter answered after the kill, $nlate of them $tmin–$tmax s after it (lease: 2 × 10 s attempt timeout + 1 s), all by replica $by; the victim's cut-off attempt seen as gone: $gone"
      dres=$("${TOOL[@]}" deliveries "$work/recv.log" "$secret")
      total=$(q "SELECT count(*) FROM deliveries")
      say "  receiver (whole run): $dres; database: $total deliveries, $(q "SELECT count(*) FROM deliveries WHERE status = 'delivered'") delivered"
      read -r ans dans twice < <(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print(d["answered_2xx"], d["distinct_answered_2xx"], d["answered_more_than_once"])' "$dres")
      check "still every delivery answered 2xx exactly once" "$([ "$ans" = "$total" ] && [ "$dans" = "$total" ] && [ "$twice" = 0 ] && echo 0 || echo 1)" \
        "$ans answers, $dans distinct, $twice twice, of $total"
      rm -f "$CLUSTER_DIR/hold-$victim"
      if w=$(wait_ready "${CLUSTER_PORTS[$((victim - 1))]}" 30); then
        say "  replica $victim released: restarted by cluster.sh and ready after $w s"
      else
        check "victim restarted" 1 "not ready in 30 s"
      fi
    fi
  fi
  kill "$recv_pid" 2>/dev/null || true; wait "$recv_pid" 2>/dev/null || true; recv_pid=""
  stop_cluster
fi

# ---------------------------------------------------------------------------------------
if want 4; then
  nrec=${KILL_RECORDS:-3000} kills=${KILLS:-4}
  say "== 4. kill -9 under load: $nrec records through nginx, 6 clients, $kills kills"
  start_cluster 2 kill9
  k=$(key ingest,read)
  # The load lasts until the kills are done (INGEST_UNTIL), however fast the machine: at least
  # $nrec records.
  rm -f "$work/kills.done"
  INGEST_UNTIL="$work/kills.done" "${TOOL[@]}" ingest "$CLUSTER_URL" "$k" "$work/model.f32" "$nrec" 6 "$work/kill.acked" >"$work/kill.out" &
  ing_pid=$!
  last_ready=$(now)
  sleep 3
  # Odd kills: cluster.sh restarts the replica at once. Even kills: it is held down 8 s,
  # longer than nginx's fail_timeout (5 s), so nginx tries it again while it is down.
  for n in $(seq "$kills"); do
    kill -0 "$ing_pid" 2>/dev/null || { check "load ran through the kills" 1 "the load generator stopped before kill $n"; break; }
    i=$(((n - 1) % 2 + 1))
    p=$(replica_pid "$i")
    down=0
    [ $((n % 2)) = 0 ] && { down=8; touch "$CLUSTER_DIR/hold-$i"; }
    kill -9 "$p"
    t=$(now)
    if [ "$down" -gt 0 ]; then sleep "$down"; rm -f "$CLUSTER_DIR/hold-$i"; fi
    sleep 0.6 # cluster.sh looks every 0.5 s
    for _ in $(seq 100); do [ "$(replica_pid "$i")" != "$p" ] && break; sleep 0.1; done
    if w=$(wait_ready "${CLUSTER_PORTS[$((i - 1))]}" 30); then
      say "  kill $n: replica $i (pid $p) at $t, held down ${down} s; restarted as pid $(replica_pid "$i"), ready $(since "$t") s after the kill"
      last_ready=$(now)
    else
      check "replica $i restarted" 1 "not ready 30 s after kill $n"
    fi
    sleep 3
  done
  touch "$work/kills.done"
  wait "$ing_pid" || true
  out=$(cat "$work/kill.out")
  nsent=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["sent"])' "$out")
  say "  ingest: $out"
  python3 -c 'import json; print("\n".join(json.loads(l)["record_id"] for l in open("'"$work/kill.acked"'")))' | sort >"$work/acked.ids"
  q "SELECT id FROM records WHERE machine_id LIKE 'kill-%'" | sort >"$work/db.ids"
  nack=$(wc -l <"$work/acked.ids")
  ndb=$(wc -l <"$work/db.ids")
  missing=$(comm -23 "$work/acked.ids" "$work/db.ids" | wc -l)
  extra=$(comm -13 "$work/acked.ids" "$work/db.ids" | wc -l)
  nidem=$(q "SELECT count(*) FROM idempotency_keys WHERE idem_key LIKE 'kill-%'")
  dupacks=$(python3 -c 'import json; ids=[json.loads(l)["key"] for l in open("'"$work/kill.acked"'")]; print(len(ids)-len(set(ids)))')
  check "acknowledged records all stored" "$([ "$missing" = 0 ] && [ "$nack" = "$nsent" ] && [ "$nack" -ge "$nrec" ] && echo 0 || echo 1)" "$nack acknowledged of $nsent sent, $missing of them missing from the database"
  check "nothing stored twice or unacknowledged" "$([ "$extra" = 0 ] && [ "$ndb" = "$nidem" ] && [ "$dupacks" = 0 ] && echo 0 || echo 1)" \
    "$ndb rows, $nidem idempotency keys, $extra rows never acknowledged"
  # A client may see 502 (nginx: the replica died with the request) or 503 (retry later); a
  # 500 is a server bug (it was: a deadlock between two replicas' group commits, now 503).
  other=$(python3 -c 'import json,sys; d=json.loads(sys.argv[1])["statuses"]; print(sum(v for k, v in d.items() if k not in ("201", "502", "503")))' "$out")
  check "no answer other than 201, 502, 503" "$([ "$other" = 0 ] && echo 0 || echo 1)" "$other other answers"
  dl=$(pglog_count "deadlock detected")
  say "  deadlocks between replicas in the PostgreSQL log for this database: ${dl:-unknown}"
  # What nginx did: final status of each POST, and the POSTs it passed to a second replica.
  python3 - "$CLUSTER_DIR/nginx/access.log" <<'EOF'
import sys, collections
final, tried = collections.Counter(), collections.Counter()
for l in open(sys.argv[1]):
    f = l.rstrip("\n").split("|")
    if len(f) != 7 or f[1] != "POST":
        continue
    final[f[3]] += 1
    if "," in f[4]:
        tried[f"{f[4]} answered {f[5]}"] += 1
print("  nginx, POSTs by the status the client got: " + ", ".join(f"{k} {v}" for k, v in sorted(final.items())))
print(f"  nginx passed {sum(tried.values())} POSTs on to the other replica: " + "; ".join(f"{k} ({v}x)" for k, v in tried.most_common(6)))
EOF
  # The restarted replicas take traffic again: 40 more records, then who answered them. nginx
  # keeps a replica it saw fail out of rotation for fail_timeout (5 s), so wait that long after
  # the last restart; no manual step.
  rest=$(python3 -c "import sys; print(max(0.0, 6.0 - (float(sys.argv[2]) - float(sys.argv[1]))))" "$last_ready" "$(now)")
  sleep "$rest"
  mark=$(wc -l <"$CLUSTER_DIR/nginx/access.log")
  "${TOOL[@]}" ingest "$CLUSTER_URL" "$k" "$work/model.f32" 40 4 "$work/after.acked" >"$work/after.out"
  split=$(tail -n +"$((mark + 1))" "$CLUSTER_DIR/nginx/access.log" | awk -F'|' '$2 == "POST" { c[$5 " " $6]++ } END { for (k in c) printf "%s: %d; ", k, c[k] }')
  say "  after the kills, 40 records: $(cat "$work/after.out")"
  say "  answered by (upstream status): $split"
  n1=$(tail -n +"$((mark + 1))" "$CLUSTER_DIR/nginx/access.log" | grep -c "|127.0.0.1:${CLUSTER_PORTS[0]}|201|" || true)
  n2=$(tail -n +"$((mark + 1))" "$CLUSTER_DIR/nginx/access.log" | grep -c "|127.0.0.1:${CLUSTER_PORTS[1]}|201|" || true)
  check "both restarted replicas serve again" "$([ "$n1" -gt 0 ] && [ "$n2" -gt 0 ] && echo 0 || echo 1)" "replica 1: $n1, replica 2: $n2 records"
  stop_cluster
fi

# ---------------------------------------------------------------------------------------
if want 5; then
  secs=${SCALE_SECONDS:-20} conc=${SCALE_CONCURRENCY:-4} fmt=${SCALE_FORMAT:-f32}
  say "== 5. throughput through nginx, 1 and 2 replicas (loadgen, closed loop, $conc clients, ${secs} s, model record as $fmt)"
  LG=$TARGET/release/examples/loadgen
  read -ra extra <<<"${SCALE_SERVE_ARGS:-}"
  SERVE+=("${extra[@]}")
  [ ${#extra[@]} -gt 0 ] && say "  serve options added: ${extra[*]}"
  # PostgreSQL's shared writer processes (WAL writer, checkpointer, background writer).
  mapfile -t aux < <(pgrep -f 'postgres: .*(checkpointer|background writer|walwriter)')
  for n in 1 2; do
    start_cluster "$n" "scale$n"
    k=$(key ingest,read)
    "$LG" --url "$CLUSTER_URL" --key "$k" --concurrency "$conc" --seconds 3 --format f32 --record "$work/model.wav" >/dev/null 2>&1
    reps=""
    for i in $(seq "$n"); do reps+="$(replica_pid "$i") "; done
    ngx="$CLUSTER_NGINX_PID $(pgrep -P "$CLUSTER_NGINX_PID" | tr '\n' ' ')"
    backends() { q "SELECT pid FROM pg_stat_activity WHERE datname = '$CLUSTER_DB_NAME'" | tr '\n' ' '; }
    pgb0=$(backends)
    # shellcheck disable=SC2086
    {
      "${TOOL[@]}" cpu $reps >"$work/c.rep0"; "${TOOL[@]}" cpu $ngx >"$work/c.ngx0"
      "${TOOL[@]}" cpu $pgb0 >"$work/c.pgb0"; "${TOOL[@]}" cpu "${aux[@]}" >"$work/c.aux0"
      "${TOOL[@]}" machine_cpu >"$work/c.m0"
    }
    r0=$(q "SELECT count(*) FROM records")
    wal0=$(q "SELECT pg_current_wal_lsn()")
    "$LG" --url "$CLUSTER_URL" --key "$k" --concurrency "$conc" --seconds "$secs" --format "$fmt" \
      --record "$work/model.wav" --pid "$(replica_pid 1)" 2>&1 | tail -1 >"$work/lg$n.json"
    pgb1="$pgb0 $(backends)"
    # shellcheck disable=SC2086
    {
      "${TOOL[@]}" cpu $reps >"$work/c.rep1"; "${TOOL[@]}" cpu $ngx >"$work/c.ngx1"
      "${TOOL[@]}" cpu $pgb1 >"$work/c.pgb1"; "${TOOL[@]}" cpu "${aux[@]}" >"$work/c.aux1"
      "${TOOL[@]}" machine_cpu >"$work/c.m1"
    }
    r1=$(q "SELECT count(*) FROM records")
    wal=$(q "SELECT pg_wal_lsn_diff(pg_current_wal_lsn(), '$wal0')")
    python3 - "$work" "$n" "$((r1 - r0))" "$wal" <<'EOF'
import json, sys
w, n, stored, wal = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
s = json.load(open(f"{w}/lg{n}.json"))
rec = s["records"]
def d(name):
    a, b = json.load(open(f"{w}/c.{name}0")), json.load(open(f"{w}/c.{name}1"))
    return sum(v - a.get(p, 0.0) for p, v in b.items())
m0, m1 = (list(map(float, open(f"{w}/c.m{i}").read().split())) for i in (0, 1))
busy, total, wall = m1[0] - m0[0], m1[1] - m0[1], m1[2] - m0[2]
parts = {"replicas": d("rep"), "nginx": d("ngx"), "postgres backends": d("pgb"), "postgres writers": d("aux")}
ms = {k: v / rec * 1e3 for k, v in parts.items()}
lg = s["client_cpu_ms_per_record"]
ours = sum(parts.values()) + lg * rec / 1e3
print(f"  {n} replica(s): {rec} records in {s['seconds']:.1f} s = {s['records_per_second']:.1f} records/s, "
      f"{s['errors']} errors, p50 {s['p50_ms']:.1f} ms, p99 {s['p99_ms']:.1f} ms; rows stored {stored}; "
      f"WAL {wal / max(stored, 1) / 1024:.0f} KiB per record (the whole PostgreSQL cluster's WAL: other databases' writes included)")
print("    CPU ms per record: " + ", ".join(f"{k} {v:.2f}" for k, v in ms.items()) +
      f", load generator {lg:.2f}; sum {sum(ms.values()) + lg:.2f}")
print(f"    machine: {busy / total * 100:.0f} % of its {total / wall:.1f} cores busy over the {wall:.1f} s measured; "
      f"of {busy:.1f} CPU-seconds, this test's processes {ours:.1f}, other processes (other developers' builds) {busy - ours:.1f}")
EOF
    stop_cluster
  done

  # The database alone: the INSERT path of one record as pgbench runs it, one record per
  # transaction (the service's group commit puts several in one), rows copied from real ones.
  say "== 5b. the database's INSERT path alone (pgbench, ${PGBENCH_SECONDS:-15} s)"
  start_cluster 1 pgb
  k=$(key ingest,read)
  "$LG" --url "$CLUSTER_URL" --key "$k" --concurrency 2 --seconds 2 --format f32 --record "$work/model.wav" >/dev/null 2>&1
  q "CREATE TABLE t_rec AS SELECT * FROM records LIMIT 1; CREATE TABLE t_diag AS SELECT * FROM diagnoses LIMIT 1; CREATE TABLE t_idem AS SELECT * FROM idempotency_keys LIMIT 1" >/dev/null
  say "  row sizes: samples $(q "SELECT octet_length(samples) FROM t_rec") B, features $(q "SELECT length(features) FROM t_rec") B, diagnosis body $(q "SELECT length(body) FROM t_diag") B, spectrum $(q "SELECT length(spectrum) FROM t_diag") B, stored answer $(q "SELECT length(response) FROM t_idem") B"
  cat >"$work/ingest.sql" <<'EOF'
SELECT * FROM idempotency_keys WHERE key_id = 'pgb' AND idem_key = gen_random_uuid()::text;
SELECT * FROM calibrations WHERE machine_id = 'pgb-' || :client_id;
BEGIN;
INSERT INTO machines (id, created_at, updated_at) VALUES ('pgb-' || :client_id, 0, 0) ON CONFLICT (id) DO NOTHING;
INSERT INTO idempotency_keys (key_id, idem_key, request_hash, status, response, created_at) SELECT key_id, gen_random_uuid()::text, request_hash, status, response, created_at FROM t_idem;
SELECT alert_level FROM machines WHERE id = 'pgb-' || :client_id;
WITH r AS (INSERT INTO records (id, machine_id, received_at, recorded_at, sensor, content_type, sample_rate_hz, shaft_hz, sample_count, sha256, features, samples) SELECT gen_random_uuid()::text, 'pgb-' || :client_id, received_at, recorded_at, sensor, content_type, sample_rate_hz, shaft_hz, sample_count, sha256, features, samples FROM t_rec RETURNING id)
INSERT INTO diagnoses (id, record_id, machine_id, created_at, ea_estimate, ea_lower, ea_upper, alert_level, motion_state, body, spectrum)
  SELECT gen_random_uuid()::text, r.id, 'pgb-' || :client_id, created_at, ea_estimate, ea_lower, ea_upper, alert_level, motion_state, body, spectrum FROM r, t_diag;
UPDATE machines SET record_count = record_count + 1, updated_at = 1, alert_level = 'ok' WHERE id = 'pgb-' || :client_id;
SELECT * FROM webhooks WHERE deleted_at IS NULL;
COMMIT;
EOF
  pgsecs=${PGBENCH_SECONDS:-15}
  for c in 1 2; do
    aux0=$("${TOOL[@]}" cpu "${aux[@]}")
    pgbench -n -h 127.0.0.1 -U "${PGUSER:-postgres}" -c "$c" -j "$c" -T "$pgsecs" -f "$work/ingest.sql" "$CLUSTER_DB_NAME" \
      >"$work/pgbench$c.out" 2>&1 &
    pb=$!
    bpids=""
    for _ in $(seq 30); do
      sleep 0.1
      bpids=$(q "SELECT pid FROM pg_stat_activity WHERE datname = '$CLUSTER_DB_NAME' AND application_name = 'pgbench'" | tr '\n' ' ')
      [ "$(wc -w <<<"$bpids")" = "$c" ] && break
    done
    # shellcheck disable=SC2086
    b0=$("${TOOL[@]}" cpu $bpids)
    n0=$(q "SELECT count(*) FROM records")
    wal0=$(q "SELECT pg_current_wal_lsn()")
    sleep $((pgsecs - 3))
    # shellcheck disable=SC2086
    b1=$("${TOOL[@]}" cpu $bpids)
    n1=$(q "SELECT count(*) FROM records")
    wal=$(q "SELECT pg_wal_lsn_diff(pg_current_wal_lsn(), '$wal0')")
    aux1=$("${TOOL[@]}" cpu "${aux[@]}")
    wait "$pb"
    tps=$(grep -o 'tps = [0-9.]*' "$work/pgbench$c.out" | head -1)
    lat=$(grep -o 'latency average = [0-9.]* ms' "$work/pgbench$c.out" | head -1)
    python3 - "$b0" "$b1" "$n0" "$n1" "$c" "$tps" "$lat" "$aux0" "$aux1" "$wal" <<'EOF'
import json, sys
b0, b1 = json.loads(sys.argv[1]), json.loads(sys.argv[2])
n = int(sys.argv[4]) - int(sys.argv[3])
cpu = sum(v - b0.get(p, 0.0) for p, v in b1.items())
a0, a1 = json.loads(sys.argv[8]), json.loads(sys.argv[9])
aux = sum(v - a0.get(p, 0.0) for p, v in a1.items())
print(f"  pgbench {sys.argv[5]} client(s): {sys.argv[6]} records/s ({sys.argv[7]}); backend CPU {cpu / max(n, 1) * 1e3:.2f} ms per record "
      f"over {n} records in the middle of the run, WAL {float(sys.argv[10]) / max(n, 1) / 1024:.0f} KiB per record; "
      f"writer processes {aux:.2f} s over the whole run (shared with other databases)")
EOF
  done
  stop_cluster
fi

# ---------------------------------------------------------------------------------------
if want 6; then
  say "== 6. a gearbox table job on one of 2 replicas, its replica SIGKILLed mid-job"
  start_cluster 2 tablejob
  admin=$(key admin)
  curl -fsS -o /dev/null -H "Authorization: Bearer $admin" -H 'Content-Type: application/toml' \
    --data-binary @configs/gearboxes/planetary-sun-in.toml -X PUT "$CLUSTER_URL/v1/gearboxes/tj"
  holder=""
  for _ in $(seq 300); do
    holder=$(q "SELECT claimed_by FROM gearboxes WHERE id = 'tj' AND status = 'running'")
    [ -n "$holder" ] && break
    sleep 0.1
  done
  # The worker id is "pid<PID>-…": find the replica that runs it.
  hpid=${holder#pid}; hpid=${hpid%%-*}
  victim=""
  for r in $(seq 1 "$CLUSTER_REPLICAS"); do
    [ -f "$CLUSTER_DIR/replica-$r.pid" ] && [ "$(replica_pid "$r")" = "$hpid" ] && victim=$r
  done
  if [ -z "$victim" ]; then
    check "the job is claimed by a replica" 1 "claimed_by '$holder' matches no replica pid"
  else
    sleep 2
    p0=$(q "SELECT progress FROM gearboxes WHERE id = 'tj'")
    touch "$CLUSTER_DIR/hold-$victim"
    kill -9 "$hpid"
    tkill=$(now)
    say "  replica $victim (pid $hpid) held the job at progress $p0; SIGKILLed (kept down)"
    for _ in $(seq 1200); do
      [ "$(q "SELECT status FROM gearboxes WHERE id = 'tj'")" = ready ] && break
      sleep 0.1
    done
    read -r status attempts by < <(q "SELECT status || ' ' || attempts || ' ' || COALESCE(claimed_by, '-') FROM gearboxes WHERE id = 'tj'")
    took=$(since "$tkill")
    check "taken over and finished by the other replica" \
      "$([ "$status" = ready ] && [ "$attempts" = 2 ] && [ "$by" != "$holder" ] && echo 0 || echo 1)" \
      "status $status after $took s, attempts $attempts, finished by $by (killed: $holder)"
    ready=$(curl -fsS -H "Authorization: Bearer $admin" "$CLUSTER_URL/v1/gearboxes/tj" | python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["status"], d["progress"])')
    check "the API shows it ready" "$([ "$ready" = "ready 1.0" ] && echo 0 || echo 1)" "$ready"
  fi
  stop_cluster
fi

if [ "$failed" = 0 ]; then say "== all checks passed"; else say "== some checks FAILED"; fi
exit "$failed"
