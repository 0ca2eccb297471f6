#!/usr/bin/env bash
# How much of the HR truth's fine detail its LR run fixes (docs/research/wrinkles.md, "How much
# of the detail the LR run fixes"). Seed-6 validation runs, coarse tracking 1000 1/s², 32x32 -> 64x64.
# For each scenario the pair is simulated once, then its HR run again under the same LR run:
#   twin     rest positions jittered by 1 µm, 0.1 mm, 1 mm (`simulate --hr-jitter J`);
#   restart  the HR run put back on the LR surface at frame F (`--hr-restart F`);
#   blind    the HR run knows only the LR run: no colliders, no wind (`--hr-blind`).
# Prints the correlation of the wrinkle detail D with the original HR run's (research/wrinkles/
# determinacy.py). Needs NumPy. ≈ 8 min on 2 cores.
#   research/wrinkles/determinacy_study.sh [OUTDIR]
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
OUT=${1:-target/determinacy-study}
PY="python3 $(dirname "$0")/determinacy.py"
sim() { # sim SCENARIO FRAMES DIR [OPTIONS]
  local scen=$1 frames=$2 dir=$3; shift 3
  [ -f "$dir/hr/geometry.npy" ] || "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$frames" \
    --seed 6 --vary 6 "$@" --out "$dir" >/dev/null 2>&1 || { echo "simulate failed: $dir" >&2; exit 1; }
}
for scen in drop drop-table drape flag twist twist-materials; do
  frames=150 restart=60; case $scen in drop|drop-table) frames=60 restart=20;; esac
  base=$OUT/$scen-6
  sim "$scen" "$frames" "$base"
  for j in 1e-6 1e-4 1e-3; do
    sim "$scen" "$frames" "$base-jitter-$j" --hr-jitter "$j"
    $PY twin "$base" "$base-jitter-$j"
  done
  sim "$scen" "$frames" "$base-restart-$restart" --hr-restart "$restart"
  $PY restart "$base" "$base-restart-$restart" "$restart"
  sim "$scen" "$frames" "$base-blind" --hr-blind
  $PY blind "$base" "$base-blind"
done
