#!/usr/bin/env bash
# API fuzzing from the contract: schemathesis against `openapi.yaml` and the
# real release binary, every operation, in three runs:
#   admin  — a key with every scope: all checks (5xx, status codes, content types, headers and
#            bodies against the spec, negative data rejected, positive data accepted);
#   read   — a read-only key: writes must be refused with a documented 403, reads conform;
#   bogus  — a well-formed but unknown key: everything but the public routes is a documented
#            401, and nothing is a 5xx.
#
#   scripts/schemathesis.sh [--short | --long] [--store sqlite|postgres] [--seconds N]
#
# --short (what CI runs): 45 + 12 + 12 s of passes, ≈ 2 min with start-up. --long: 20 minutes
# for the admin run and 5 for each of the others (or --seconds N for the admin run). Any
# failure, and any panic in the server's log, exits non-zero; the schemathesis reports (JUnit +
# NDJSON) and the server log are kept in target/schemathesis/<run>/.
#
# One worker: with several, CPython 3.11's ast module (used by hypothesis to describe
# lambdas) can raise a spurious "AST constructor recursion depth mismatch" (cpython#106905).
#
# Needs python3 with venv (installed on the development and CI machines); schemathesis is
# installed, pinned, into ~/.cache/gearwear/schemathesis-<version> on first use
# (GEARWEAR_ST_VENV overrides).
set -euo pipefail
cd "$(dirname "$0")/.."

mode=short store=sqlite seconds=""
while [ $# -gt 0 ]; do
  case "$1" in
    --short) mode=short; shift ;;
    --long) mode=long; shift ;;
    --store) store=$2; shift 2 ;;
    --seconds) seconds=$2; shift 2 ;;
    *) echo "unknown option $1 (see the header of $0)" >&2; exit 2 ;;
  esac
done
if [ "$mode" = short ]; then
  admin_s=${seconds:-45} other_s=12 examples=40
else
  admin_s=${seconds:-1200} other_s=300 examples=1000
fi

ST_VERSION=4.32.5
# A cache outside the checkout (like cargo's registry), so a fresh clone does not reinstall.
venv=${GEARWEAR_ST_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/gearwear/schemathesis-$ST_VERSION}
if ! "$venv/bin/st" --version 2>/dev/null | grep -q "$ST_VERSION"; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check "schemathesis==$ST_VERSION"
fi

cargo build --release --quiet --bin gearwear
. scripts/lib/serve.sh
out=target/schemathesis
rm -rf "$out" && mkdir -p "$out"
gw_fresh_store "$store" st
trap gw_cleanup EXIT
admin=$(gw_key admin)
read=$(gw_key read)
bogus="gw_0123456789abcdef_$(printf 'x%.0s' $(seq 43))"
gw_serve "$out/server.log"
pid=$GW_PID port=$GW_PORT
echo "schemathesis $ST_VERSION, $mode, store $store, server pid $pid on port $port, $(date -u +%FT%TZ)"

status=0
run() { # name key seconds [extra st options]
  local name=$1 key=$2 secs=$3
  shift 3
  mkdir -p "$out/$name"
  echo "== $name key, up to $secs s"
  local t0=$SECONDS
  if ! GEARWEAR_ST_RUN=$name "$venv/bin/st" --config-file scripts/schemathesis.toml run openapi.yaml \
      --url "http://127.0.0.1:$port" -H "Authorization: Bearer $key" \
      --max-time "$secs" --max-examples "$examples" --seed 20261122 --workers 1 \
      --request-timeout 60 --no-color \
      --report junit,ndjson --report-dir "$out/$name" "$@" >"$out/$name/output.txt" 2>&1; then
    status=1
    echo "   FAILED (full output: $out/$name/output.txt)"
  fi
  # The summary block: operations, test cases, checks passed/failed.
  sed -n '/SUMMARY/,$p' "$out/$name/output.txt" | grep -v '^$' | head -30
  echo "   wall $((SECONDS - t0)) s"
}
run admin "$admin" "$admin_s" --checks all
run read "$read" "$other_s" --checks not_a_server_error,status_code_conformance,content_type_conformance,response_headers_conformance,response_schema_conformance --mode positive
run bogus "$bogus" "$other_s" --checks not_a_server_error,status_code_conformance,content_type_conformance,response_headers_conformance,response_schema_conformance --mode positive

if grep -q "panicked" "$out/server.log"; then
  echo "the server panicked:"; grep -n -A3 "panicked" "$out/server.log" | head -40
  status=1
fi
kill -0 "$pid" 2>/dev/null || { echo "the server died during the run"; status=1; }
echo "exit $status"
exit $status
