#!/usr/bin/env python3
"""Where a method's detail goes on a garment, against the truth's (issue 45; docs/research/wrinkles.md).

    python3 research/garments/against_truth.py RUN OUT

RUN is an `anisocb simulate --scenario G --pair` folder, OUT an OBJ sequence of the same HR mesh
(`anisocb upscale RUN/lr --out OUT`). Over the HR vertices that are not LR vertices and every
frame after the first, with n the LR surface's normal there (the mean of the LR corners' area-
weighted normals):

  ratio      RMSE of OUT over RMSE of the linear subdivision S, against the truth T (all vertices)
  corr n/t   correlation of the normal (tangential) part of OUT − S with that of T − S
  scale n/t  the scale c that makes c·(OUT − S) closest to T − S in that part (1 = right amount,
             < 0 = the detail points away from the truth's)

Standard library only.
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from twins import apply, frames, read_obj, sq, subdivision  # noqa: E402


def sub3(a, b):
    return [a[k] - b[k] for k in range(3)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot(a, b):
    return sum(a[k] * b[k] for k in range(3))


def main(run, out):
    lr_paths, hr_paths, out_paths = frames(os.path.join(run, "lr")), frames(os.path.join(run, "hr")), frames(out)
    if len(out_paths) != len(hr_paths):
        sys.exit(f"{out}: {len(out_paths)} frames, the truth {len(hr_paths)}")
    lr0, faces = read_obj(lr_paths[0])
    n = len(lr0)
    sub = subdivision(n, faces)
    s = dict(lin=0.0, out=0.0, nn=0.0, tn=0.0, xn=0.0, nt=0.0, tt=0.0, xt=0.0)
    for lp, hp, op in zip(lr_paths, hr_paths, out_paths):
        lr, truth, o = read_obj(lp)[0], read_obj(hp)[0], read_obj(op)[0]
        if len(o) != len(truth):
            sys.exit(f"{op}: {len(o)} vertices, the truth {len(truth)}")
        lin = apply(sub, lr)
        s["lin"] += sq(lin, truth)
        s["out"] += sq(o, truth)
        if lp == lr_paths[0]:
            continue
        normal = [[0.0] * 3 for _ in range(n)]
        for f in faces:
            c = cross(sub3(lr[f[1]], lr[f[0]]), sub3(lr[f[2]], lr[f[0]]))
            for v in f:
                for k in range(3):
                    normal[v][k] += c[k]
        for i in range(n, len(sub)):
            nv = [sum(normal[v][k] for v in sub[i]) for k in range(3)]
            length = math.sqrt(dot(nv, nv)) or 1.0
            nv = [x / length for x in nv]
            d, t = sub3(o[i], lin[i]), sub3(truth[i], lin[i])
            dn, tn = dot(d, nv), dot(t, nv)
            dt = [d[k] - dn * nv[k] for k in range(3)]
            tt = [t[k] - tn * nv[k] for k in range(3)]
            s["nn"] += dn * dn
            s["tn"] += tn * tn
            s["xn"] += dn * tn
            s["nt"] += dot(dt, dt)
            s["tt"] += dot(tt, tt)
            s["xt"] += dot(dt, tt)

    def corr(x, a, b):
        return x / math.sqrt(a * b) if a > 0 and b > 0 else float("nan")

    print(
        f"| {os.path.basename(run.rstrip('/'))} | {math.sqrt(s['out'] / s['lin']):.3f} | "
        f"{corr(s['xn'], s['nn'], s['tn']):+.2f} / {corr(s['xt'], s['nt'], s['tt']):+.2f} | "
        f"{s['xn'] / s['nn'] if s['nn'] else float('nan'):+.2f} / {s['xt'] / s['nt'] if s['nt'] else float('nan'):+.2f} |"
    )


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
