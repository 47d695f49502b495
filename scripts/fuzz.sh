#!/usr/bin/env bash
# Fuzz every input parser, one target at a time: scripts/fuzz.sh [seconds-per-target] [target...]
#
#   scripts/fuzz.sh            # 600 s each for all targets (the documented long run)
#   scripts/fuzz.sh 60 wav     # one target, one minute
#
# Needs cargo-fuzz (`cargo install cargo-fuzz`). It runs on the stable toolchain: cargo fuzz's
# nightly flags are allowed with RUSTC_BOOTSTRAP=1. The targets are built once (`cargo fuzz
# build`) and the built binaries run directly, so editing the source during a run does not
# rebuild in the middle of it. Environment:
#   FUZZ_SANITIZER   address (default) or none
#   FUZZ_TARGET_DIR  build directory (default ./target-fuzz-build, git-ignored)
#   FUZZ_LOG_DIR     where the logs and summary.txt go (default fuzz/logs, git-ignored)
#   FUZZ_CMIN        1 (default): minimise fuzz/corpus/<target> after a clean run (libFuzzer
#                    -merge=1, what `cargo fuzz cmin` runs); fuzz/seeds/<target> is kept as is
# Limits per run: 2 GiB RSS, no single allocation over 512 MiB, 10 s per input. A crash,
# panic, timeout or out-of-memory stops that target and leaves the input in
# fuzz/artifacts/<target>/ (docs/reliability/fuzzing.md says what to do with it).
# Exit status: 0 when every target ran its time without a finding, 1 otherwise.
set -uo pipefail
cd "$(dirname "$0")/.."

secs="${1:-600}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(json_body csv csv_gz f32_raw wav model_config quality)
fi
sanitizer="${FUZZ_SANITIZER:-address}"
tdir="${FUZZ_TARGET_DIR:-$PWD/target-fuzz-build}"
logs="${FUZZ_LOG_DIR:-$PWD/fuzz/logs}"
mkdir -p "$logs"
summary="$logs/summary.txt"
limits=(-rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=10)

RUSTC_BOOTSTRAP=1 nice -n 10 cargo fuzz build --sanitizer "$sanitizer" --target-dir "$tdir" ||
  exit 1
bindir="$tdir/$(rustc -vV | sed -n 's/^host: //p')/release"

failed=0
for t in "${targets[@]}"; do
  log="$logs/$t.log"
  corpus="fuzz/corpus/$t"   # what the runs found (minimised); new inputs go here
  seeds="fuzz/seeds/$t"     # hand-made seeds, read only
  mkdir -p "fuzz/artifacts/$t" "$corpus"
  corpus_before="$(find "$corpus" -type f | wc -l)"
  start="$(date -u +%Y-%m-%dT%H:%M:%SZ)"
  nice -n 19 "$bindir/$t" -artifact_prefix="fuzz/artifacts/$t/" -max_total_time="$secs" \
    "${limits[@]}" -print_final_stats=1 "$corpus" "$seeds" >"$log" 2>&1
  rc=$?
  done_line="$(grep -E '^#[0-9]+[[:space:]]+DONE' "$log" | tail -1)"
  [ -n "$done_line" ] || done_line="$(grep -E '^#[0-9]+[[:space:]]' "$log" | tail -1)"
  execs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)"
  eps="$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)"
  rss="$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)"
  finding="none"
  if [ $rc -ne 0 ]; then
    finding="$(grep -m1 -E 'panicked at|ERROR: libFuzzer|==ERROR' "$log" || echo "exit $rc")"
    finding="$finding $(grep -m1 -E '^Test unit written to' "$log")"
    failed=1
  fi
  corpus_after="$(find "$corpus" -type f | wc -l)"
  if [ "${FUZZ_CMIN:-1}" = 1 ] && [ $rc -eq 0 ]; then
    # Minimise: merge the corpus into an empty folder (keeps one input per feature), swap.
    tmp="fuzz/artifacts/cmin-$t"
    rm -rf "$tmp" && mkdir -p "$tmp"
    if nice -n 19 "$bindir/$t" -merge=1 "${limits[@]}" "$tmp" "$corpus" >"$logs/$t.cmin.log" 2>&1
    then
      rm -rf "$corpus" && mv "$tmp" "$corpus"
    else
      rm -rf "$tmp"
    fi
  fi
  corpus_min="$(find "$corpus" -type f | wc -l)"
  corpus_kb="$(du -sk "$corpus" | cut -f1)"
  echo "$start $t secs=$secs sanitizer=$sanitizer exit=$rc execs=${execs:-?}" \
    "exec/s=${eps:-?} peak_rss_mb=${rss:-?}" \
    "corpus=$corpus_before->$corpus_after->cmin $corpus_min files/${corpus_kb}KB" \
    "| $done_line | finding: $finding" | tee -a "$summary"
done
exit $failed
