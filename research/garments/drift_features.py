#!/usr/bin/env python3
"""Which features of a garment's LR run predict its HR run's drift at the LR vertices (issue 45;
docs/results.md, "Where the error is").

    bpy-venv/bin/python research/garments/drift_features.py --train RUN... --val RUN...

RUNs are `anisocb simulate --scenario G --pair` folders (training: --vary 1..5; judged on --vary
6). The drift of LR vertex i at frame k is the HR run's vertex i minus the LR run's (the HR run's
first vertices are the LR vertices). Its part along the LR vertex normal n, and its part along
gravity in the tangent plane, are each regressed (ridge, standardised features) on local features
of the LR run: the vertex's velocity and acceleration along n and along the tangent gravity
direction, now and one and two frames before (the history an LR frame alone does not show), the
umbrella curvature along n, gravity along n, the stretch of the vertex's edges against the first
frame, and the curved subdivision's bulge restricted to the vertex. Printed: the share of the drift
each part carries, the fit's correlation on the training runs, and per validation run the
correlation and the drift's RMS left after the fit over the drift's (1 = nothing predicted; the
last column subtracts only the normal part's fit). Needs NumPy.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from detail_features import frames, normals, ridge, topology, train_val_args  # noqa: E402

NAMES = ["v.n", "a.n", "v.n[-1]", "a.n[-1]", "v.n[-2]", "v.t", "a.t", "v.t[-1]", "a.t[-1]", "v.t[-2]",
         "curv.n", "g.n", "stretch", "bulge.n", "speed"]
LAGS = 3


def run_features(run):
    lr, hr, faces = frames(run)
    n = lr.shape[1]
    edges, quads, quad_edges = topology(n, faces)
    a, b = edges[:, 0], edges[:, 1]
    deg = np.bincount(np.concatenate([a, b]), minlength=n).astype(np.float64)[:, None]
    rest = np.linalg.norm(lr[0, a] - lr[0, b], axis=1)
    xs, yn, yt, sq = [], [], [], []
    g = np.array([0.0, -1.0, 0.0])
    for k in range(LAGS + 1, len(lr)):
        x, nrm = lr[k], normals(lr[k], faces)
        tg = g - (nrm @ g)[:, None] * nrm
        tg /= np.linalg.norm(tg, axis=1, keepdims=True) + 1e-12
        vel = [lr[k - j] - lr[k - j - 1] for j in range(LAGS)]
        acc = [lr[k - j] - 2 * lr[k - j - 1] + lr[k - j - 2] for j in range(LAGS - 1)]
        along = lambda v, d: np.einsum("ij,ij->i", v, d)  # noqa: E731
        nbr = np.zeros_like(x)
        np.add.at(nbr, a, x[b])
        np.add.at(nbr, b, x[a])
        curv = along(nbr / np.maximum(deg, 1) - x, nrm)
        length = np.linalg.norm(x[a] - x[b], axis=1) / rest - 1
        stretch = np.zeros(n)
        np.add.at(stretch, a, length)
        np.add.at(stretch, b, length)
        stretch /= np.maximum(deg[:, 0], 1)
        nm = nrm[a] + nrm[b]
        nm /= np.linalg.norm(nm, axis=1, keepdims=True) + 1e-12
        move = (np.einsum("ij,ij->i", nrm[b] - nrm[a], x[b] - x[a]) / 8.0)[:, None] * nm
        bulge = np.zeros_like(x)
        np.add.at(bulge, a, 0.5 * move)
        np.add.at(bulge, b, 0.5 * move)
        cm = 0.5 * move[quad_edges].sum(1)
        for c in range(4):
            np.add.at(bulge, quads[:, c], 0.25 * cm)
        xs.append(np.stack([along(vel[0], nrm), along(acc[0], nrm), along(vel[1], nrm), along(acc[1], nrm),
                            along(vel[2], nrm), along(vel[0], tg), along(acc[0], tg), along(vel[1], tg),
                            along(acc[1], tg), along(vel[2], tg), curv, nrm @ g, stretch,
                            along(bulge, nrm) / deg[:, 0], np.linalg.norm(vel[0], axis=1)], axis=1))
        d = hr[k, :n] - x
        yn.append(along(d, nrm))
        yt.append(along(d, tg))
        sq.append(np.einsum("ij,ij->i", d, d))
    return np.concatenate(xs), np.concatenate(yn), np.concatenate(yt), np.concatenate(sq)


def main():
    a = train_val_args()
    tr = [run_features(r) for r in a.train]
    x = np.concatenate([t[0] for t in tr])
    fits = {}
    for part, i in (("normal", 1), ("gravity", 2)):
        y = np.concatenate([t[i] for t in tr])
        f, w = ridge(x, y)
        fits[part] = f
        share = (y ** 2).sum() / np.concatenate([t[3] for t in tr]).sum()
        print(f"{part:8s} part: {share:.0%} of the training drift; training fit correlation "
              f"{np.corrcoef(f(x), y)[0, 1]:+.3f}; weights " + ", ".join(f"{n} {v:+.2e}" for n, v in zip(NAMES, w)))
    print("| run | drift mm | normal: corr, left | gravity: corr, left | drift left, normal fit alone |")
    print("|---|---:|---:|---:|---:|")
    for r in a.val:
        xv, yn, yt, sq = run_features(r)
        pn, pt = fits["normal"](xv), fits["gravity"](xv)
        left = lambda y, p: np.sqrt(((y - p) ** 2).sum() / (y ** 2).sum())  # noqa: E731
        all_left = np.sqrt((sq - yn ** 2 + (yn - pn) ** 2).sum() / sq.sum())
        print(f"| {os.path.basename(r.rstrip('/'))} | {1e3 * np.sqrt(sq.mean()):.2f} | "
              f"{np.corrcoef(pn, yn)[0, 1]:+.2f}, {left(yn, pn):.3f} | {np.corrcoef(pt, yt)[0, 1]:+.2f}, "
              f"{left(yt, pt):.3f} | {all_left:.3f} |")


if __name__ == "__main__":
    main()
