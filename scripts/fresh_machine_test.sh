#!/usr/bin/env bash
# The README's test command as on a fresh machine with only the Rust toolchain: run as root, it
# enters a new mount and network namespace (`unshare -mn`) where mosquitto, Chromium,
# chromedriver, PostgreSQL (its binaries, and its server: the namespace's loopback has nothing
# listening), nginx and python3 are hidden by overlay whiteouts, `CI` is unset, and cargo works
# offline from the crates already fetched. The tests that need one of those services must then
# skip with a message, and everything else must pass.
#
#   scripts/fresh_machine_test.sh                      # cargo test --release --workspace
#   scripts/fresh_machine_test.sh cargo test --release --test api -- mqtt
#
# Uses CARGO_TARGET_DIR when set, like the README's command.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "$(id -u)" != 0 ]; then
  echo "needs root (unshare -mn, overlay mounts)" >&2
  exit 2
fi
if [ $# -eq 0 ]; then
  set -- cargo test --release --workspace
fi

# Names hidden from each directory (whiteouts in an overlay's upper layer).
HIDE_BIN="chromium chromium-browser chromedriver psql pg_ctlcluster pg_isready pg_lsclusters nginx python3 python3.11 python3.12 python3.13 python mosquitto mosquitto_pub mosquitto_sub"
HIDE_SBIN="mosquitto nginx"
HIDE_LIB="chromium postgresql"

scratch=$(mktemp -d /tmp/gearwear-fresh.XXXXXX)
trap 'rm -rf "$scratch"' EXIT

exec unshare -mn --propagation private bash -s "$scratch" "$HIDE_BIN" "$HIDE_SBIN" "$HIDE_LIB" "$@" <<'INNER'
set -euo pipefail
scratch=$1 hide_bin=$2 hide_sbin=$3 hide_lib=$4
shift 4
ip link set lo up 2>/dev/null || true

# Overlay `dir` with whiteouts (character devices 0:0) for `names`.
hide() {
  local dir=$1 names=$2 tag
  tag=$(echo "$dir" | tr / _)
  mkdir -p "$scratch/$tag/up" "$scratch/$tag/work"
  for n in $names; do mknod "$scratch/$tag/up/$n" c 0 0; done
  mount -t overlay overlay \
    -o "lowerdir=$dir,upperdir=$scratch/$tag/up,workdir=$scratch/$tag/work" "$dir"
}
hide /usr/bin "$hide_bin"
hide /usr/sbin "$hide_sbin"
hide /usr/lib "$hide_lib"

echo "fresh-machine namespace: no network but loopback; hidden:" \
  "$(for p in /usr/sbin/mosquitto /usr/bin/chromium /usr/bin/chromedriver /usr/lib/postgresql \
       /usr/bin/psql /usr/bin/python3; do [ -e "$p" ] && echo "STILL THERE $p" || printf '%s ' "$p"; done)"
if (exec 3<>/dev/tcp/127.0.0.1/5432) 2>/dev/null; then
  echo "PostgreSQL still reachable at 127.0.0.1:5432" >&2
  exit 2
fi
unset CI
export CARGO_NET_OFFLINE=true
# The toolchain (rustup's or the system's) and the system's directories; nothing else.
export PATH="${CARGO_HOME:-$HOME/.cargo}/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
echo "+ $*"
"$@"
INNER
