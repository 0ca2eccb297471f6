#!/usr/bin/env python3
"""How much of a garment's HR truth its LR run fixes (issue 45; docs/research/wrinkles.md).

    python3 research/garments/twins.py RUN...

Each RUN is an `anisocb simulate --scenario G --pair` folder (lr/, hr/ OBJ sequences) with its
twins beside it, `RUN-twinJ` (the same command with `--hr-jitter J`: the HR half again, under
the same LR run, from a start moved by up to J metres). Printed per run, over every frame and
every HR vertex:

  linear   RMSE of the linear subdivision of the LR frame against the truth (mm)
  twin J   RMSE of the twin against the truth (mm)
  floor J  twin / sqrt(2) / linear: if truth and twin were two independent draws of the HR run
           given the LR run, no method that sees only the LR run could get its RMSE below
           twin / sqrt(2) (the spread about their mean); this is that floor over the linear
           subdivision's RMSE. Twins that start closer than independent draws make it lower.

Standard library only; the subdivision is anisocb's (`geom/surface.rs` `Subdivision::of`: edges
numbered as first met over the faces, then one centre per quad), checked against frame 0.
"""
import glob
import math
import os
import sys


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append(tuple(float(x) for x in line.split()[1:4]))
            elif line.startswith("f "):
                faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    return verts, faces


def frames(folder):
    paths = sorted(glob.glob(os.path.join(folder, "*.obj")))
    if not paths:
        sys.exit(f"{folder}: no OBJ frames (run `anisocb simulate --pair` into it first)")
    return paths


def subdivision(n, faces):
    """The HR vertices of anisocb's subdivision as lists of LR vertices to average."""
    index, edges, centres = {}, [], []
    for f in faces:
        for i in range(len(f)):
            key = (min(f[i], f[(i + 1) % len(f)]), max(f[i], f[(i + 1) % len(f)]))
            if key not in index:
                index[key] = n + len(edges)
                edges.append(list(key))
    for f in faces:
        if len(f) == 4:
            centres.append(list(f))
    return [[v] for v in range(n)] + edges + centres


def apply(sub, lr):
    return [tuple(sum(lr[v][k] for v in w) / len(w) for k in range(3)) for w in sub]


def sq(a, b):
    return sum((p[k] - q[k]) ** 2 for p, q in zip(a, b) for k in range(3))


def main(runs):
    print("| run | linear mm | " + " | ".join("twin {0} mm | floor {0}".format(j) for j in twins_of(runs[0])) + " |")
    print("|---|---:|" + "---:|---:|" * len(twins_of(runs[0])))
    for run in runs:
        lr_paths, hr_paths = frames(os.path.join(run, "lr")), frames(os.path.join(run, "hr"))
        lr0, faces = read_obj(lr_paths[0])
        sub = subdivision(len(lr0), faces)
        hr0, _ = read_obj(hr_paths[0])
        if len(hr0) != len(sub) or sq(apply(sub, lr0), hr0) / len(hr0) > 1e-10:
            sys.exit(f"{run}: hr/ frame 0 is not the LR mesh subdivided once (a --pair run of anisocb's garments?)")
        twins = twins_of(run)
        lin, tw, count = 0.0, {j: 0.0 for j in twins}, 0
        for k, (lp, hp) in enumerate(zip(lr_paths, hr_paths)):
            truth = read_obj(hp)[0]
            lin += sq(apply(sub, read_obj(lp)[0]), truth)
            for j, folder in twins.items():
                tw[j] += sq(read_obj(frames(folder)[k])[0], truth)
            count += len(truth)
        lin = math.sqrt(lin / count)
        cells = []
        for j in twins:
            t = math.sqrt(tw[j] / count)
            cells += [f"{1000 * t:.3f}", f"{t / math.sqrt(2) / lin:.2f}"]
        print(f"| {os.path.basename(run.rstrip('/'))} | {1000 * lin:.3f} | " + " | ".join(cells) + " |", flush=True)


def twins_of(run):
    out = {}
    for folder in sorted(glob.glob(run.rstrip("/") + "-twin*")):
        out[folder.rsplit("-twin", 1)[1]] = os.path.join(folder, "hr")
    return out


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main([r for r in sys.argv[1:] if "-twin" not in os.path.basename(r.rstrip("/"))])
