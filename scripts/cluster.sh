#!/usr/bin/env bash
# Several `gearwear serve` replicas on one PostgreSQL behind nginx, without containers: the
# topology of docker/compose.yaml on this machine's loopback.
#
#   scripts/cluster.sh [--replicas 2] [--port 0] [--keep-db] [--database NAME] [--dir DIR]
#                      [--seconds 43200] [--max-restarts 20] [--env-file FILE] [--no-build]
#                      [-- serve options…]
#
# 1. a fresh database on the PostgreSQL at 127.0.0.1:5432 (PGUSER, default postgres; trust
#    auth) named gw_cluster_<time>_<pid>, or --database NAME (created if missing, kept);
# 2. the schema made once (`gearwear keys list` migrates) before the replicas start;
# 3. N replicas `gearwear serve --address 127.0.0.1:<free port>` on that database;
# 4. nginx (Debian's; installed with apt-get when missing) as a foreground process with its
#    own prefix, pid, logs and temp files in DIR, configured from docker/nginx.conf with the
#    upstream's server lines replaced by the replicas (same server parameters, same
#    proxy_next_upstream) and `listen` set to 127.0.0.1:--port (0: a free port);
# 5. waits for every replica's /readyz and nginx's, prints the URL and how to make an admin key,
#    writes FILE (shell variables CLUSTER_*, for scripts such as cluster_test.sh);
# 6. supervises: a replica that exits is started again on its port (like compose's
#    `restart: unless-stopped`), at most --max-restarts times per replica — unless DIR/hold-<i>
#    exists (a test holding it down); runs at most --seconds, until Ctrl-C or SIGTERM;
# 7. on exit stops what it started (replicas with SIGTERM, then SIGKILL after 10 s; nginx),
#    drops the database unless --keep-db or --database, removes DIR unless --dir was given.
#
# Only loopback addresses. Serve options after `--` go to every replica (for example
# `-- --allow-stale-table --rate-per-second 1000`).
set -euo pipefail
cd "$(dirname "$0")/.."

replicas=2 lb_port=0 keep_db=false db_name="" dir="" max_seconds=43200 max_restarts=20
env_file="" build=true serve_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --replicas) replicas=$2; shift 2 ;;
    --port) lb_port=$2; shift 2 ;;
    --keep-db) keep_db=true; shift ;;
    --database) db_name=$2; keep_db=true; shift 2 ;;
    --dir) dir=$2; shift 2 ;;
    --seconds) max_seconds=$2; shift 2 ;;
    --max-restarts) max_restarts=$2; shift 2 ;;
    --env-file) env_file=$2; shift 2 ;;
    --no-build) build=false; shift ;;
    --) shift; serve_args=("$@"); break ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "cluster.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
case "$replicas" in ''|*[!0-9]*|0) echo "--replicas must be a positive integer" >&2; exit 2 ;; esac
[ "$replicas" -le 16 ] || { echo "--replicas: at most 16" >&2; exit 2; }

PGUSER=${PGUSER:-postgres}
PSQL=(psql -X -q -v ON_ERROR_STOP=1 -h 127.0.0.1 -p 5432 -U "$PGUSER" -d postgres)
GW_BIN=${GW_BIN:-${CARGO_TARGET_DIR:-target}/release/gearwear}
if $build; then
  cargo build --release --quiet --bin gearwear
fi
[ -x "$GW_BIN" ] || { echo "no binary at $GW_BIN (build it, or set GW_BIN)" >&2; exit 1; }

# nginx: Debian's package, only the binary is used (the system service is left alone).
NGINX=$(command -v nginx || true)
[ -z "$NGINX" ] && [ -x /usr/sbin/nginx ] && NGINX=/usr/sbin/nginx
if [ -z "$NGINX" ]; then
  echo "nginx is missing: apt-get install -y nginx" >&2
  if [ "$(id -u)" != 0 ]; then
    echo "not root: install nginx (Debian package nginx) and run again" >&2
    exit 1
  fi
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq nginx >/dev/null
  NGINX=/usr/sbin/nginx
fi

free_port() {
  python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'
}

own_dir=false
if [ -z "$dir" ]; then
  dir=$(mktemp -d /tmp/gearwear-cluster.XXXXXX)
  own_dir=true
fi
mkdir -p "$dir/nginx"
# nginx's workers run as an unprivileged user when nginx is started by root: they must reach
# the temp directories below.
chmod 755 "$dir" "$dir/nginx"

