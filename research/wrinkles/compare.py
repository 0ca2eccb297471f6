"""Close-up comparison, normal-shaded in the grid's (u, v) layout: LR (upsampled nearest) |
Catmull-Rom | each OUT | HR truth, one row per frame.
`python3 compare.py [--detail] OUT.png RUN FRAME[,FRAME...] OUT_DIR...` (RUN a pair dir with
lr/, hr/). `--detail`: the wrinkle detail D (the issue's metric, wrinkle.py `detail`) instead,
Catmull-Rom | each OUT | HR, blue below the coarse surface, red above, white at 0, one scale per
row (±2.5× the truth's RMS(D)): where the folds are, which shading shows only faintly."""
import os
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shade import shade  # noqa: E402
from stats import cr_up  # noqa: E402
from wrinkle import detail, load  # noqa: E402

args = sys.argv[1:]
maps = args[0] == "--detail"
args = args[1:] if maps else args
out, run, frames, outs = args[0], args[1], [int(f) for f in args[2].split(",")], args[3:]
hr, lr = load(run + "/hr"), load(run + "/lr")
cr = cr_up(lr, hr.shape[1], hr.shape[2])
preds = [load(o) for o in outs]


def diverging(d, scale):  # H,W signed -> H,W,3 uint8: blue < 0 < red, white at 0
    t = np.clip(d / scale, -1, 1)[..., None]
    white, red, blue = np.ones(3), np.array([0.8, 0.1, 0.1]), np.array([0.1, 0.2, 0.8])
    c = np.where(t > 0, white + t * (red - white), white - t * (blue - white))
    return (c * 255).astype(np.uint8)


rows = []
for f in frames:
    if maps:
        ds = [detail(x[f : f + 1], lr.shape[1], lr.shape[2])[0] for x in [cr] + preds + [hr]]
        scale = 2.5 * np.sqrt(np.mean(ds[-1] ** 2))
        tiles = [diverging(d, scale) for d in ds]
        pad = ((4, 4), (4, 4), (0, 0))
    else:
        tiles = [np.kron(shade(lr[f]), np.ones((2, 2), np.uint8)), shade(cr[f])]
        tiles += [shade(p[f]) for p in preds] + [shade(hr[f])]
        pad = ((4, 4), (4, 4))
    row = np.concatenate([np.pad(t, pad, constant_values=255) for t in tiles], axis=1)
    rows.append(row)
img = Image.fromarray(np.concatenate(rows, axis=0))
img.resize((img.width * 3, img.height * 3), Image.NEAREST).save(out)
