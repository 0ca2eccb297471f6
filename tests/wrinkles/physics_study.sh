#!/usr/bin/env bash
# `upscale --physics` (docs/wrinkles.md, "The physics pass") against the truth: wrinkle ratio,
# correlation, D change and vertex RMSE beside Catmull-Rom's (tests/wrinkles/stats.py), each run
# upscaled with its own material (meta.json: the artist knows the cloth) and 30 fps.
#   tests/wrinkles/physics_study.sh val|heldout [OUTDIR] [upscale options...]
# val: the seed-6 validation runs (choices are made here); heldout: drop, drape, drop-table at
# seed 8 and flag-sphere, twist-zero-g at seed 1000 (frozen before the wrinkle work; never
# used for a choice). Needs NumPy. ≈ 4 min per set on 2 cores.
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
SET=$1; OUT=${2:-target/physics-study}; shift $(( $# < 2 ? $# : 2 ))
HERE=$(dirname "$0")
case $SET in
  val) runs="drop:6:60 drop-table:6:60 drape:6:150 flag:6:150 twist:6:150 twist-materials:6:150";;
  heldout) runs="drop:8:60 drape:8:150 drop-table:8:60 flag-sphere:1000:120 twist-zero-g:1000:120";;
  *) echo "usage: $0 val|heldout [OUTDIR] [upscale options...]" >&2; exit 2;;
esac
pairs=""; mkdir -p "$OUT/physics"
for r in $runs; do
  IFS=: read -r scen seed frames <<<"$r"
  run=$OUT/runs/$scen-$seed
  vary=$seed; [ "$seed" = 1000 ] && vary=0
  [ -f "$run/hr/geometry.npy" ] || "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$frames" \
    --seed "$seed" --vary "$vary" --out "$run" >/dev/null 2>&1 || { echo "simulate failed: $run" >&2; exit 1; }
  mat=$(python3 -c "import json,sys; m=json.load(open(sys.argv[1]))['material']; print(m['name'] if isinstance(m, dict) else 'cotton')" "$run/hr/meta.json")
  "$BIN" upscale "$run/lr" --out "$OUT/physics/$scen-$seed" --format npy --physics --material "$mat" "$@" \
    >/dev/null 2>"$OUT/physics/$scen-$seed.log" || { cat "$OUT/physics/$scen-$seed.log" >&2; exit 1; }
  pairs="$pairs $run:$OUT/physics/$scen-$seed"
done
python3 "$HERE/stats.py" physics $pairs
