"""Wrinkle statistics of upscaled runs against their HR truth: `python3 stats.py TAG RUN:OUT ...`
(RUN a simulator pair dir with lr/ and hr/, OUT an `upscale --format npy` output dir)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from wrinkle import cr_matrix, detail, load, rms  # noqa: E402


def stats(pred, truth, lh, lw):
    dp, dt = detail(pred, lh, lw), detail(truth, lh, lw)
    corr = float((dp * dt).sum() / np.sqrt((dp**2).sum() * (dt**2).sum() + 1e-30))
    change = rms(np.diff(dp, axis=0)) / rms(np.diff(dt, axis=0))
    rmse = 1000 * float(np.sqrt(np.mean(np.sum((pred - truth) ** 2, -1))))
    return rms(dp) * 1000, rms(dp) / rms(dt), corr, change, rmse


def cr_up(lr, h, w):
    return np.einsum("ay,tyxc,bx->tabc", cr_matrix(lr.shape[1], h), lr, cr_matrix(lr.shape[2], w))


if __name__ == "__main__":
    tag = sys.argv[1]
    for pair in sys.argv[2:]:
        run, out = pair.split(":")
        truth, lr, pred = load(run + "/hr"), load(run + "/lr"), load(out)
        lh, lw = lr.shape[1], lr.shape[2]
        for name, x in (("catmull-rom", cr_up(lr, *truth.shape[1:3])), (tag, pred)):
            r = stats(x, truth, lh, lw)
            print(
                f"{os.path.basename(run):30s} {name:12s} D {r[0]:.3f} mm ratio {r[1]:.2f} corr {r[2]:.3f} "
                f"change {r[3]:.2f} rmse {r[4]:.2f} mm (truth D {1000 * rms(detail(truth, lh, lw)):.3f})"
            )
