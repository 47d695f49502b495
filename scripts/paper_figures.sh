#!/usr/bin/env bash
# Regenerate the figures and data behind docs/findings.md (the first seed's Figures 2, 3–14, 17).
# Usage: scripts/paper_figures.sh   (from the repo root; about a minute on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
B=target/release/gearwear
F=docs/figures
mkdir -p "$F/data"
# Figure 2: bifurcation diagrams of x1 and xrp1 for five wear degrees.
for ea in 0.1 0.2 0.4 0.8 1; do
  $B bifurcation --ea "$ea" --omega1 0.01:5:0.01 --elements x1,xrp1 \
    --plot "$F/fig2_ea$ea.png" --summary "$F/data/fig2_ea${ea}_summary.csv"
done
# Figures 3–14: one run each at ea = 0.8 along Ω1 (time history, phase portrait, Poincaré, spectrum).
for w in 0.3 0.5 0.8 1.0 1.3 1.5 1.6 1.8 1.9 2.2 2.5 3.0; do
  d=$(mktemp -d)
  $B simulate --omega1 "$w" --ea 0.8 --plot "$d" --output "$F/data/run_ea0.8_omega$w.json" 2>/dev/null
  cp "$d/overview.png" "$F/runs_ea0.8_omega$w.png"
  rm -rf "$d"
done
# Figure 17: line amplitudes of x1 versus wear at Ω1 = 1.
$B wear-lines --omega1 1 --ea 0.1:1:0.05 --plot "$F/fig17_lines_vs_wear.png" --output "$F/data/fig17_lines_vs_wear.csv" >/dev/null
# The same with a worn planetary stage (planetary error 0.3 instead of 0.1): finding 8's f3 cue.
$B wear-lines --omega1 1 --ea 0.1:1:0.05 --planetary-error 0.3 --output "$F/data/fig17_planetary0.3.csv" >/dev/null
echo "figures in $F"
