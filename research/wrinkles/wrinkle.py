"""Wrinkle detail D (issue 30 metric, the same definition as anisocb::eval::metrics::wrinkle_detail) in NumPy, for the study scripts beside this file: S = Catmull-Rom round trip through the LR grid, D = (X - S)·n(S), interior only."""
import sys, json, os
import numpy as np

def keys(t, a=-0.5):
    t = abs(t)
    if t <= 1: return (a+2)*t**3 - (a+3)*t**2 + 1
    if t < 2: return a*t**3 - 5*a*t**2 + 8*a*t - 4*a
    return 0.0

def cr_matrix(n_in, n_out):
    M = np.zeros((n_out, n_in))
    for d in range(n_out):
        s = d*(n_in-1)/(n_out-1) if n_out > 1 else 0.0
        f = int(np.floor(s)); t = s-f
        for o in (-1,0,1,2):
            M[d, min(max(f+o,0),n_in-1)] += keys(t-o)
    return M

def load(run):
    g = np.load(os.path.join(run, "geometry.npy")).astype(np.float64)  # T,3,H,W
    dom = np.load(os.path.join(run, "domain.npy")).astype(np.float64)
    p = dom[0][None,:,None,None] + g*(dom[1]-dom[0])[None,:,None,None]
    return p.transpose(0,2,3,1)  # T,H,W,3

def smooth(X, lh, lw):
    T,H,W,_ = X.shape
    Dh, Dw = cr_matrix(H, lh), cr_matrix(W, lw)
    Uh, Uw = cr_matrix(lh, H), cr_matrix(lw, W)
    Sh, Sw = Uh@Dh, Uw@Dw
    return np.einsum('ay,tyxc,bx->tabc', Sh, X, Sw)

def normals(S):
    dx = np.gradient(S, axis=2); dy = np.gradient(S, axis=1)
    n = np.cross(dx, dy); return n/np.linalg.norm(n, axis=-1, keepdims=True)

def detail(X, lh, lw):
    S = smooth(X, lh, lw)
    D = ((X-S)*normals(S)).sum(-1)
    return D[:, 2:-2, 2:-2]

def rms(a): return float(np.sqrt(np.mean(a**2)))

if __name__ == "__main__":
    for run in sys.argv[1:]:
        X = load(run); T,H,W,_ = X.shape
        D = detail(X, H//2, W//2)
        print(f"{run}: RMS(D) {1000*rms(D):.3f} mm, change {1000*rms(np.diff(D,axis=0)):.3f} mm/frame")

def gap(pair):
    """RMS distance (mm) between S(HR) and the Catmull-Rom upsampled LR, interior."""
    H = load(os.path.join(pair, "hr")); L = load(os.path.join(pair, "lr"))
    T, h, w, _ = L.shape
    S = smooth(H, h, w)
    Uh, Uw = cr_matrix(h, H.shape[1]), cr_matrix(w, H.shape[2])
    U = np.einsum('ay,tyxc,bx->tabc', Uh, L, Uw)
    d = np.linalg.norm((S-U)[:, 2:-2, 2:-2], axis=-1)
    return 1000*float(np.sqrt(np.mean(d**2)))
