"""STED temporal (eval::metrics::sted, the same definition) of upscaled runs against a pair's HR
truth, next to Catmull-Rom's: `python3 sted.py RUN OUT...` (RUN with lr/ and hr/, each OUT an
`upscale --format npy` output; all geometry.npy + domain.npy)."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stats import cr_up  # noqa: E402
from wrinkle import load  # noqa: E402


def edges(X):  # T,H,W,3 -> T,E: row edges, then column edges
    r = np.linalg.norm(X[:, :, 1:] - X[:, :, :-1], axis=-1).reshape(X.shape[0], -1)
    c = np.linalg.norm(X[:, 1:, :] - X[:, :-1, :], axis=-1).reshape(X.shape[0], -1)
    return np.concatenate([r, c], 1)


def sted_temporal(p, g):
    lp, lg = edges(p), edges(g)
    ok = lg[:-1] > 1e-9
    den = np.where(ok, lg[:-1], 1)
    dp, dg = (lp[1:] - lp[:-1]) / den, (lg[1:] - lg[:-1]) / den
    return 100 * np.sqrt(np.mean(((dp - dg) ** 2)[ok]))


run = sys.argv[1]
truth, lr = load(run + "/hr"), load(run + "/lr")
print(f"catmull-rom STED temporal {sted_temporal(cr_up(lr, *truth.shape[1:3]), truth):.3f} %")
for o in sys.argv[2:]:
    print(f"{o}: STED temporal {sted_temporal(load(o), truth):.3f} %")
