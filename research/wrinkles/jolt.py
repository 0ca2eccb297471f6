"""Per frame, how hard a shot's coarse motion jolts upward: the RMS over LR vertices of the
upward part of their acceleration (second differences, m/s²; gravity along −y). A landing
shows as a spike; so do a drape's corners pulling taut and a flag's gusts, which is why this
is not the trigger for the physics pass's damping (docs/research/wrinkles.md, "Blender shots").
`python3 jolt.py LR_DIR:FPS ...` (LR_DIR with geometry.npy + domain.npy)."""
import os
import sys

import numpy as np

for spec in sys.argv[1:]:
    d, fps = spec.rsplit(":", 1)
    g = np.load(os.path.join(d, "geometry.npy")).astype(np.float64)  # T,3,H,W in [0, 1]
    dom = np.load(os.path.join(d, "domain.npy"))  # [bmin; bmax], metres
    x = g * (dom[1] - dom[0])[None, :, None, None] + dom[0][None, :, None, None]
    a = np.diff(x, 2, axis=0) * float(fps) ** 2
    up = np.sqrt((np.maximum(a[:, 1], 0).reshape(a.shape[0], -1) ** 2).mean(1))
    print(f"{d}: peak {up.max():.1f} m/s² at frame {up.argmax() + 1}; per frame "
          + " ".join(f"{u:.0f}" for u in up))
