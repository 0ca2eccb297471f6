#!/usr/bin/env python3
"""How far a garment's HR run drifts from its LR run at the LR vertices (issue 45; docs/results.md).

    anisocb eval --meshes RUN... --out EVAL
    python3 research/garments/lr_drift.py EVAL/meshes.json RUN...

Each RUN is an `anisocb simulate --scenario G --pair` folder (lr/, hr/ OBJ sequences; the HR
run's first vertices are the LR vertices). Printed per run, over every frame:

  drift    RMS distance between the HR run's LR vertices and the LR run's own (mm): where the
           coarsely tracked HR cloth went that the LR run did not
  linear   the linear subdivision's vertex RMSE against the HR run (from EVAL/meshes.json, mm)
  ratio    drift / linear: near 1, the subdivision's whole error is that drift, which no method
           that keeps the LR vertices where the LR run put them can take away
  anisocb  anisocb's RMSE over the linear subdivision's (from EVAL/meshes.json)

Standard library only.
"""
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from twins import frames, read_obj  # noqa: E402


def main(eval_json, runs):
    scores = {}
    for r in json.load(open(eval_json)):
        scores.setdefault(r["run"], {})[r["method"]] = r
    print("| run | drift mm | linear mm | drift ÷ linear | anisocb ÷ linear |")
    print("|---|---:|---:|---:|---:|")
    for run in runs:
        name = os.path.basename(os.path.normpath(run))
        if name not in scores:
            sys.exit(f"{eval_json}: no scores for {name} (eval --meshes it first)")
        s, n = 0.0, 0
        for lp, hp in zip(frames(os.path.join(run, "lr")), frames(os.path.join(run, "hr"))):
            lr, _ = read_obj(lp)
            hr, _ = read_obj(hp)
            s += sum((p[k] - q[k]) ** 2 for p, q in zip(lr, hr[: len(lr)]) for k in range(3))
            n += len(lr)
        drift = math.sqrt(s / n)
        lin = scores[name]["linear subdivision"]["rmse_m"]
        ours = scores[name]["anisocb"]["rmse_m"]
        print(f"| {name} | {1e3 * drift:.2f} | {1e3 * lin:.2f} | {drift / lin:.2f} | {ours / lin:.3f} |")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
