"""Normal-shaded pictures of runs in the grid's (u, v) layout, side by side: `python3 shade.py OUT.png FRAME RUN...` (a RUN is a dir with geometry.npy + domain.npy); folds show as dark and light stripes."""
import os, sys; sys.path.insert(0, os.path.dirname(os.path.abspath(__file__))); from wrinkle import *
from PIL import Image
def shade(X):  # H,W,3 -> uint8 image in (u,v) space shaded by normals
    n = normals(X[None])[0]
    l = np.array([0.3,0.8,0.5]); l/=np.linalg.norm(l)
    s = np.abs(n@l)
    return (np.clip(s,0,1)*255).astype(np.uint8)
if __name__ == '__main__':
  out, frame = sys.argv[1], int(sys.argv[2]); runs = sys.argv[3:]
  tiles=[]
  for r in runs:
      X = load(r)[frame]
      img = Image.fromarray(shade(X)).resize((X.shape[1]*4, X.shape[0]*4), Image.NEAREST)
      tiles.append(img)
  W = sum(t.width for t in tiles)+10*len(tiles); H = max(t.height for t in tiles)
  canvas = Image.new('L',(W,H),255); x=0
  for t in tiles: canvas.paste(t,(x,0)); x+=t.width+10
  canvas.save(out)
