# Shared by the scripts that run the release binary on a fresh store (soak.sh,
# schemathesis.sh, service_bench.sh). Sourced, not run:
#
#   . scripts/lib/serve.sh
#   gw_fresh_store sqlite|postgres PREFIX    # sets GW_DIR (a temp dir) and GW_DB (store URL)
#   key=$(gw_key ingest,read)                # a key made by `gearwear keys create`
#   gw_serve LOG [serve options…]            # sets GW_PID, GW_PORT; waits for /readyz
#   trap gw_cleanup EXIT                     # stops the server, drops the database, rm GW_DIR
#
# The server runs with rate limits out of the way (the limiter is tested in tests/api).
GW_BIN=${GW_BIN:-${CARGO_TARGET_DIR:-target}/release/gearwear}
GW_PID="" GW_PG_NAME=""

gw_fresh_store() {
  GW_DIR=$(mktemp -d "/tmp/gearwear-$2.XXXXXX")
  case "$1" in
    sqlite) GW_DB="$GW_DIR/$2.db" ;;
    postgres)
      GW_PG_NAME="gw_$2_$(date +%s)_$$"
      psql -q -h 127.0.0.1 -U postgres -d test -c "CREATE DATABASE $GW_PG_NAME" >/dev/null
      GW_DB="postgres://postgres@127.0.0.1:5432/$GW_PG_NAME" ;;
    *) echo "--store is sqlite or postgres" >&2; exit 2 ;;
  esac
}

gw_key() {
  "$GW_BIN" keys create --scope "$1" --database-url "$GW_DB" 2>/dev/null | grep -o 'gw_[A-Za-z0-9_-]*' | head -1
}

gw_serve() {
  local log=$1
  shift
  GW_PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
  "$GW_BIN" serve --address "127.0.0.1:$GW_PORT" --database-url "$GW_DB" \
    --rate-per-second 100000 --rate-burst 100000 "$@" >"$log" 2>&1 &
  GW_PID=$!
  for _ in $(seq 150); do
    curl -fs "http://127.0.0.1:$GW_PORT/readyz" >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  echo "gearwear serve did not become ready:" >&2
  cat "$log" >&2
  exit 1
}

gw_cleanup() {
  if [ -n "$GW_PID" ]; then
    kill "$GW_PID" 2>/dev/null || true
    wait "$GW_PID" 2>/dev/null || true
  fi
  if [ -n "$GW_PG_NAME" ]; then
    psql -q -h 127.0.0.1 -U postgres -d test -c "DROP DATABASE IF EXISTS $GW_PG_NAME WITH (FORCE)" >/dev/null || true
  fi
  rm -rf "${GW_DIR:-}"
}
