"""An OBJ sequence of a square grid whose vertices are stored row by row (Blender's grid, as
`research/blender/make_scenes.py` exports it) as geometry.npy + domain.npy, for stats.py / sted.py:
`python3 obj2npy.py OBJ_DIR OUT_DIR`. The domain is the unit box, so values are metres."""
import glob
import os
import sys

import numpy as np

src, dst = sys.argv[1], sys.argv[2]
frames = []
for f in sorted(glob.glob(os.path.join(src, "*.obj"))):
    v = [list(map(float, line.split()[1:4])) for line in open(f) if line.startswith("v ")]
    n = int(round(len(v) ** 0.5))
    frames.append(np.array(v).reshape(n, n, 3))
X = np.stack(frames).transpose(0, 3, 1, 2).astype(np.float32)
os.makedirs(dst, exist_ok=True)
np.save(os.path.join(dst, "geometry.npy"), X)
np.save(os.path.join(dst, "domain.npy"), np.array([[0, 0, 0], [1, 1, 1]], np.float32))
print(dst, X.shape)
