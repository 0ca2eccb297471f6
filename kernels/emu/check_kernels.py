#!/usr/bin/env python3
"""Check kernels/*.cu on the CPU (no GPU needed): builds emu.cpp with g++, runs every kernel
with the launch geometry of src/cuda/device.rs on small odd shapes, and compares with NumPy
references written from the CPU contracts (src/ops/*.rs). Usage: python3 kernels/emu/check_kernels.py
Needs g++ (C++20) and numpy."""
import ctypes, math, os, subprocess, sys, tempfile
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SO = os.path.join(tempfile.gettempdir(), "anisocb_emu_kernels.so")
subprocess.run(["g++", "-O1", "-std=c++20", "-shared", "-fPIC", "-pthread", "-w", "-o", SO,
                os.path.join(HERE, "emu.cpp")], check=True)
lib = ctypes.CDLL(SO)
THREADS, TILE, BK, MAX_BLOCKS, WGRAD_TARGET = 256, 64, 16, 8192, 1024
rng = np.random.default_rng(7)
failures = []


def launch(name, grid, block, *args):
    keep, ptrs = [], []
    for a in args:
        if isinstance(a, np.ndarray):
            assert a.flags.c_contiguous
            v = ctypes.c_void_p(a.ctypes.data)
        else:
            v = a
        keep.append(v)
        ptrs.append(ctypes.cast(ctypes.pointer(v), ctypes.c_void_p))
    arr = (ctypes.c_void_p * max(1, len(ptrs)))(*ptrs)
    gx, gy, gz = grid
    getattr(lib, "emu_" + name)(ctypes.c_uint(gx), ctypes.c_uint(gy), ctypes.c_uint(gz), ctypes.c_uint(block), arr)


