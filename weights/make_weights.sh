#!/usr/bin/env bash
# Rebuild the shipped ×2 model (weights/anisocb-x2.npz) from scratch: simulate the training
# scenarios, build the dataset, train the three nets. Run through `make weights`.
# Held out of training (used by `anisocb demo` and `anisocb eval`): flag-sphere, twist-zero-g.
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
WORK=${WORK:-target/weights-work}
STEPS=${STEPS:-1500}
FRAMES=${FRAMES:-150}
TRACKING=${TRACKING:-1000}
SEEDS=${SEEDS:-"1 2 3"}
rm -rf "$WORK"
mkdir -p "$WORK/runs"
for scen in flag drape twist twist-materials; do
  for seed in $SEEDS; do
    "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$FRAMES" --seed "$seed" \
      --tracking "$TRACKING" --out "$WORK/runs/$scen-$seed"
  done
done
"$BIN" dataset --runs "$WORK"/runs/* --out "$WORK/data.npz" --gamma 0.2 --canny-low 0.12 --canny-high 0.16
"$BIN" train --data "$WORK/data.npz" --net all --config small --steps "$STEPS" --lr 5e-4 \
  --patch 16 --batch 32 --seed 1 --out "$WORK/train"
cp "$WORK/train/weights.npz" weights/anisocb-x2.npz
sha256sum weights/anisocb-x2.npz
