#!/usr/bin/env bash
# The held-out garment runs (issue 45) and anisocb on them: `anisocb simulate` pairs of every
# garment, then `anisocb eval --meshes --physics` (each run's body as the collider, its pins.txt
# as the held vertices, its fps). About 4 min on 2 cores.
#
# Chosen on 2026-11-26, before any model was trained on garments, and never tuned on:
#   held out   the garment `tshirt` (every seed), and --vary 7 and above of every garment;
#   validation --vary 6 of every garment, for choices made after training;
#   training   --vary 1..5 of skirt, sleeve, cape, tablecloth and holed-sheet.
#
#   research/garments/heldout.sh [OUT]      (default target/garments-heldout)
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
OUT=${1:-target/garments-heldout}
FRAMES=${FRAMES:-120}
VARY=${VARY:-7}
mkdir -p "$OUT"
for g in skirt sleeve cape tablecloth tshirt holed-sheet; do
  "$BIN" simulate --scenario "$g" --pair --frames "$FRAMES" --seed "$VARY" --vary "$VARY" --out "$OUT/$g-$VARY"
done
"$BIN" eval --meshes "$OUT"/*-"$VARY" --physics --out "$OUT/eval"
cat "$OUT/eval/meshes.md"
