#!/usr/bin/env bash
# `upscale --physics` (docs/research/wrinkles.md, "The physics pass") against the truth: wrinkle
# ratio, correlation, D change and vertex RMSE beside Catmull-Rom's (research/wrinkles/stats.py), each run
# upscaled with its own material and gravity (meta.json: the artist knows the cloth) and 30 fps.
# `anisocb eval --physics --runs RUN...` reports the same pass with every other metric.
#   [PINS=1] research/wrinkles/physics_study.sh val|heldout [OUTDIR] [upscale options...]
# PINS=1 names each scene's held edges as its artist would (--physics-pin: the flag's top row,
# the twist's two ends, the drape's corners; the drops hold nothing) and its floor
# (--physics-ground 0 under the drops and the drape).
# val: the seed-6 validation runs (choices are made here); heldout: drop, drape, drop-table at
# seed 8 and flag-sphere, twist-zero-g at seed 1000 (frozen before the wrinkle work; never
# used for a choice). Needs NumPy. ≈ 4 min per set on 2 cores.
set -euo pipefail
BIN=${BIN:-target/release/anisocb}
SET=$1; OUT=${2:-target/physics-study}; shift $(( $# < 2 ? $# : 2 ))
HERE=$(dirname "$0")
case $SET in
  val) runs="drop:6:60:none:0 drop-table:6:60:none:0 drape:6:150:corners:0 flag:6:150:top:- twist:6:150:left,right:-
             twist-materials:6:150:left,right:-";;
  heldout) runs="drop:8:60:none:0 drape:8:150:corners:0 drop-table:8:60:none:0 flag-sphere:1000:120:top:-
                 twist-zero-g:1000:120:left,right:-";;
  *) echo "usage: $0 val|heldout [OUTDIR] [upscale options...]" >&2; exit 2;;
esac
pairs=""; mkdir -p "$OUT/physics"
for r in $runs; do
  IFS=: read -r scen seed frames pins ground <<<"$r"
  floor=(); [ "$ground" = - ] || floor=(--physics-ground "$ground")
  [ "${PINS:-0}" = 1 ] || { pins=none; floor=(); }
  run=$OUT/runs/$scen-$seed
  vary=$seed; [ "$seed" = 1000 ] && vary=0
  [ -f "$run/hr/geometry.npy" ] || "$BIN" simulate --scenario "$scen" --res 32x32 --pair --frames "$frames" \
    --seed "$seed" --vary "$vary" --out "$run" >/dev/null 2>&1 || { echo "simulate failed: $run" >&2; exit 1; }
  # The run's material (cotton where it mixes materials) and gravity, as FollowParams::for_run
  # (eval --physics) reads them.
  read -r mat grav < <(python3 -c "import json,sys; j=json.load(open(sys.argv[1])); m=j['material']
print(m['name'] if isinstance(m, dict) else 'cotton', ','.join(map(str, j['gravity_m_per_s2'])))" "$run/hr/meta.json")
  "$BIN" upscale "$run/lr" --out "$OUT/physics/$scen-$seed" --format npy --physics --material "$mat" --gravity="$grav" \
    --physics-pin "$pins" "${floor[@]}" "$@" \
    >/dev/null 2>"$OUT/physics/$scen-$seed.log" || { cat "$OUT/physics/$scen-$seed.log" >&2; exit 1; }
  pairs="$pairs $run:$OUT/physics/$scen-$seed"
done
python3 "$HERE/stats.py" physics $pairs
