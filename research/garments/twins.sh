#!/usr/bin/env bash
# How much of a garment's HR truth its LR run fixes (issue 45; docs/research/wrinkles.md,
# "Garments: how much the LR run fixes"): every garment simulated as a pair, then its HR half
# again under the same LR run from a start moved by J metres (`simulate --hr-jitter J`), and
# `twins.py` compares the twin with the truth beside the linear subdivision. No model is run
# or trained. About 8 min a --vary on 2 cores.
#
#   research/garments/twins.sh [OUT]      (default target/garments-twins; VARY=6 by default)
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
OUT=${1:-target/garments-twins}
FRAMES=${FRAMES:-120}
VARY=${VARY:-6}
JITTERS=${JITTERS:-"0.0001 0.001"}
mkdir -p "$OUT"
for g in skirt sleeve cape tablecloth tshirt holed-sheet; do
  run="$OUT/$g-$VARY"
  "$BIN" simulate --scenario "$g" --pair --frames "$FRAMES" --seed "$VARY" --vary "$VARY" --out "$run" --overwrite
  for j in $JITTERS; do
    "$BIN" simulate --scenario "$g" --pair --frames "$FRAMES" --seed "$VARY" --vary "$VARY" --hr-jitter "$j" \
      --out "$run-twin$j" --overwrite
  done
done
python3 "$(dirname "$0")/twins.py" "$OUT"/*-"$VARY"