pids=() ports=() restarts=() nginx_pid="" created_db=false
log() { echo "cluster: $*" >&2; }

cleanup() {
  local rc=$?
  trap - EXIT INT TERM
  local i
  for i in "${!pids[@]}"; do
    if [ -n "${pids[$i]}" ]; then kill -TERM "${pids[$i]}" 2>/dev/null || true; fi
  done
  if [ -n "$nginx_pid" ]; then kill -TERM "$nginx_pid" 2>/dev/null || true; fi
  # SIGTERM lets a replica finish requests in flight; bounded: 10 s, then SIGKILL.
  local t
  for t in $(seq 50); do
    local alive=false
    for i in "${!pids[@]}"; do
      [ -n "${pids[$i]}" ] && kill -0 "${pids[$i]}" 2>/dev/null && ! zombie "${pids[$i]}" && alive=true
    done
    [ -n "$nginx_pid" ] && kill -0 "$nginx_pid" 2>/dev/null && ! zombie "$nginx_pid" && alive=true
    $alive || break
    [ "$t" = 50 ] && for i in "${!pids[@]}"; do kill -KILL "${pids[$i]}" 2>/dev/null || true; done
    sleep 0.2
  done
  wait 2>/dev/null || true
  if $created_db && ! $keep_db; then
    "${PSQL[@]}" -c "DROP DATABASE IF EXISTS $db_name WITH (FORCE)" >/dev/null 2>&1 ||
      log "could not drop database $db_name"
  elif [ -n "$db_name" ]; then
    log "database kept: $db_url"
  fi
  if $own_dir; then rm -rf "$dir"; else log "logs kept in $dir"; fi
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 143' TERM
trap 'exit 130' INT

# A killed child stays a zombie until waited for; kill -0 still succeeds on it.
zombie() { [ "$(awk '{print $3}' "/proc/$1/stat" 2>/dev/null || echo Z)" = Z ]; }

# 1. database
if [ -z "$db_name" ]; then
  db_name="gw_cluster_$(date +%s)_$$"
  "${PSQL[@]}" -c "CREATE DATABASE $db_name" >/dev/null
  created_db=true
else
  case "$db_name" in *[!a-z0-9_]*) echo "--database: lower-case letters, digits, _" >&2; exit 2 ;; esac
  if [ -z "$("${PSQL[@]}" -At -c "SELECT 1 FROM pg_database WHERE datname = '$db_name'")" ]; then
    "${PSQL[@]}" -c "CREATE DATABASE $db_name" >/dev/null
  fi
fi
db_url="postgres://$PGUSER@127.0.0.1:5432/$db_name"

# 2. schema, once: replicas starting together would otherwise all run the migrations.
"$GW_BIN" keys list --database-url "$db_url" >/dev/null

# 3. replicas
start_replica() {
  local i=$1
  "$GW_BIN" serve --address "127.0.0.1:${ports[$i]}" --database-url "$db_url" \
    "${serve_args[@]}" >>"$dir/replica-$i.log" 2>&1 &
  pids[i]=$!
  echo "${pids[$i]}" >"$dir/replica-$i.pid"
}
for i in $(seq 1 "$replicas"); do
  ports[i]=$(free_port)
  restarts[i]=0
  start_replica "$i"
done

