#!/usr/bin/env bash
# The closed loop on the real SpectraQuest records with their own gearbox
# description: a table for the description, then `gearwear calibrate` on every healthy and
# broken-tooth record, one line each: f1, effects claimed, error before → after, wear before →
# after, the two tooth-damage candidates (ΔBIC, their shaft's TSA FM4, eligible), the level-
# over-time features (`unexplained_in_time`: kind, runs, size), null spread / claim margin.
#
#   scripts/closed_loop_spectraquest.sh [CHANNEL]     # default a1
#
# Env: GFD_DIR (default ../shared/data/spectraquest-gfd), KEEP=1 keeps the reports (JSON) and
# plots in the printed directory. Sample rate 12 900 Hz (see the data's README); no
# `--shaft-hz`: f1 is found in the spectrum.
set -euo pipefail
cd "$(dirname "$0")/.."
CH=${1:-a1}
DATA=${GFD_DIR:-../shared/data/spectraquest-gfd}
TARGET=${CARGO_TARGET_DIR:-target}
cargo build --release --quiet --bin gearwear
BIN=$TARGET/release/gearwear
GB=configs/gearboxes/spectraquest-gfd.toml
work=$(mktemp -d /tmp/gearwear-cl-sq.XXXXXX)
[ -n "${KEEP:-}" ] || trap 'rm -rf "$work"' EXIT
"$BIN" precompute --gearbox "$GB" --input-hz 27:33:1.5 --output "$work/table.json" >/dev/null 2>&1
echo "# closed loop on SpectraQuest, channel $CH, $(git rev-parse --short HEAD 2>/dev/null || echo '?'), $(date -u +%FT%TZ)"
for f in h30hz0 h30hz20 h30hz40 h30hz60 h30hz80 b30hz0 b30hz20 b30hz40 b30hz60 b30hz80; do
  [ -f "$DATA/$f.csv.gz" ] || continue
  t0=$(date +%s.%N)
  "$BIN" calibrate --gearbox "$GB" --table "$work/table.json" --input "$DATA/$f.csv.gz" \
    --sample-rate 12900 --column "$CH" --output "$work/$f.json" >/dev/null 2>"$work/$f.err" ||
    { echo "$f: calibrate failed: $(tail -1 "$work/$f.err")"; continue; }
  secs=$(python3 -c "import time; print(f'{time.time() - $t0:.1f}')")
  python3 - "$work/$f.json" "$f" "$secs" <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
eff = ', '.join(
    e['name'] + ' (' + ', '.join(f"{k} {v:.4g}" for k, v in e['parameters'].items()) + ')'
    for e in r['effects']) or 'none'
wb, wa = r['wear_before'], r['wear_after']
teeth = '; '.join(
    f"{c['effects'][0]['labels'].get('gear', '?')} ΔBIC {c['delta_bic']:.0f}"
    + (f", TSA FM4 {c['tsa_fm4']:.2f}" if c.get('tsa_fm4') is not None else ', no TSA')
    + ('' if c['eligible'] else ' (not eligible)')
    for c in r['candidates'] if c['name'] == 'tooth-damage')
timef = '; '.join(
    f"{t['kind']} ({len(t['times_s'])}, {t['size_db']:+.1f} dB)" if t['times_s']
    else f"{t['kind']} ({t['size_db']:+.1f} dB)"
    for t in r.get('unexplained_in_time', [])) or 'none'
print(f"{sys.argv[2]:8} f1 {r['f1_hz']:.1f} Hz | {eff} | error {r['error_before']:.2f} → {r['error_after']:.2f} dB"
      f" | ea {wb['ea']:.3f} → {wa['ea']:.3f} [{wa['ea_lower']:.3f}, {wa['ea_upper']:.3f}] ({wa['method']})"
      f" | tooth: {teeth} | in time: {timef} | null spread {r['null_spread']:.1f}, margin {r['claim_margin']:.0f} | {sys.argv[3]} s")
EOF
done
[ -z "${KEEP:-}" ] || echo "reports in $work"
