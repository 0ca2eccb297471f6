"""The rows `make bench-peers` compares; names and shapes shared by every side.

benches/peers.rs (anisocb), ort_bench.py (ONNX Runtime) and jax_bench.py (JAX/XLA) each print
one JSON line per row they time: {"row": NAME, "ms": MEDIAN_MS_PER_CALL}.
"""
import json
import time

# (N, C, O, H, W): 3x3 conv forward, zero padding, with bias. The 64-channel shapes,
# then the shipped small config's (C = 32: LR trunk 32x32, HR tail 64x64, the C->3 / C->1 tails).
CONVS = [
    (1, 64, 64, 32, 32),
    (16, 64, 64, 32, 32),
    (1, 64, 64, 128, 128),
    (1, 32, 32, 32, 32),
    (1, 32, 32, 64, 64),
    (1, 32, 3, 64, 64),
    (1, 32, 1, 64, 64),
]
# name -> (channels C, blocks): src/nn/config.rs presets
CONFIGS = {"small": (32, 4), "paper": (64, 10)}
TRAIN_BATCH, TRAIN_PATCH = 32, 16


def conv_row(n, c, o, h, w):
    return f"conv {c}->{o} {n}x{c}x{h}x{w}"


# Frame sizes of the nets rows (LR side; the nets output twice that).
NET_SIZES = [32, 64]


def nets_row(name, size, precision="default"):
    """The three nets on one size x size frame. precision "default": as the side runs them
    without being told (its JSON line names the precision that ran); "fp32": forced to fp32."""
    return f"nets {name} 1x3x{size}x{size} [{precision}]"


def train_row(name):
    return f"train {name} {TRAIN_BATCH}x3x{TRAIN_PATCH}x{TRAIN_PATCH}"


# Untimed warm-up before each row, as benches/peers.rs `WARMUP_SECS`.
WARMUP_SECS = 0.25


def median_ms(fn, min_calls=10, min_secs=1.0):
    """Median wall time of one call (ms): untimed warm-up calls for WARMUP_SECS (at least one),
    then calls until both limits are reached (at most 200), as benches/peers.rs `median_ms`."""
    warm = time.perf_counter()
    fn()
    while time.perf_counter() - warm < WARMUP_SECS:
        fn()
    start, t = time.perf_counter(), []
    while len(t) < 200 and (len(t) < min_calls or time.perf_counter() - start < min_secs):
        s = time.perf_counter()
        fn()
        t.append((time.perf_counter() - s) * 1e3)
    t.sort()
    return t[len(t) // 2]


def emit(row, ms=None, gflops=None, precision=None):
    d = {"row": row}
    if ms is not None:
        d["ms"] = round(ms, 5)
    if gflops is not None:
        d["gflops"] = round(gflops, 1)
    if precision is not None:
        d["precision"] = precision
    print(json.dumps(d), flush=True)


SGEMM_N = 2048
SGEMM_ROW = f"sgemm {SGEMM_N}"


def groups(argv):
    """The row groups asked for on the command line (none: all)."""
    g = [a for a in argv if not a.startswith("-")]
    return g or ["peak", "conv", "nets", "train"]
