#!/usr/bin/env bash
# The training truth's wrinkle detail per scenario with coarse tracking, per-vertex tracking and
# none (docs/research/wrinkles.md): seed-6 validation runs, 32x32 -> 64x64. Needs NumPy. ≈ 1 min.
#   research/wrinkles/truth_study.sh [OUTDIR]
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
OUT=${1:-target/wrinkle-study}
HERE=$(dirname "$0")
for scen in drop drop-table drape flag twist twist-materials; do
  frames=150; case $scen in drop|drop-table) frames=60;; esac
  for cfg in "coarse 1000" "vertex 1000" "coarse 0"; do
    set -- $cfg
    run=$OUT/$scen-6-$1-$2
    "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$frames" --seed 6 --vary 6 \
      --tracking "$2" --track "$1" --out "$run" >/dev/null 2>&1
    python3 - "$run" "$HERE" <<'PY'
import os, sys
sys.path.insert(0, sys.argv[2])
import numpy as np
from wrinkle import cr_matrix, detail, load, rms, smooth
run = sys.argv[1]
hr, lr = load(run + "/hr"), load(run + "/lr")
lh, lw = lr.shape[1], lr.shape[2]
u = np.einsum("ay,tyxc,bx->tabc", cr_matrix(lh, hr.shape[1]), lr, cr_matrix(lw, hr.shape[2]))
gap = np.linalg.norm((smooth(hr, lh, lw) - u)[:, 2:-2, 2:-2], axis=-1)
print(f"{os.path.basename(run):28s} truth RMS(D) {1000 * rms(detail(hr, lh, lw)):.3f} mm, "
      f"S(HR) - U(LR) {1000 * float(np.sqrt(np.mean(gap ** 2))):.2f} mm")
PY
  done
done
