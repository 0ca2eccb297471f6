#!/usr/bin/env python3
"""Which local features of a garment's LR run carry its HR detail (issue 45; docs/research/wrinkles.md).

    bpy-venv/bin/python research/garments/detail_features.py --train RUN... --val RUN...

RUNs are `anisocb simulate --scenario G --pair` folders (training: --vary 1..5; judged on
--vary 6). At every edge midpoint of every second frame, the truth's detail along the LR normal
(HR vertex minus the chord's midpoint) is regressed (ridge, standardised features) on:
the buckling height of the edge if inextensible (amp), amp times the signs of the bend, the
normal velocity and acceleration, the bend itself (kappa·rest), the normal velocity and
acceleration, gravity along the normal, and the compression. Printed: the fit's correlation on
the training runs, per validation run the correlation and the midpoints' RMSE over the chord's,
the weights, and each feature's own correlation on the validation runs. Then the closed-form
curved subdivision anisocb uses (`Subdivision::apply_curved`: ((n_b − n_a)·(x_b − x_a))/8 along
the mean normal at each edge vertex, half the sum of its edges' at a quad centre; nothing fitted):
its RMSE over the linear subdivision's on every HR vertex of each validation run. Needs NumPy.
"""
import argparse
import glob
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from twins import read_obj, subdivision  # noqa: E402

NAMES = ["amp", "amp*sgn(k)", "amp*k", "amp*sgn(vn)", "amp*vn", "amp*sgn(an)", "amp*gn", "k*rest", "vn", "an",
         "gn*rest", "comp"]


def frames(run):
    lrp = sorted(glob.glob(os.path.join(run, "lr", "*.obj")))
    hrp = sorted(glob.glob(os.path.join(run, "hr", "*.obj")))
    if not lrp or len(lrp) != len(hrp):
        sys.exit(f"{run}: lr/ and hr/ OBJ sequences of one length expected (simulate --pair)")
    lr0, faces = read_obj(lrp[0])
    lr = np.array([read_obj(p)[0] for p in lrp], dtype=np.float64)
    hr = np.array([read_obj(p)[0] for p in hrp], dtype=np.float64)
    return lr, hr, faces


def normals(x, faces):
    n = np.zeros_like(x)
    for f in faces:
        u, v = (x[f[2]] - x[f[0]], x[f[3]] - x[f[1]]) if len(f) == 4 else (x[f[1]] - x[f[0]], x[f[2]] - x[f[0]])
        n[f] += np.cross(u, v)
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-12)


def topology(n, faces):
    sub = subdivision(n, faces)
    edges = np.array([w for w in sub[n:] if len(w) == 2])
    quads = np.array([w for w in sub[n:] if len(w) == 4], dtype=np.int64).reshape(-1, 4)
    index = {tuple(sorted(e)): i for i, e in enumerate(map(tuple, edges))}
    quad_edges = np.array([[index[tuple(sorted((q[i], q[(i + 1) % 4])))] for i in range(4)] for q in quads],
                          dtype=np.int64).reshape(-1, 4)
    return edges, quads, quad_edges


