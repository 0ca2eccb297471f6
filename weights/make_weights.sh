#!/usr/bin/env bash
# Rebuild the shipped ×2 model (weights/anisocb-x2.npz) and the prior-method baseline used by
# `anisocb eval` (weights/prior-x2.npz) from scratch: simulate the training scenarios, build the
# dataset, train. Run through `make weights` (≈ 25 min on 2 cores).
# Held out of training (used by `anisocb demo` and the README's evaluation): flag-sphere,
# twist-zero-g, and seeds ≥ 7 of every scenario.
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
WORK=${WORK:-target/weights-work}
GEO_STEPS=${GEO_STEPS:-6000}   # GeometryNet (and the prior baseline)
MAP_STEPS=${MAP_STEPS:-1500}   # BoundaryNet, EnhanceNet
FRAMES=${FRAMES:-150}
TRACKING=${TRACKING:-100}
SEEDS=${SEEDS:-"1 2 3"}
TRAIN=(--data "$WORK/data.npz" --config small --lr 5e-4 --patch 16 --batch 32 --seed 1)
rm -rf "$WORK"
mkdir -p "$WORK/runs"
for scen in flag drape twist twist-materials; do
  for seed in $SEEDS; do
    "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$FRAMES" --seed "$seed" \
      --tracking "$TRACKING" --out "$WORK/runs/$scen-$seed"
  done
done
"$BIN" dataset --runs "$WORK"/runs/* --out "$WORK/data.npz" --gamma 0.2 --canny-low 0.12 --canny-high 0.16
# GeometryNet gets more steps than the map nets; `--net all --resume` then trains the map nets
# and bundles the three (a net already at its step count is kept as it is).
"$BIN" train "${TRAIN[@]}" --net geometry --steps "$GEO_STEPS" --out "$WORK/train/geometry"
"$BIN" train "${TRAIN[@]}" --net all --steps "$MAP_STEPS" --resume --out "$WORK/train"
cp "$WORK/train/weights.npz" weights/anisocb-x2.npz
# The prior method (Chen et al. 2018 style): one residual SR net with replicate padding.
"$BIN" train "${TRAIN[@]}" --net geometry --padding replicate --steps "$GEO_STEPS" --out "$WORK/prior"
cp "$WORK/prior/weights.npz" weights/prior-x2.npz
sha256sum weights/anisocb-x2.npz weights/prior-x2.npz