# 4. nginx, configured from docker/nginx.conf: the upstream's `server` lines become one per
# replica with the parameters of the first one; `listen` becomes the loopback port. Fails if
# either anchor is missing, so the two files cannot drift apart silently.
[ "$lb_port" = 0 ] && lb_port=$(free_port)
upstreams=""
for i in $(seq 1 "$replicas"); do upstreams+="127.0.0.1:${ports[$i]} "; done
awk -v ups="$upstreams" -v listen="127.0.0.1:$lb_port" -v d="$dir/nginx" '
  BEGIN { n = split(ups, u, " ") }
  /^[[:space:]]*upstream gearwear[[:space:]]*\{/ { print; inup = 1; next }
  inup && /^[[:space:]]*server[[:space:]]/ {
    if (!done) {
      params = $0; sub(/^[[:space:]]*server[[:space:]]+[^[:space:]]+[[:space:]]*/, "", params)
      sub(/;[[:space:]]*$/, "", params)
      for (k = 1; k <= n; k++) printf "    server %s %s;\n", u[k], params
      done = 1; servers++
    }
    next
  }
  inup && /\}/ { inup = 0 }
  /^[[:space:]]*listen[[:space:]]+8080;/ { sub(/8080/, listen); listens++ }
  /^http[[:space:]]*\{/ {
    print
    # Local additions: files inside the temp prefix, and an access log that shows which
    # replica answered each request and whether nginx tried another one.
    print "  client_body_temp_path " d "/body;"
    print "  proxy_temp_path " d "/proxy;"
    print "  fastcgi_temp_path " d "/fastcgi;"
    print "  uwsgi_temp_path " d "/uwsgi;"
    print "  scgi_temp_path " d "/scgi;"
    print "  log_format upstreams \"$msec|$request_method|$request_uri|$status|$upstream_addr|$upstream_status|$request_time\";"
    print "  access_log " d "/access.log upstreams;"
    next
  }
  { print }
  END { if (servers != 1 || listens != 1) { print "docker/nginx.conf: upstream gearwear server lines or `listen 8080;` not found" > "/dev/stderr"; exit 1 } }
' docker/nginx.conf >"$dir/nginx/nginx.conf"
"$NGINX" -p "$dir/nginx/" -c "$dir/nginx/nginx.conf" \
  -g "daemon off; pid $dir/nginx/nginx.pid; error_log $dir/nginx/error.log notice;" \
  >>"$dir/nginx/stdout.log" 2>&1 &
nginx_pid=$!

# 5. readiness, bounded: 30 s for everything.
wait_ready() {
  local url=$1 what=$2
  local t
  for t in $(seq 150); do
    curl -fs -m 2 "$url/readyz" >/dev/null 2>&1 && return 0
    sleep 0.2
  done
  log "$what did not become ready at $url within 30 s; logs in $dir"
  tail -n 20 "$dir"/replica-*.log "$dir/nginx/error.log" >&2 2>/dev/null || true
  return 1
}
for i in $(seq 1 "$replicas"); do wait_ready "http://127.0.0.1:${ports[$i]}" "replica $i"; done
wait_ready "http://127.0.0.1:$lb_port" nginx

url="http://127.0.0.1:$lb_port"
if [ -n "$env_file" ]; then
  {
    echo "CLUSTER_URL=$url"
    echo "CLUSTER_DB=$db_url"
    echo "CLUSTER_DB_NAME=$db_name"
    echo "CLUSTER_DIR=$dir"
    echo "CLUSTER_REPLICAS=$replicas"
    echo "CLUSTER_NGINX_PID=$nginx_pid"
    echo "CLUSTER_PORTS=(${ports[*]})"
    echo "CLUSTER_SUPERVISOR_PID=$$"
  } >"$env_file.tmp"
  mv "$env_file.tmp" "$env_file"
fi
cat >&2 <<EOF
cluster: ready — $replicas replica(s) behind nginx at $url
cluster: replicas: $(for i in $(seq 1 "$replicas"); do printf '%s ' "127.0.0.1:${ports[$i]}(pid ${pids[$i]})"; done)
cluster: database: $db_url   logs: $dir
cluster: admin key:  $GW_BIN keys create --scope admin --database-url $db_url
cluster:   then      curl -H "Authorization: Bearer \$KEY" $url/v1/webhooks
cluster: Ctrl-C stops everything this script started.
EOF

# 6. supervise, bounded in time and in restarts.
deadline=$((SECONDS + max_seconds))
while [ "$SECONDS" -lt "$deadline" ]; do
  if ! kill -0 "$nginx_pid" 2>/dev/null || zombie "$nginx_pid"; then
    log "nginx exited; stopping"
    exit 1
  fi
  for i in $(seq 1 "$replicas"); do
    p=${pids[$i]}
    if [ -n "$p" ] && { ! kill -0 "$p" 2>/dev/null || zombie "$p"; }; then
      st=0
      wait "$p" 2>/dev/null || st=$?
      log "replica $i (pid $p, port ${ports[$i]}) exited with status $st"
      pids[i]=""
    fi
    if [ -z "${pids[$i]}" ] && [ ! -e "$dir/hold-$i" ]; then
      if [ "${restarts[$i]}" -ge "$max_restarts" ]; then
        log "replica $i: $max_restarts restarts used, left down"
        continue
      fi
      restarts[i]=$((restarts[i] + 1))
      start_replica "$i"
      log "replica $i restarted as pid ${pids[$i]} on port ${ports[$i]} (restart ${restarts[$i]})"
    fi
  done
  sleep 0.5
done
log "--seconds $max_seconds reached; stopping"
