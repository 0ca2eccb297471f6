"""Close-up comparison, normal-shaded in the grid's (u, v) layout: LR (upsampled nearest) |
Catmull-Rom | each OUT | HR truth, one row per frame.
`python3 compare.py OUT.png RUN FRAME[,FRAME...] OUT_DIR...` (RUN a pair dir with lr/, hr/)."""
import os
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shade import shade  # noqa: E402
from stats import cr_up  # noqa: E402
from wrinkle import load  # noqa: E402

out, run, frames, outs = sys.argv[1], sys.argv[2], [int(f) for f in sys.argv[3].split(",")], sys.argv[4:]
hr, lr = load(run + "/hr"), load(run + "/lr")
cr = cr_up(lr, hr.shape[1], hr.shape[2])
preds = [load(o) for o in outs]
rows = []
for f in frames:
    tiles = [np.kron(shade(lr[f]), np.ones((2, 2), np.uint8)), shade(cr[f])]
    tiles += [shade(p[f]) for p in preds] + [shade(hr[f])]
    row = np.concatenate([np.pad(t, ((4, 4), (4, 4)), constant_values=255) for t in tiles], axis=1)
    rows.append(row)
img = Image.fromarray(np.concatenate(rows, axis=0))
img.resize((img.width * 3, img.height * 3), Image.NEAREST).save(out)
