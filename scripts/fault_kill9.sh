#!/usr/bin/env bash
# kill -9 in the middle of concurrent ingests, several times, then the checks: the long
# version of the `faults::kill9_mid_ingest_*` tests (same code: `faults::kill9_long`).
#
#   scripts/fault_kill9.sh                                   # SQLite, 2000 records, 8 clients, 5 kills
#   BACKEND=postgres RECORDS=1000 KILLS=3 scripts/fault_kill9.sh
#
# Each phase starts the real binary (`gearwear serve`) on the same database, streams the
# records that have no answer yet (and every fifth answered one again) from CLIENTS
# concurrent clients, each record with its own Idempotency-Key, and SIGKILLs the process once
# RECORDS/(KILLS+1) of its requests got a 201 while others are in flight. After the last phase
# (no kill) and one more restart the run checks every 201 against the store, counts rows per
# body hash and per idempotency key, and runs `PRAGMA integrity_check` (SQLite) or amcheck's
# `bt_index_check` over every index (PostgreSQL, a fresh database on 127.0.0.1:5432).
# Prints the figures (`Kill9Figures`); exits non-zero if any check fails.
set -euo pipefail
cd "$(dirname "$0")/.."
export GEARWEAR_FAULT_BACKEND=${BACKEND:-sqlite}
export GEARWEAR_FAULT_RECORDS=${RECORDS:-2000}
export GEARWEAR_FAULT_CLIENTS=${CLIENTS:-8}
export GEARWEAR_FAULT_KILLS=${KILLS:-5}
echo "== fault_kill9 $(date -u +%Y-%m-%dT%H:%M:%SZ) backend=$GEARWEAR_FAULT_BACKEND records=$GEARWEAR_FAULT_RECORDS clients=$GEARWEAR_FAULT_CLIENTS kills=$GEARWEAR_FAULT_KILLS"
cargo test --release --test api faults::kill9_long -- --ignored --exact --nocapture 2>&1 |
    sed -n '/^FIGURES/,/^}/p; /panicked/,+3p; /^test result/p'
exit "${PIPESTATUS[0]}"
