"""How far one HR run's wrinkle detail D agrees with another's under the same LR run
(docs/research/wrinkles.md, "How much of the detail the LR run fixes"), for determinacy_study.sh:
  python3 determinacy.py twin BASE OTHER        whole-run correlation of D (frames 1..)
  python3 determinacy.py restart BASE OTHER F   correlation of D at F + lag, per lag
  python3 determinacy.py blind BASE OTHER       correlation, amount, change and vertex RMSE
BASE, OTHER: simulator pair dirs (lr/, hr/) of the same scenario, seed and LR run."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np  # noqa: E402
from wrinkle import cr_matrix, detail, load, rms  # noqa: E402


def corr(x, y):
    return float((x * y).sum() / np.sqrt((x * x).sum() * (y * y).sum() + 1e-30))


mode, base, other = sys.argv[1:4]
lr_a, lr_b = load(base + "/lr"), load(other + "/lr")
# The same LR run, up to the rounding of each pair's shared domain.
assert np.abs(lr_a - lr_b).max() < 1e-5, "the two pairs' LR runs differ"
a, b = load(base + "/hr"), load(other + "/hr")
lh, lw = lr_a.shape[1:3]
da, db = detail(a, lh, lw), detail(b, lh, lw)
name = os.path.basename(base.rstrip("/"))
if mode == "twin":
    r = corr(da[1:], db[1:])
    print(f"{name:18s} {os.path.basename(other):28s} twin corr {r:5.2f}, sqrt {np.sqrt(max(r, 0)):4.2f}; "
          f"RMS(D) {1000 * rms(da):.2f} / {1000 * rms(db):.2f} mm")
elif mode == "restart":
    f = int(sys.argv[4])
    lags = [g for g in (1, 2, 4, 8, 16, 32, 64) if f + g < len(da)]
    print(f"{name:18s} restart at {f:3d}: " + "  ".join(f"+{g} {corr(da[f + g], db[f + g]):5.2f}" for g in lags))
else:
    u = np.einsum("ay,tyxc,bx->tabc", cr_matrix(lh, a.shape[1]), lr_a, cr_matrix(lw, a.shape[2]))
    err = lambda x: 1000 * float(np.sqrt(np.mean(np.sum((x - a)[2:] ** 2, -1))))
    change = rms(np.diff(db[2:], axis=0)) / rms(np.diff(da[2:], axis=0))
    print(f"{name:18s} blind: corr {corr(da[2:], db[2:]):5.2f}, ratio {rms(db[2:]) / rms(da[2:]):.2f}, "
          f"D change {change:.2f}x, vertex RMSE {err(b):.2f} mm (Catmull-Rom {err(u):.2f} mm)")