def grid1(n):
    return (min(max(1, -(-n // THREADS)), MAX_BLOCKS), 1, 1)


I, L, F = ctypes.c_int, ctypes.c_longlong, ctypes.c_float


def check(what, got, want, atol=1e-5, rtol=1e-5):
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    assert got.shape == want.shape, (what, got.shape, want.shape)
    d = np.abs(got - want)
    bad = d > atol + rtol * np.abs(want)
    worst = float(d.max()) if d.size else 0.0
    print(f"{'FAIL' if bad.any() else 'ok  '} {what}: largest diff {worst:.3g}")
    if bad.any():
        failures.append(what)


def rnd(*shape):
    return rng.uniform(-1, 1, shape).astype(np.float32)


# ---------------- conv2d ----------------
def gather_idx(n, k, mode):
    """(k, n) source indices and validity of tap k at output position."""
    p = np.arange(n)[None, :] + np.arange(k)[:, None] - k // 2
    valid = (p >= 0) & (p < n)
    if mode == 1:
        valid[:] = True
    return np.clip(p, 0, n - 1), valid


def conv_ref(x, w, b, mode):
    N, C, H, W = x.shape
    O, _, KH, KW = w.shape
    iy, vy = gather_idx(H, KH, mode)
    ix, vx = gather_idx(W, KW, mode)
    cols = x[:, :, iy[:, :, None, None], ix[None, None, :, :]]  # N C KH H KW W
    cols = cols * (vy[:, :, None, None] & vx[None, None, :, :])
    y = np.einsum("ocyx,ncyhxw->nohw", w.astype(np.float64), cols.astype(np.float64))
    if b is not None:
        y += b[None, :, None, None]
    return y, cols


def conv_bwd_ref(x, w, dy, mode):
    N, C, H, W = x.shape
    O, _, KH, KW = w.shape
    _, cols = conv_ref(x, w, None, mode)
    dw = np.einsum("nohw,ncyhxw->ocyx", dy.astype(np.float64), cols.astype(np.float64))
    iy, vy = gather_idx(H, KH, mode)
    ix, vx = gather_idx(W, KW, mode)
    g = np.einsum("ocyx,nohw->ncyhxw", w.astype(np.float64), dy.astype(np.float64))
    g = g * (vy[:, :, None, None] & vx[None, None, :, :])
    dx = np.zeros(x.shape, np.float64)
    Y = np.broadcast_to(iy[:, :, None, None], g.shape[2:])
    X = np.broadcast_to(ix[None, None, :, :], g.shape[2:])
    for n in range(N):
        for c in range(C):
            np.add.at(dx[n, c], (Y, X), g[n, c])
    db = dy.astype(np.float64).sum(axis=(0, 2, 3))
    return dx, dw, db


def tile_rows(rows):
    """src/cuda/conv2d.rs tile_rows: (kernel name suffix, rows per tile)."""
    return ("_m32", TILE // 2) if rows <= TILE // 2 else ("", TILE)


EPI_NONE, EPI_RELU, EPI_ADD, EPI_MASK = 0, 1, 2, 3  # kernels/conv2d.cu


def conv_fwd_dev(x, w, b, mode, force=None, epi=EPI_NONE, aux=None):
    N, C, H, W = x.shape
    O, _, KH, KW = w.shape
    y = np.zeros((N, O, H, W), np.float32)
    bias = b if b is not None else np.zeros(1, np.float32)
    aux = aux if aux is not None else np.zeros(1, np.float32)
    P = N * H * W
    sfx, bm = force or tile_rows(O)
    launch("conv2d_fwd" + sfx, (-(-P // TILE), -(-O // bm), 1), THREADS, x, w, bias, y,
           I(N), I(C), I(H), I(W), I(O), I(KH), I(KW), I(mode), I(b is not None), I(0), aux, I(epi))
    return y


def conv_bwd_dev(x, w, dy, mode, dx, dw, db, mask=None):
    """src/cuda/conv2d.rs conv2d_backward_dev; mask: dx += mask > 0 ? input gradient : 0."""
    N, C, H, W = x.shape
    O, _, KH, KW = w.shape
    P, KK = N * H * W, C * KH * KW
    tiles = -(-KK // TILE) * -(-O // TILE)
    want_z = max(1, -(-WGRAD_TARGET // tiles))
    chunk = max(-(-(-(-P // want_z)) // BK) * BK, 16 * BK)
    Z = -(-P // chunk)
    part = np.zeros(Z * O * KK, np.float32)
    sfx, bm = tile_rows(O)
    launch("conv2d_wgrad" + sfx, (-(-KK // TILE), -(-O // bm), Z), THREADS, x, dy, part,
           I(N), I(C), I(H), I(W), I(O), I(KH), I(KW), I(mode), I(chunk))
    launch("conv2d_wgrad_reduce", grid1(O * KK), THREADS, part, dw, I(Z), L(O * KK))
    sfx, bm = tile_rows(C)
    if mode == 0:  # the forward kernel in its dgrad mode: dx += conv(dy, w transposed and flipped)
        launch("conv2d_fwd" + sfx, (-(-P // TILE), -(-C // bm), 1), THREADS, dy, w, dy, dx,
               I(N), I(O), I(H), I(W), I(C), I(KH), I(KW), I(0), I(0), I(1),
               mask if mask is not None else dy, I(EPI_MASK if mask is not None else EPI_NONE))
    else:
        Hp, Wp = H + KH - 1, W + KW - 1
        dxp = np.zeros(N * C * Hp * Wp, np.float32)
        launch("conv2d_dgrad_padded" + sfx, (-(-(N * Hp * Wp) // TILE), -(-C // bm), 1), THREADS, w, dy, dxp,
               I(N), I(C), I(H), I(W), I(O), I(KH), I(KW))
        launch("conv2d_dgrad_fold", grid1(N * C * H * W), THREADS, dxp, dx, I(N * C), I(H), I(W), I(KH), I(KW), I(mode),
               mask if mask is not None else dx, I(mask is not None))
    launch("conv2d_bias_grad", (O, 1, 1), THREADS, dy, db, I(N), I(O), I(H * W))
    return Z


# The two tile heights give the same bits.
x, w, b = rnd(2, 5, 9, 7), rnd(30, 5, 3, 3), rnd(30)
check("conv2d_fwd: 32-row tiles give the 64-row tiles' bits",
      conv_fwd_dev(x, w, b, 1, ("_m32", TILE // 2)).view(np.uint32),
      conv_fwd_dev(x, w, b, 1, ("", TILE)).view(np.uint32), 0, 0)

for case, (N, C, H, W, O, KH, KW) in enumerate([
        (1, 3, 5, 7, 4, 3, 3), (2, 5, 9, 6, 70, 3, 3), (1, 70, 4, 5, 3, 3, 3), (2, 3, 1, 9, 5, 5, 3),
        (1, 2, 11, 2, 3, 1, 5), (3, 4, 13, 17, 66, 3, 3), (1, 1, 1, 1, 1, 3, 3), (2, 33, 6, 5, 32, 3, 3),
        (1, 32, 5, 9, 33, 3, 3)]):
    for mode in (0, 1):
        x, w, b = rnd(N, C, H, W), rnd(O, C, KH, KW), rnd(O)
        tag = f"conv2d {N}x{C}x{H}x{W} w {O}x{C}x{KH}x{KW} {'replicate' if mode else 'zero'}"
        yr, _ = conv_ref(x, w, b, mode)
        check(tag + " forward", conv_fwd_dev(x, w, b, mode), yr, 1e-4, 1e-4)
        check(tag + " forward no bias", conv_fwd_dev(x, w, None, mode), conv_ref(x, w, None, mode)[0], 1e-4, 1e-4)
        dy = rnd(N, O, H, W)
        dx0, dw0, db0 = rnd(N, C, H, W), rnd(O, C, KH, KW), rnd(O)
        dx, dw, db = dx0.copy(), dw0.copy(), db0.copy()
        Z = conv_bwd_dev(x, w, dy, mode, dx, dw, db)
        rdx, rdw, rdb = conv_bwd_ref(x, w, dy, mode)
        check(tag + f" dx", dx, dx0 + rdx, 1e-4, 1e-4)
        check(tag + f" dw (Z={Z})", dw, dw0 + rdw, 1e-4, 1e-4)
        check(tag + " db", db, db0 + rdb, 1e-4, 1e-4)

# Fused epilogues (device-resident training) give the bits of the conv, then the element-wise
# kernel they replace.
# Their own generator: the checks after them keep their inputs.
fused_rng = np.random.default_rng(11)


def bits(a):
    return np.ascontiguousarray(a).view(np.uint32)


def frnd(*shape):
    return fused_rng.uniform(-1, 1, shape).astype(np.float32)


for (N, C, H, W, O) in [(2, 5, 9, 7, 6), (1, 33, 5, 6, 33), (3, 4, 4, 13, 70)]:
    for mode in (0, 1):
        tag = f"fused {N}x{C}x{H}x{W}->{O} {'replicate' if mode else 'zero'}"
        x, w, b = frnd(N, C, H, W), frnd(O, C, 3, 3), frnd(O)
        y = conv_fwd_dev(x, w, b, mode)
        r = np.zeros_like(y)
        launch("relu_fwd", grid1(y.size), THREADS, y, r, L(y.size))
        check(tag + " forward + ReLU (bits)", bits(conv_fwd_dev(x, w, b, mode, epi=EPI_RELU)), bits(r), 0, 0)
        skip = frnd(N, O, H, W)
        ys = y.copy()
        launch("add_assign", grid1(y.size), THREADS, ys, skip, L(y.size))
        check(tag + " forward + skip (bits)", bits(conv_fwd_dev(x, w, b, mode, epi=EPI_ADD, aux=skip)), bits(ys), 0, 0)
        # dx of a conv whose input is a ReLU's output xr: the unfused way, then fused
        t = frnd(N, C, H, W)
        t[0, 0, 0, :] = 0.0
        xr = np.zeros_like(t)
        launch("relu_fwd", grid1(t.size), THREADS, t, xr, L(t.size))
        dy = frnd(N, O, H, W)
        dxr, dt = np.zeros_like(x), np.zeros_like(x)
        conv_bwd_dev(xr, w, dy, mode, dxr, np.zeros_like(w), np.zeros(O, np.float32))
        launch("relu_bwd", grid1(t.size), THREADS, t, dxr, dt, L(t.size))
        fused = np.zeros_like(x)
        conv_bwd_dev(xr, w, dy, mode, fused, np.zeros_like(w), np.zeros(O, np.float32), mask=xr)
        check(tag + " input gradient + ReLU backward (bits)", bits(fused), bits(dt), 0, 0)
        # the residual's gradient added by accumulating into the skip's gradient
        da = frnd(N, C, H, W)
        unfused = np.zeros_like(x)
        conv_bwd_dev(x, w, dy, mode, unfused, np.zeros_like(w), np.zeros(O, np.float32))
        launch("add_assign", grid1(da.size), THREADS, unfused, da, L(da.size))
        acc = da.copy()
        conv_bwd_dev(x, w, dy, mode, acc, np.zeros_like(w), np.zeros(O, np.float32))
        check(tag + " input gradient into the skip's (bits)", bits(acc), bits(unfused), 0, 0)

# ---------------- element-wise ----------------
for n in (1, 255, 257, 3000):
    x = rnd(n)
    x[0] = 0.0
    y = np.zeros(n, np.float32)
    launch("relu_fwd", grid1(n), THREADS, x, y, L(n))
    check(f"relu n={n}", y, np.where(x < 0, 0, x))
    dy, dx0 = rnd(n), rnd(n)
    dx = dx0.copy()
    launch("relu_bwd", grid1(n), THREADS, x, dy, dx, L(n))
    check(f"relu_backward n={n}", dx, dx0 + np.where(x > 0, dy, 0))
    a0, b = rnd(n), rnd(n)
    a = a0.copy()
    launch("add_assign", grid1(n), THREADS, a, b, L(n))
    check(f"add_assign n={n}", a, a0 + b)
    z = (rnd(n) * 40).astype(np.float32)
    launch("sigmoid_fwd", grid1(n), THREADS, z, y, L(n))
    check(f"sigmoid n={n}", y, 1 / (1 + np.exp(-z.astype(np.float64))), 1e-6, 1e-5)

# ---------------- pixel shuffle ----------------
for (N, C, H, W, r) in [(1, 3, 5, 7, 2), (2, 2, 3, 4, 3), (1, 5, 1, 1, 2), (2, 1, 4, 3, 1)]:
    x = rnd(N, C * r * r, H, W)
    want = x.reshape(N, C, r, r, H, W).transpose(0, 1, 4, 2, 5, 3).reshape(N, C, H * r, W * r)
    y = np.zeros((N, C, H * r, W * r), np.float32)
    launch("pixel_shuffle", grid1(y.size), THREADS, x, y, I(N), I(C), I(H), I(W), I(r))
    check(f"pixel_shuffle {x.shape} r={r}", y, want, 0, 0)
    back = np.zeros_like(x)
    launch("pixel_unshuffle", grid1(back.size), THREADS, y, back, I(N), I(C), I(H), I(W), I(r))
    check(f"pixel_unshuffle {y.shape} r={r}", back, x, 0, 0)


# ---------------- resize ----------------
def taps(in_n, out_n, mode):
    sc = np.float32((in_n - 1) / np.float32(out_n - 1)) if out_n > 1 else np.float32(0)
    sc = np.float32(np.float32(in_n - 1) / np.float32(out_n - 1)) if out_n > 1 else np.float32(0)
    idx, wt = [], []
    a = np.float32(-0.75)
    for d in range(out_n):
        s = np.float32(sc * np.float32(d))
        if mode == "bilinear":
            i0 = min(int(np.floor(s)), in_n - 1)
            i1 = min(i0 + 1, in_n - 1)
            t = np.float32(min(max(s - np.float32(i0), 0), 1))
            idx += [i0, i1]
            wt += [np.float32(1) - t, t]
        else:
            f = np.float32(np.floor(s))
            t = np.float32(s - f)
            c1 = lambda x: ((a + 2) * x - (a + 3)) * x * x + 1
            c2 = lambda x: ((a * x - 5 * a) * x + 8 * a) * x - 4 * a
            idx += [min(max(int(f) + o, 0), in_n - 1) for o in (-1, 0, 1, 2)]
            wt += [c2(t + 1), c1(t), c1(1 - t), c2(2 - t)]
    k = 2 if mode == "bilinear" else 4
    return np.array(idx, np.int32), np.array(wt, np.float32), k


def dense(in_n, out_n, mode):
    idx, wt, k = taps(in_n, out_n, mode)
    A = np.zeros((out_n, in_n))
    for d in range(out_n):
        for j in range(k):
            A[d, idx[d * k + j]] += wt[d * k + j]
    return A


def csr(in_n, out_n, mode):
    idx, wt, k = taps(in_n, out_n, mode)
    cols = [[] for _ in range(in_n)]
    for d in range(out_n):
        for j in range(k):
            c = cols[idx[d * k + j]]
            if c and c[-1][0] == d:
                c[-1][1] += wt[d * k + j]
            else:
                c.append([d, wt[d * k + j]])
    ptr = np.zeros(in_n + 1, np.int32)
    o, w = [], []
    for i, c in enumerate(cols):
        o += [e[0] for e in c]
        w += [e[1] for e in c]
        ptr[i + 1] = len(o)
    return ptr, np.array(o + [0], np.int32), np.array(w + [0], np.float32)


for (N, C, H, W, OH, OW) in [(1, 3, 5, 7, 10, 14), (2, 2, 1, 4, 3, 8), (1, 1, 6, 5, 1, 1), (1, 2, 9, 3, 17, 20)]:
    for mode in ("bilinear", "bicubic"):
        x = rnd(N, C, H, W)
        Ah, Aw = dense(H, OH, mode), dense(W, OW, mode)
        want = np.einsum("yi,ncij,xj->ncyx", Ah, x.astype(np.float64), Aw)
        y = np.zeros((N, C, OH, OW), np.float32)
        tyi, tyw, ky = taps(H, OH, mode)
        txi, txw, kx = taps(W, OW, mode)
        launch("resize_fwd", grid1(y.size), THREADS, x, y, L(N * C), I(H), I(W), I(OH), I(OW),
               tyi, tyw, I(ky), txi, txw, I(kx))
        check(f"resize {mode} {x.shape}->{OH}x{OW}", y, want)
        dy, dx0 = rnd(N, C, OH, OW), rnd(N, C, H, W)
        dx = dx0.copy()
        cy, cx = csr(H, OH, mode), csr(W, OW, mode)
        launch("resize_bwd", grid1(dx.size), THREADS, dy, dx, L(N * C), I(H), I(W), I(OH), I(OW), *cy, *cx)
        check(f"resize_backward {mode} {x.shape}->{OH}x{OW}", dx,
              dx0 + np.einsum("yi,ncyx,xj->ncij", Ah, dy.astype(np.float64), Aw))

# ---------------- losses ----------------
for n in (1, 300, 5000):
    p, t = rnd(n), rnd(n)
    g = np.zeros(n, np.float32)
    cfg = grid1(n)
    part = np.zeros(cfg[0], np.float64)
    launch("mse_loss", cfg, THREADS, p, t, g, part, L(n), F(n))
    d = p.astype(np.float64) - t
    check(f"mse loss n={n}", part.sum() / n, (d * d).mean(), 1e-7, 1e-6)
    check(f"mse grad n={n}", g, 2 * d / n, 1e-7, 1e-5)
    z = (rnd(n) * 30).astype(np.float32)
    tt = (rng.uniform(0, 1, n) > 0.7).astype(np.float32)
    tt[: n // 3] = rng.uniform(0, 1, n // 3)
    pw = 3.5
    launch("bce_logits_loss", cfg, THREADS, z, tt, g, part, L(n), F(n), F(pw))
    z64 = z.astype(np.float64)
    sp = lambda v: np.maximum(v, 0) + np.log1p(np.exp(-np.abs(v)))
    loss = pw * tt * sp(-z64) + (1 - tt) * sp(z64)
    sg = 1 / (1 + np.exp(-z64))
    check(f"bce loss n={n}", part.sum() / n, loss.mean(), 1e-6, 1e-5)
    check(f"bce grad n={n}", g, (pw * tt * (sg - 1) + (1 - tt) * sg) / n, 1e-7, 1e-5)


def geometry_loss_ref(p, t, we, wl):
    """estimate_loss (src/nn/geometry_net.rs) with MSE + we * edge_mse + wl * edge_length_mse,
    in float32 op for op in the CPU's order (src/ops/loss): the gradient's exact bits; the
    three f64 sums (d^2, edge errors^2, length errors^2; 0 for a term of weight 0)."""
    f = np.float32
    N, C, H, W = p.shape
    nf, edges = f(p.size), N * (H * (W - 1) + (H - 1) * W)
    ef, ls = f(max(C * edges, 1)), f(2) / f(max(edges, 1))
    d = p - t
    g = f(2) * d / nf
    er, ed = d[..., 1:] - d[..., :-1], d[:, :, 1:] - d[:, :, :-1]
    sums = [np.sum(d.astype(np.float64) ** 2), np.sum(er.astype(np.float64) ** 2) + np.sum(ed.astype(np.float64) ** 2)]
    if we != 0:
        ge = np.zeros_like(d)
        ge[:, :, 1:] += f(2) * ed / ef     # the edge from the pixel above
        ge[..., 1:] += f(2) * er / ef      # from the left
        ge[..., :-1] -= f(2) * er / ef     # to the right
        ge[:, :, :-1] -= f(2) * ed / ef    # downwards
        g = g + f(we) * ge
    def length(v, ax):
        s = np.zeros_like(np.take(np.diff(v, axis=ax), 0, axis=1))
        for ch in range(C):
            dv = np.diff(v[:, ch], axis=ax - 1)
            s = s + dv * dv
        return np.sqrt(s)
    sl = 0.0
    gl = np.zeros_like(d)
    ks = {}
    for ax in (3, 2):
        lp, lt = length(p, ax), length(t, ax)
        el = lp - lt
        sl += np.sum(el.astype(np.float64) ** 2)
        on = lp > 0
        ks[ax] = (np.where(on, ls * el / np.where(on, lp, f(1)), f(0)), on)
    sums = [sums[0], sums[1] if we != 0 else 0.0, sl if wl != 0 else 0.0]
    if wl != 0:
        dp = {3: np.diff(p, axis=3), 2: np.diff(p, axis=2)}
        for ax, sign, end in ((2, 1, True), (3, 1, True), (3, -1, False), (2, -1, False)):
            k, on = ks[ax]
            dd = k[:, None] * dp[ax]
            tgt = (slice(None), slice(None)) + ((slice(1, None),) if ax == 2 else (slice(None), slice(1, None)))
            if not end:
                tgt = (slice(None), slice(None)) + ((slice(None, -1),) if ax == 2 else (slice(None), slice(None, -1)))
            cur = gl[tgt]
            gl[tgt] = np.where(on[:, None], cur + dd if sign > 0 else cur - dd, cur)
        g = g + f(wl) * gl
    return g, sums

for shape in ((2, 3, 5, 7), (1, 3, 1, 6), (3, 3, 4, 1), (1, 2, 9, 8)):
    for we, wl in ((0.0, 0.0), (1.0, 0.0), (0.5, 4.0), (0.0, 2.0)):
        p, t = rnd(*shape), rnd(*shape)
        p[0, :, 0, :2] = 0.25  # an edge of zero length in pred: no length gradient from it
        N, C, H, W = shape
        g = np.zeros(shape, np.float32)
        cfg = grid1(N * H * W)
        part = np.zeros(3 * cfg[0], np.float64)
        edges = N * (H * (W - 1) + (H - 1) * W)
        launch("geometry_loss", cfg, THREADS, p, t, g, part, I(N), I(C), I(H), I(W), F(p.size),
               F(max(C * edges, 1)), F(np.float32(2) / np.float32(max(edges, 1))), F(we), F(wl))
        g_ref, sums = geometry_loss_ref(p, t, we, wl)
        check(f"geometry_loss grad {shape} we={we} wl={wl} (bits)", g.view(np.uint32), g_ref.view(np.uint32), 0, 0)
        got = part.reshape(3, -1).sum(axis=1)
        check(f"geometry_loss sums {shape} we={we} wl={wl}", got, sums, 1e-12, 1e-12)

# ---------------- adam ----------------
n = 1000
p0 = rnd(n)
p, m, v = p0.copy(), np.zeros(n, np.float32), np.zeros(n, np.float32)
pr, mr, vr = p0.astype(np.float64), np.zeros(n), np.zeros(n)
lr, b1, b2, eps = 1e-3, 0.9, 0.999, 1e-8
for step in range(1, 11):
    g = rnd(n)
    c1, c2 = 1 - b1 ** step, 1 - b2 ** step
    launch("adam_step", grid1(n), THREADS, p, g, m, v, L(n), F(lr), F(b1), F(b2), F(eps), F(c1), F(c2))
    mr = b1 * mr + (1 - b1) * g
    vr = b2 * vr + (1 - b2) * g.astype(np.float64) ** 2
    pr = pr - lr * (mr / c1) / (np.sqrt(vr / c2) + eps)
check("adam 10 steps p", p, pr, 1e-6, 1e-5)
check("adam 10 steps m", m, mr, 1e-6, 1e-5)
check("adam 10 steps v", v, vr, 1e-7, 1e-5)

# adam_step_all: several tensors in one launch, adam_step's bits, each gradient zeroed
sizes = [1, 255, 257, 3000, 0, 17]
ps = [frnd(k) for k in sizes]
gs = [frnd(k) for k in sizes]
ms = [frnd(k) * 0.1 for k in sizes]
vs = [np.abs(frnd(k)) * 0.1 for k in sizes]
want = [(p.copy(), g.copy(), m.copy(), v.copy()) for p, g, m, v in zip(ps, gs, ms, vs)]
c1, c2 = np.float32(1 - b1 ** 3), np.float32(1 - b2 ** 3)
for p, g, m, v in want:
    if p.size:
        launch("adam_step", grid1(p.size), THREADS, p, g, m, v, L(p.size), F(lr), F(b1), F(b2), F(eps), F(c1), F(c2))
table = np.array([[a.ctypes.data if a.size else 0 for a in t] + [t[0].size] for t in zip(ps, gs, ms, vs)], np.uint64)
gx = grid1(max(sizes))[0]
launch("adam_step_all", (gx, len(sizes), 1), THREADS, table, F(lr), F(b1), F(b2), F(eps), F(c1), F(c2))
for k, (p, g, m, v) in enumerate(zip(ps, gs, ms, vs)):
    for what, got, ref in (("p", p, want[k][0]), ("m", m, want[k][2]), ("v", v, want[k][3])):
        check(f"adam_step_all tensor {k} (n={p.size}) {what} (bits)", bits(got), bits(ref), 0, 0)
    check(f"adam_step_all tensor {k} gradient zeroed", g, np.zeros_like(g), 0, 0)

# ---------------- a training step: fused (src/cuda/train.rs) against op by op ----------------
# One GeometryNet-shaped trunk (C = 4, 2 blocks, x2, four tail convs) through the forward, a
# given output gradient, the backward and Adam, twice: op for op as the trainer ran before the
# fusions (ReLU, skip and U + R as kernels of their own, a memset of the gradients, Adam per
# tensor), then as it runs now. Every gradient and parameter must keep its bits.
def relu_k(t):
    r = np.zeros_like(t)
    launch("relu_fwd", grid1(t.size), THREADS, t, r, L(t.size))
    return r


def add_k(a, b):
    launch("add_assign", grid1(a.size), THREADS, a, b, L(a.size))


def shuffle_k(u, r):
    N, Cr, H, W = u.shape
    z = np.zeros((N, Cr // (r * r), H * r, W * r), np.float32)
    launch("pixel_shuffle", grid1(z.size), THREADS, u, z, I(N), I(Cr // (r * r)), I(H), I(W), I(r))
    return z


def unshuffle_k(dz, r):
    N, C, Hr, Wr = dz.shape
    du = np.zeros((N, C * r * r, Hr // r, Wr // r), np.float32)
    launch("pixel_unshuffle", grid1(du.size), THREADS, dz, du, I(N), I(C), I(Hr // r), I(Wr // r), I(r))
    return du


def trunk_step(params, x, skip, dy, mode, fused, blocks, tails=4, r=2):
    """Gradients (w, b per conv, layout order) of one step; params: [(w, b)] in layout order."""
    conv = lambda i, inp, epi=EPI_NONE, aux=None: conv_fwd_dev(inp, params[i][0], params[i][1], mode, epi=epi, aux=aux)
    grads = [(np.zeros_like(w), np.zeros_like(b)) for w, b in params]
    bwd = lambda i, inp, d, dx, mask=None: conv_bwd_dev(inp, params[i][0], d, mode, dx, grads[i][0], grads[i][1], mask=mask)
    a = conv(0, x)
    tape = []
    for k in range(blocks):
        if fused:
            r1 = conv(1 + 2 * k, a, EPI_RELU)
            out = conv(2 + 2 * k, r1, EPI_ADD, a)
            tape.append((a, None, r1))
        else:
            t1 = conv(1 + 2 * k, a)
            r1 = relu_k(t1)
            out = conv(2 + 2 * k, r1)
            add_k(out, a)
            tape.append((a, t1, r1))
        a = out
    up = 1 + 2 * blocks
    z = shuffle_k(conv(up, a), r)
    tail_in, tail_pre = [], []
    for i in range(tails):
        if i + 1 == tails:
            if fused:
                y = conv(up + 1 + i, z, EPI_ADD, skip)
            else:
                y = conv(up + 1 + i, z)
                add_k(y, skip)
            tail_in.append(z)
            break
        if fused:
            nz = conv(up + 1 + i, z, EPI_RELU)
        else:
            pre = conv(up + 1 + i, z)
            tail_pre.append(pre)
            nz = relu_k(pre)
        tail_in.append(z)
        z = nz
    # backward
    if fused:
        d = dy
        for i in reversed(range(tails)):
            dzin = np.zeros_like(tail_in[i])
            bwd(up + 1 + i, tail_in[i], d, dzin, tail_in[i] if i > 0 else None)
            d = dzin
    else:
        d = np.zeros_like(tail_in[-1])
        bwd(up + tails, tail_in[-1], dy, d)
        for i in reversed(range(tails - 1)):
            dpre = np.zeros_like(d)
            launch("relu_bwd", grid1(d.size), THREADS, tail_pre[i], d, dpre, L(d.size))
            dzin = np.zeros_like(tail_in[i])
            bwd(up + 1 + i, tail_in[i], dpre, dzin)
            d = dzin
    du = unshuffle_k(d, r)
    da = np.zeros_like(a)
    bwd(up, a, du, da)
    for k in reversed(range(blocks)):
        a_in, t1, r1 = tape[k]
        if fused:
            dt1 = np.zeros_like(r1)
            bwd(2 + 2 * k, r1, da, dt1, r1)
            bwd(1 + 2 * k, a_in, dt1, da)  # into the skip's gradient
        else:
            dr1 = np.zeros_like(r1)
            bwd(2 + 2 * k, r1, da, dr1)
            dt1 = np.zeros_like(t1)
            launch("relu_bwd", grid1(t1.size), THREADS, t1, dr1, dt1, L(t1.size))
            da_in = np.zeros_like(a_in)
            bwd(1 + 2 * k, a_in, dt1, da_in)
            add_k(da_in, da)
            da = da_in
    bwd(0, x, da, np.zeros_like(x))  # conv_in: its input gradient is not used
    return grads


C_, B_, N_, H_, W_ = 4, 2, 2, 5, 6
shapes = [(C_, 3)] + [(C_, C_)] * (2 * B_) + [(4 * C_, C_)] + [(C_, C_)] * 3 + [(3, C_)]
for mode in (0, 1):
    params = [(frnd(o, i, 3, 3) * 0.5, frnd(o) * 0.1) for o, i in shapes]
    x, skip, dy = frnd(N_, 3, H_, W_), frnd(N_, 3, 2 * H_, 2 * W_), frnd(N_, 3, 2 * H_, 2 * W_)
    old = trunk_step(params, x, skip, dy, mode, False, B_)
    new = trunk_step(params, x, skip, dy, mode, True, B_)
    same = all((bits(o[j]) == bits(n[j])).all() for o, n in zip(old, new) for j in (0, 1))
    nonzero = all(np.abs(o[0]).max() > 0 for o in old)
    check(f"training step fused = op by op, every gradient (bits), {'replicate' if mode else 'zero'}",
          np.float64(same and nonzero), np.float64(1), 0, 0)
    # Adam: per tensor after a memset (before), one launch that zeroes the gradients (now)
    tensors = [t for pair in params for t in pair]
    gl = [t for pair in old for t in pair]
    ref = [(p.copy(), g.copy(), np.zeros_like(p), np.zeros_like(p)) for p, g in zip(tensors, gl)]
    for p, g, m, v in ref:
        launch("adam_step", grid1(p.size), THREADS, p, g, m, v, L(p.size), F(lr), F(b1), F(b2), F(eps),
               F(np.float32(1 - b1)), F(np.float32(1 - b2)))
    got = [(p.copy(), g.copy(), np.zeros_like(p), np.zeros_like(p)) for p, g in zip(tensors, gl)]
    table = np.array([[t.ctypes.data for t in row] + [row[0].size] for row in got], np.uint64)
    launch("adam_step_all", (grid1(max(t.size for t in tensors))[0], len(got), 1), THREADS, table,
           F(lr), F(b1), F(b2), F(eps), F(np.float32(1 - b1)), F(np.float32(1 - b2)))
    same = all((bits(a[j]) == bits(b[j])).all() for a, b in zip(ref, got) for j in (0, 2, 3))
    zeroed = all(not row[1].any() for row in got)
    check(f"training step's Adam in one launch = per tensor (bits), gradients zeroed, {'replicate' if mode else 'zero'}",
          np.float64(same and zeroed), np.float64(1), 0, 0)

# ---------------- infer.cu: the tensor-core inference kernels ----------------
TC_COUT = 32


def f16(a):
    return np.asarray(a, np.float32).astype(np.float16)


def pack_w(w, ci, cop):
    """(O, I, 3, 3) -> (COP, 9*CI) fp16 as infer.rs packs it: k = (ky*3 + kx)*CI + c."""
    O, I = w.shape[:2]
    p = np.zeros((cop, 9, ci), np.float32)
    p[:O, :, :I] = w.transpose(0, 2, 3, 1).reshape(O, 9, I)
    return f16(p.reshape(cop, 9 * ci))


def tc_conv(x16, xz, w16, b, skip16, Z, NB, H, W, CI, COP, pad, mode, relu, nskip, ng=0, CO=3, cg=3, cm=1):
    P = NB * H * W
    if mode == 0:
        y = np.zeros((Z, NB, H, W, COP), np.float16)
    elif mode == 1:
        y = np.zeros((Z, NB, 2 * H, 2 * W, COP // 4), np.float16)
    else:
        y = np.zeros((Z, NB, CO, H, W), np.float32)
    sk = skip16 if skip16 is not None else np.zeros(1, np.float16)
    launch("conv3x3_tc", (-(-W // 16) * -(-H // 8), -(-COP // TC_COUT), Z * NB), 128, x16.view(np.uint16), L(xz),
           w16.view(np.uint16), b, sk.view(np.uint16), y.view(np.uint16) if mode != 2 else y,
           I(NB), I(H), I(W), I(CI), I(COP), I(pad), I(mode), I(relu),
           I(nskip if skip16 is not None else 0), I(ng), I(CO), I(cg), I(cm))
    if skip16 is None and mode == 0:
        pass
    return y


for (NB, H, W, I_, O_, pad, Z) in [(2, 5, 7, 3, 32, 1, 2), (1, 9, 4, 32, 40, 0, 1), (3, 3, 3, 16, 8, 1, 3), (2, 17, 9, 16, 16, 0, 1), (1, 10, 20, 64, 32, 1, 2)]:
    CI = -(-I_ // 16) * 16
    COP = -(-O_ // 8) * 8
    xs = [rnd(NB, I_, H, W) for _ in range(Z)]
    ws = [rnd(O_, I_, 3, 3) * 0.3 for _ in range(Z)]
    bs = [rnd(O_) for _ in range(Z)]
    x16 = np.zeros((Z, NB, H, W, CI), np.float16)
    for z in range(Z):
        x16[z, ..., :I_] = f16(xs[z].transpose(0, 2, 3, 1))
    w16 = np.stack([pack_w(ws[z], CI, COP) for z in range(Z)])
    b = np.zeros((Z, COP), np.float32)
    for z in range(Z):
        b[z, :O_] = bs[z]
    skip = f16(rnd(Z, NB, H, W, COP))
    refs = []
    for z in range(Z):
        xr = x16[z, ..., :I_].astype(np.float32).transpose(0, 3, 1, 2)
        wr = w16[z].astype(np.float32).reshape(COP, 9, CI)[:O_, :, :I_].reshape(O_, 3, 3, I_).transpose(0, 3, 1, 2)
        refs.append(conv_ref(xr, wr, bs[z], pad)[0])  # (NB, O, H, W) float64
    # mode 0 with a skip on net 0 only, ReLU
    y = tc_conv(x16, NB * H * W * CI, w16, b, skip, Z, NB, H, W, CI, COP, pad, 0, 1, 1)
    want = np.zeros((Z, NB, H, W, COP))
    for z in range(Z):
        r = refs[z].transpose(0, 2, 3, 1)
        if z < 1:
            r = r + skip[z, ..., :O_].astype(np.float64)
        want[z, ..., :O_] = np.maximum(r, 0)
    check(f"conv3x3_tc mode 0 Z={Z} NB={NB} {H}x{W} {I_}->{O_} pad {pad}", y.astype(np.float32), want, 2e-3, 2e-3)
    # mode 2: fp32 NCHW, 3 channels of net 0 (ng = 1), 1 of the others
    y = tc_conv(x16, NB * H * W * CI, w16, b, None, Z, NB, H, W, CI, COP, pad, 2, 0, 0, ng=1)
    for z in range(Z):
        co = min(3 if z < 1 else 1, O_)
        check(f"conv3x3_tc mode 2 net {z}", y[z, :, :co], refs[z][:, :co], 1e-3, 1e-3)
    # mode 1: pixel shuffle x2 (COP a multiple of 4), one input shared by every net (xz = 0)
    if COP % 4 == 0:
        y = tc_conv(x16[:1].copy(), 0, w16, b, None, Z, NB, H, W, CI, COP, pad, 1, 0, 0)
        for z in range(Z):
            xr = x16[0, ..., :I_].astype(np.float32).transpose(0, 3, 1, 2)
            wr = w16[z].astype(np.float32).reshape(COP, 9, CI)[:O_, :, :I_].reshape(O_, 3, 3, I_).transpose(0, 3, 1, 2)
            r = np.zeros((NB, COP, H, W))
            r[:, :O_] = conv_ref(xr, wr, bs[z], pad)[0]
            r = r.reshape(NB, COP // 4, 2, 2, H, W).transpose(0, 4, 2, 5, 3, 1).reshape(NB, 2 * H, 2 * W, COP // 4)
            check(f"conv3x3_tc mode 1 (shuffle) net {z}", y[z].astype(np.float32), r, 2e-3, 2e-3)

# views_to_nhwc and views_average: view flags as infer.rs builds them
N, H, W, V = 2, 5, 6, 4
flags_l = [0, 1 | 4, 2 | 8, 3 | 4 | 8]
flags = sum(f << (8 * v) for v, f in enumerate(flags_l))
x = rng.uniform(0, 1, (N, 3, H, W)).astype(np.float32)
y = np.zeros((V * N, H, W, 16), np.float16)
launch("views_to_nhwc", grid1(V * N * H * W), THREADS, x, y.view(np.uint16), I(V), I(N), I(H), I(W), I(16), I(flags))
want = np.zeros((V * N, H, W, 16), np.float32)
for v, f in enumerate(flags_l):
    m = x[:, :, ::-1] if f & 1 else x
    m = m[:, :, :, ::-1] if f & 2 else m
    m = m.copy()
    for c in range(3):
        if (f >> (2 + c)) & 1:
            m[:, c] = 1 - m[:, c]
    want[v * N:(v + 1) * N, ..., :3] = m.transpose(0, 2, 3, 1)
check("views_to_nhwc", y.astype(np.float32), f16(want).astype(np.float32), 0, 0)
Z, CO = 3, 3
s = rnd(Z, V * N, CO, H, W)
for (z0, z1, C, neg, sig) in [(0, 2, 3, 1, 0), (2, 3, 1, 0, 1)]:
    out = np.zeros((N, C, H, W), np.float32)
    launch("views_average", grid1(N * C * H * W), THREADS, s, out, I(z0), I(z1), I(V), I(N), I(CO), I(C), I(H), I(W),
           I(flags), I(neg), I(sig))
    acc = np.zeros((N, C, H, W))
    for v, f in enumerate(flags_l):
        t = s[z0:z1, v * N:(v + 1) * N, :C].astype(np.float64)
        t = 1 / (1 + np.exp(-t)) if sig else t
        t = t.mean(axis=0)
        t = t[:, :, ::-1] if f & 1 else t
        t = t[:, :, :, ::-1] if f & 2 else t
        t = t.copy()
        if neg:
            for c in range(C):
                if (f >> (2 + c)) & 1:
                    t[:, c] = -t[:, c]
        acc += t / V
    check(f"views_average nets {z0}..{z1} C={C} neg={neg} sig={sig}", out, acc, 1e-6, 1e-5)
h = np.zeros(7, np.float16)
vals = np.array([0.1, -2.5, 65504.0, 1e-8, 3.14159, -0.0, 1.0 / 3], np.float32)
launch("f32_to_f16", grid1(7), THREADS, vals, h.view(np.uint16), L(7))
check("f32_to_f16 (round to nearest even)", h.astype(np.float32), vals.astype(np.float16).astype(np.float32), 0, 0)

print(f"\n{len(failures)} failure(s)" + (": " + ", ".join(failures) if failures else ""))
sys.exit(1 if failures else 0)
