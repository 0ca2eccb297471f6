#!/bin/bash
# The checks that need an NVIDIA GPU, for a machine that has one but no Rust toolchain.
# Build on any x86-64 Linux machine, copy the two binaries over, run there:
#   cargo build --release --features cuda
#   cargo test --release --features cuda --no-run --test cuda_parity   # prints the test binary's path
#   benches/gpu-check.sh target/release/anisocb target/release/deps/cuda_parity-HASH [OUT_DIR]
# It runs tests/cuda_parity.rs on the GPU, `anisocb bench --device cuda` (the conv table, then the
# shipped bundle device-resident by chunk size), the demo on cpu and cuda twice each (output
# difference and upscaling time), `upscale` of a 64x64 flag (48 frames) on cpu and on cuda at
# chunks of 16 and 1 (ms a frame from upscale.json, largest vertex difference), the same bundle in
# PyTorch (benches/gpu/torch_peer.py, where torch is installed), and 100 training steps of both
# configs on cpu and cuda, three pairs interleaved (samples/s, the weights' difference); last, each
# target of docs/gpu.md met or missed (training: the median of the three pairs' ratios). Needs
# python3 with numpy. About 2.5 minutes on an H200 machine.
# With BASE_BIN=path/to/an/older/anisocb (built with --features cuda), it also times cuda training
# of the older binary against this one, three pairs interleaved per config (samples/s, the median
# ratio), and says whether the weights after 100 steps have the same bits: a change meant to keep
# the bits (e.g. fused launches) is then measured and checked in the same run. About 1 minute more.
set -u
BIN=${1:?usage: gpu-check.sh ANISOCB_BIN CUDA_PARITY_TEST_BIN [OUT_DIR]}
PARITY=${2:?usage: gpu-check.sh ANISOCB_BIN CUDA_PARITY_TEST_BIN [OUT_DIR]}
OUT=${3:-gpu-check-out}
TMP=$(mktemp -d)
mkdir -p "$OUT"
export LD_LIBRARY_PATH=/usr/local/cuda/lib64${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
echo "cores: $(nproc); GPU: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader)"
"$PARITY" --test-threads 1 --nocapture > "$OUT/parity.log" 2>&1
echo "cuda_parity: $(grep '^test result' "$OUT/parity.log") ($(grep -c skipped "$OUT/parity.log") skipped lines)"
"$BIN" bench --device cuda 2>&1 | tee "$OUT/bench.log"
for d in cpu cuda cpu cuda; do
  "$BIN" demo --device "$d" --out "$TMP/demo-$d" > "$OUT/demo-$d.log" 2>&1 || { echo "demo --device $d failed: $OUT/demo-$d.log"; exit 1; }
  grep -h "upscaling" "$TMP/demo-$d/metrics.md"
done
python3 - "$TMP" <<'PY'
import glob, sys, numpy as np
def load(p): return np.array([[float(x) for x in l.split()[1:4]] for l in open(p) if l.startswith('v ')])
t = sys.argv[1]
worst = max(np.abs(load(a) - load(a.replace('demo-cpu', 'demo-cuda'))).max()
            for a in sorted(glob.glob(t + '/demo-cpu/anisocb/*.obj')))
print(f'demo: largest |cpu - cuda| vertex coordinate difference {worst:.2e} m')
PY
"$BIN" simulate --scenario flag --res 64x64 --frames 48 --seed 3 --out "$TMP/flag64" > /dev/null 2>&1
for run in "cpu 8" "cuda 16" "cuda 1" "cpu 8" "cuda 16" "cuda 1"; do
  set -- $run
  "$BIN" upscale "$TMP/flag64" --out "$TMP/up-$1-$2" --device $1 --batch $2 --overwrite > "$OUT/upscale-$1-$2.log" 2>&1 \
    || { echo "upscale --device $1 --batch $2 failed: $OUT/upscale-$1-$2.log"; exit 1; }
  echo "upscale 64x64 -> 128x128, 48 frames, $1 chunk $2: $(grep -o '"ms_per_frame": *[0-9.]*' "$TMP/up-$1-$2/upscale.json") (whole command: read, nets, compose, write)"
done
python3 - "$TMP" <<'PY'
import sys, numpy as np
t = sys.argv[1]
a = np.load(t + '/up-cpu-8/geometry.npy')
for chunk in (16, 1):
    d = np.abs(a - np.load(t + f'/up-cuda-{chunk}/geometry.npy')).max()
    print(f'upscale 64x64 flag: largest |cpu - cuda chunk {chunk}| HR coordinate difference {d * 1e3:.4f} mm')
PY
python3 -c "import torch" 2>/dev/null && python3 "$(dirname "$0")/gpu/torch_peer.py" "$(dirname "$0")/../weights/anisocb-x2.npz" 2>&1 | tee "$OUT/torch.log"
"$BIN" simulate --scenario flag --res 32x32 --pair --frames 60 --seed 1 --vary 1 --out "$TMP/runs/flag-1" > /dev/null 2>&1
"$BIN" dataset --runs "$TMP"/runs/* --out "$TMP/data.npz" --input-frame cloth-frame > /dev/null 2>&1
for cfg in small paper; do
  for rep in 1 2 3; do  # cpu, cuda, cpu, cuda, ...: the ratio of each pair
    for d in cpu cuda; do
      "$BIN" train --data "$TMP/data.npz" --config $cfg --net geometry --steps 100 --batch 32 --patch 16 --device $d \
        --val-every 1000 --checkpoint-every 1000 --out "$TMP/train-$d-$cfg-$rep" > "$OUT/train-$d-$cfg-$rep.log" 2>&1
      echo "train $cfg on $d (pair $rep): $(tr '\r' '\n' < "$OUT/train-$d-$cfg-$rep.log" | grep -o '[0-9.]* samples/s' | tail -1)"
    done
  done
  python3 - "$TMP/train-cpu-$cfg-1/weights.npz" "$TMP/train-cuda-$cfg-1/weights.npz" $cfg <<'PY'
import sys, numpy as np
a, b = np.load(sys.argv[1]), np.load(sys.argv[2])
keys = [k for k in a.files if isinstance(a[k], np.ndarray) and a[k].dtype.kind == 'f']
d = max(float(np.abs(a[k] - b[k]).max()) for k in keys)
m = max(float(np.abs(a[k]).max()) for k in keys)
print(f'train {sys.argv[3]}: weights after 100 steps, largest |cpu - cuda| {d:.2e} (largest weight {m:.2e})')
PY
done
if [ -n "${BASE_BIN:-}" ]; then
  for cfg in small paper; do
    for rep in 1 2 3; do  # base, this, base, this, ...
      for side in base this; do
        b=$BIN; [ $side = base ] && b=$BASE_BIN
        "$b" train --data "$TMP/data.npz" --config $cfg --net geometry --steps 100 --batch 32 --patch 16 --device cuda \
          --val-every 1000 --checkpoint-every 1000 --out "$TMP/ab-$side-$cfg-$rep" > "$OUT/ab-$side-$cfg-$rep.log" 2>&1
      done
    done
    python3 - "$TMP" "$OUT" $cfg <<'PY'
import re, sys, numpy as np
t, out, cfg = sys.argv[1:]
def sps(side, rep):
    v = re.findall(r'([0-9.]+) samples/s', open(f'{out}/ab-{side}-{cfg}-{rep}.log').read().replace('\r', '\n'))
    return float(v[-1]) if v else float('nan')
rs = sorted(sps('this', k) / sps('base', k) for k in (1, 2, 3))
a, b = np.load(f'{t}/ab-base-{cfg}-1/weights.npz'), np.load(f'{t}/ab-this-{cfg}-1/weights.npz')
keys = [k for k in a.files if a[k].dtype.kind == 'f']
same = all(a[k].shape == b[k].shape and a[k].tobytes() == b[k].tobytes() for k in keys)
print(f'train {cfg} on cuda, this binary / BASE_BIN: {rs[1]:.3f}x samples/s (median of 3 pairs: '
      + ', '.join(f'{r:.3f}' for r in rs) + f'); weights after 100 steps {"the same bits" if same else "DIFFER"}')
PY
  done
fi
# The targets of the GPU work (docs/gpu.md), from the logs above.
python3 - "$OUT" <<'PY'
import re, sys
out = sys.argv[1]
bench = open(out + '/bench.log').read()
def ms(chunk):
    m = re.search(r'64x64 -> 128x128, chunk +%d: ([0-9.]+) ms' % chunk, bench)
    return float(m.group(1)) if m else float('nan')
def sps(d, cfg, rep):
    v = re.findall(r'([0-9.]+) samples/s', open(f'{out}/train-{d}-{cfg}-{rep}.log').read().replace('\r', '\n'))
    return float(v[-1]) if v else float('nan')
ok = lambda c: 'met' if c else 'MISSED'
for chunk, target in ((16, 0.5), (1, 1.5)):
    print(f'target: bundle 64x64 -> 128x128 at chunk {chunk} <= {target} ms a frame: {ms(chunk):.3f} ms, {ok(ms(chunk) <= target)}')
for cfg in ('small', 'paper'):
    rs = sorted(sps('cuda', cfg, k) / sps('cpu', cfg, k) for k in (1, 2, 3))
    pairs = ', '.join(f'{r:.1f}' for r in rs)
    print(f'target: training samples/s >= 10x the CPU ({cfg}): {rs[1]:.1f}x (median of 3 pairs: {pairs}), {ok(rs[1] >= 10)}')
PY
rm -rf "$TMP"