def features(run, stride=2):
    lr, hr, faces = frames(run)
    n = lr.shape[1]
    edges, _, _ = topology(n, faces)
    a, b = edges[:, 0], edges[:, 1]
    rest = np.linalg.norm(lr[0, a] - lr[0, b], axis=1)
    xs, ys, sq = [], [], []
    for k in range(2, len(lr), stride):
        x, nrm = lr[k], normals(lr[k], faces)
        nm = nrm[a] + nrm[b]
        nm /= np.linalg.norm(nm, axis=1, keepdims=True) + 1e-12
        e = x[b] - x[a]
        length = np.linalg.norm(e, axis=1)
        amp = 0.5 * np.sqrt(np.maximum(0.0, rest**2 - length**2))
        kappa = np.einsum("ij,ij->i", nrm[a] - nrm[b], e) / (length**2 + 1e-12) * rest
        mid = lambda j: 0.5 * (lr[j][a] + lr[j][b])  # noqa: E731
        vn = np.einsum("ij,ij->i", mid(k) - mid(k - 1), nm)
        an = np.einsum("ij,ij->i", mid(k) - 2 * mid(k - 1) + mid(k - 2), nm)
        gn = -nm[:, 1]
        xs.append(np.stack([amp, amp * np.sign(kappa), amp * kappa, amp * np.sign(vn), amp * vn / (np.abs(vn).mean() + 1e-9),
                            amp * np.sign(an), amp * gn, kappa * rest, vn, an, gn * rest,
                            np.maximum(0.0, 1 - length / rest)], axis=1))
        t = hr[k, n + np.arange(len(edges))] - mid(k)
        ys.append(np.einsum("ij,ij->i", t, nm))
        sq.append(np.einsum("ij,ij->i", t, t))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(sq)


def curved_ratio(run):
    lr, hr, faces = frames(run)
    n = lr.shape[1]
    edges, quads, quad_edges = topology(n, faces)
    a, b = edges[:, 0], edges[:, 1]
    lin = cur = 0.0
    for k in range(1, len(lr)):
        x, nrm = lr[k], normals(lr[k], faces)
        nm = nrm[a] + nrm[b]
        nm /= np.linalg.norm(nm, axis=1, keepdims=True) + 1e-12
        move = (np.einsum("ij,ij->i", nrm[b] - nrm[a], x[b] - x[a]) / 8.0)[:, None] * nm
        s = np.concatenate([x, 0.5 * (x[a] + x[b]), x[quads].mean(1)])
        c = s.copy()
        c[n:n + len(edges)] += move
        c[n + len(edges):] += 0.5 * move[quad_edges].sum(1)
        lin += ((s - hr[k]) ** 2).sum()
        cur += ((c - hr[k]) ** 2).sum()
    return np.sqrt(cur / lin)


def ridge(x, y):
    """A ridge fit of y on standardised x: (predict(x'), weights)."""
    mu, sd = x.mean(0), x.std(0) + 1e-12
    z = (x - mu) / sd
    w = np.linalg.solve(z.T @ z + 1e-3 * len(z) * np.eye(z.shape[1]), z.T @ (y - y.mean()))
    return lambda q: ((q - mu) / sd) @ w + y.mean(), w


def train_val_args():
    ap = argparse.ArgumentParser(description=sys.modules["__main__"].__doc__.split("\n")[0])
    ap.add_argument("--train", nargs="+", required=True)
    ap.add_argument("--val", nargs="+", required=True)
    return ap.parse_args()


def main():
    a = train_val_args()
    tr = [features(r) for r in a.train]
    xt, yt = np.concatenate([t[0] for t in tr]), np.concatenate([t[1] for t in tr])
    predict, w = ridge(xt, yt)
    print(f"training fit: correlation {np.corrcoef(predict(xt), yt)[0, 1]:+.3f}")
    vals = []
    for r in a.val:
        xv, yv, sv = features(r)
        vals.append((xv, yv))
        p = predict(xv)
        ratio = np.sqrt((sv - 2 * p * yv + p * p).sum() / sv.sum())
        print(f"{os.path.basename(r.rstrip('/')):16s} correlation {np.corrcoef(p, yv)[0, 1]:+.3f}  midpoints' RMSE ÷ chord's {ratio:.3f}"
              f"  curved subdivision ÷ linear (every vertex) {curved_ratio(r):.3f}")
    print("weights:", ", ".join(f"{n} {x:+.4f}" for n, x in zip(NAMES, w)))
    xv, yv = np.concatenate([v[0] for v in vals]), np.concatenate([v[1] for v in vals])
    print("each feature's correlation on the validation runs:",
          ", ".join(f"{n} {np.corrcoef(xv[:, i], yv)[0, 1]:+.3f}" for i, n in enumerate(NAMES)))


if __name__ == "__main__":
    main()
