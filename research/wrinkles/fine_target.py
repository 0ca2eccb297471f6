"""Copies simulator pairs with the HR truth replaced by U(LR) + (HR - S(HR)): the Catmull-Rom
upsampled LR run plus only the HR run's detail beyond the LR grid, so a GeometryNet trained on
it (`anisocb dataset` + `train --net geometry`) is asked for the fine folds alone, with no
coarse correction to drown them (docs/research/wrinkles.md, "How much of the detail the LR run fixes").
  python3 fine_target.py SRC_RUNS_DIR DST_RUNS_DIR"""
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np  # noqa: E402
from wrinkle import cr_matrix, load, smooth  # noqa: E402

src, dst = sys.argv[1], sys.argv[2]
for name in sorted(os.listdir(src)):
    a, b = os.path.join(src, name), os.path.join(dst, name)
    if os.path.exists(b):
        shutil.rmtree(b)
    shutil.copytree(a, b)
    hr, lr = load(a + "/hr"), load(a + "/lr")
    lh, lw = lr.shape[1:3]
    u = np.einsum("ay,tyxc,bx->tabc", cr_matrix(lh, hr.shape[1]), lr, cr_matrix(lw, hr.shape[2]))
    fine = u + hr - smooth(hr, lh, lw)
    dom = np.load(a + "/hr/domain.npy").astype(np.float64)
    g = ((fine - dom[0]) / (dom[1] - dom[0])).transpose(0, 3, 1, 2).astype(np.float32)
    np.save(b + "/hr/geometry.npy", g)
    print(f"{name}: fine target written, within [{g.min():.3f}, {g.max():.3f}] of the domain")
