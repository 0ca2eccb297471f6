#!/usr/bin/env python3
"""OpenVINO's side of `make bench-peers`: the three nets per frame, as a user would run them.

    python benches/peers/ov_bench.py [nets] [--threads N]

The same ONNX graph as ort_bench.py (GeometryNet + BoundaryNet + EnhanceNet + the cubic U,
random weights of the small and paper configs), read by OpenVINO and compiled for the CPU
with its defaults: no precision hint, so OpenVINO picks its own inference precision (bf16 on
a CPU with AMX or AVX512_BF16, fp32 elsewhere), which the row names. The "fp32" rows force
INFERENCE_PRECISION_HINT f32. Frames of rows.NET_SIZES. Threads: the machine's cores (as anisocb's
rayon pool). `make bench-peers` (run.py) runs it in turn with the other sides.
"""
import os
import sys

import numpy as np
import openvino as ov

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import rows  # noqa: E402
from ort_bench import nets_model  # noqa: E402


def main():
    threads = os.cpu_count()
    if "--threads" in sys.argv:
        threads = int(sys.argv[sys.argv.index("--threads") + 1])
    want = rows.groups([a for a in sys.argv[1:] if not a.isdigit()])
    core = ov.Core()
    rng = np.random.default_rng(0)
    if "nets" in want:
        for name, (c, b) in rows.CONFIGS.items():
            for size in rows.NET_SIZES:
                model = core.read_model(nets_model(c, b, rng, size).SerializeToString(), b"")
                for hint in [None, "f32"]:
                    cfg = {"INFERENCE_NUM_THREADS": threads}
                    if hint:
                        cfg["INFERENCE_PRECISION_HINT"] = hint
                    compiled = core.compile_model(model, "CPU", cfg)
                    precision = compiled.get_property("INFERENCE_PRECISION_HINT").get_type_name()
                    req = compiled.create_infer_request()
                    x = rng.uniform(0, 1, (1, 3, size, size)).astype(np.float32)
                    row = rows.nets_row(name, size, "default" if hint is None else "fp32")
                    rows.emit(row, rows.median_ms(lambda: req.infer({0: x})), precision=precision)

if __name__ == "__main__":
    main()
