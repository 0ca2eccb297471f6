#!/usr/bin/env python3
"""Check that ONNX Runtime on the exported model matches anisocb.

    python tests/onnx/check_onnx.py --onnx anisocb-x2.onnx

Needs a built `target/release/anisocb` (copied to a temp dir first, so a rebuild under it does
no harm) and the packages of tests/onnx/requirements.txt. Exits 1 if any check fails.

1. nets:     the held-out demo frames (flag-sphere, seed 1000), put in the nets' input frame by
             anisocb itself (`anisocb dataset`, the same `InputFrame::image_maps` as upscale),
             through `anisocb audit` and through ONNX Runtime: u, r, boundary, enhance.
2. pipeline: the README recipe in numpy (cloth frame, the grid's four mirrors each in its
             own frame, temporal smoothing, back to the domain, Eq 12) around ONNX Runtime,
             against `anisocb upscale`'s geometry.npy.
3. padding:  the same weights relabelled with the other padding (zero <-> replicate: the
             Conv(pads=1) or the Pad(mode=edge) + Conv path, whichever the shipped model does
             not use), exported and compared with anisocb's audit of that file.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile

import numpy as np
import onnx
import onnxruntime as ort

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import export_onnx  # noqa: E402

OUTPUTS = ("u", "r", "boundary", "enhance")
# Where `anisocb audit` of a bundle writes each output (src/nn/audit.rs).
AUDIT_FILE = {"u": "geometry/interp.npy", "r": "geometry/tail.3.npy",
              "boundary": "boundary/sigmoid.npy", "enhance": "enhance/sigmoid.npy"}
# Tolerances on max |ORT - anisocb| (see README.md "Tolerances"):
#  u:   pure interpolation (16 taps); only the f32 source coordinate may round differently
#       -> 1e-5 of u's range.
#  r:   14 convs of 288 / 27 terms, f32, different accumulation order (MLAS vs anisocb's SIMD)
#       -> 1e-4 of r's range. R is small next to the activations it is computed from, so
#       this is the strictest place to see rounding.
#  maps: probabilities; sigmoid's derivative <= 1/4 and MLAS's sigmoid is a rational
#       approximation (~1e-7) -> 1e-5 absolute, i.e. of their nominal [0, 1] range.
#  A wrong layout (padding mode, DepthToSpace order, resize mode) differs by 1e-2 .. 1 of
#  the range; the check prints such a difference as a control.
TOL = {"u": ("range", 1e-5), "r": ("range", 1e-4), "boundary": ("abs", 1e-5), "enhance": ("abs", 1e-5),
       "hr": ("range", 1e-5)}


def run(cmd, **kw):
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if p.returncode != 0:
        sys.exit(f"failed: {' '.join(map(str, cmd))}\n{p.stdout}{p.stderr}")
    return time.perf_counter() - t, p.stdout + p.stderr


def session(model, threads):
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    src = model.SerializeToString() if isinstance(model, onnx.ModelProto) else model
    return ort.InferenceSession(src, so, providers=["CPUExecutionProvider"])


def ort_run(sess, x):
    sess.run(None, {"lr": x[:1]})  # warm-up (first-run allocation)
    t = time.perf_counter()
    out = dict(zip(OUTPUTS, sess.run(None, {"lr": x})))
    return out, time.perf_counter() - t


def compare(name, got, ref, failures, expect_pass=True):
    """Print the largest differences; add `name` to `failures` unless it passes as expected."""
    if got.shape != ref.shape:
        print(f"  {name:9s} FAIL shape {got.shape} vs anisocb {ref.shape}")
        failures.append(name)
        return
    d = np.abs(got.astype(np.float64) - ref.astype(np.float64))
    rng = float(ref.max() - ref.min())
    worst = float(d.max())
    kind, tol = TOL.get(name, TOL["hr"])
    limit = tol * rng if kind == "range" else tol
    ok = worst <= limit and np.all(np.isfinite(got))
    where = np.unravel_index(int(d.argmax()), d.shape)
    verdict = ("ok  " if ok else "FAIL") if expect_pass else ("FAIL (as expected)" if not ok else "PASSED?!")
    print(f"  {name:9s} {verdict} max|diff| {worst:.3e}  /range {worst / max(rng, 1e-30):.3e}"
          f"  (range {rng:.4g}; limit {limit:.3e} = {tol:g}{' x range' if kind == 'range' else ' abs'})"
          f"  at {tuple(int(i) for i in where)}")
    if ok != expect_pass:
        failures.append(name)


def nets_frames(exe, env, work, tag, scenario, res, frames, seed):
    """Simulate a run and put its LR frames in the nets' frame with anisocb itself."""
    run_dir, ds = os.path.join(work, tag), os.path.join(work, f"{tag}.npz")
    cmd = [exe, "simulate", "--scenario", scenario, "--frames", str(frames), "--seed", str(seed),
           "--pair", "--out", run_dir] + (["--res", res] if res else [])
    run(cmd, env=env)
    run([exe, "dataset", "--runs", run_dir, "--out", ds, "--input-frame", "cloth-frame"], env=env)
    with np.load(ds) as z:
        return run_dir, np.ascontiguousarray(z["lr"], dtype=np.float32)


def check_nets(exe, env, work, tag, weights, sess, x, failures):
    """ORT vs `anisocb audit` on x; returns (ORT outputs, ORT seconds, audit seconds)."""
    xin = os.path.join(work, f"{tag}_in.npy")
    np.save(xin, x)
    t_audit, _ = run([exe, "audit", "--weights", weights, "--input", xin,
                      "--out", os.path.join(work, f"{tag}_audit")], env=env)
    got, t_ort = ort_run(sess, x)
    for name in OUTPUTS:
        compare(name, got[name], audit_output(os.path.join(work, f"{tag}_audit"), name), failures)
    return got, t_ort, t_audit


def audit_output(audit_dir, name):
    """What `anisocb audit` says the model outputs as `name`; for an ensemble bundle, r is the
    mean of its GeometryNets' residuals (`geometry/`, `geometry1/`, … summed in that order,
    times 1/K in float32, as AnisoCb::forward_with)."""
    ref = np.load(os.path.join(audit_dir, AUDIT_FILE[name]))
    if name != "r":
        return ref
    k = 1
    while os.path.isdir(os.path.join(audit_dir, f"geometry{k}")):
        ref = ref + np.load(os.path.join(audit_dir, f"geometry{k}", "tail.3.npy"))
        k += 1
    return ref if k == 1 else (ref * np.float32(1.0 / k)).astype(np.float32)


# ---- the pipeline around the nets, in numpy (src/sr/upscale.rs, src/geom/cloth_frame.rs) ----

def polar_3x2(a, b):
    """cloth_frame.rs `polar_3x2`: orthonormal polar factor of [a b] (Gram-Schmidt if rank <= 1)."""
    def normalize_or(v, fb):
        n = np.sqrt(v @ v)
        return v / n if n > 0 else np.array(fb, float)
    saa, sab, sbb = a @ a, a @ b, b @ b
    det, tr = saa * sbb - sab * sab, saa + sbb
    if tr > 0 and det > 1e-10 * tr * tr:
        sd = np.sqrt(det)
        t = np.sqrt(tr + 2 * sd)
        p, q, r = (saa + sd) / t, sab / t, (sbb + sd) / t
        dd = p * r - q * q
        ip, iq, ir = r / dd, -q / dd, p / dd
        return normalize_or(a * ip + b * iq, [1, 0, 0]), normalize_or(a * iq + b * ir, [0, 1, 0])
    swap = sbb > saa
    long, short = (b, a) if swap else (a, b)
    u = normalize_or(long, [1, 0, 0])
    v = short - u * (short @ u)
    if v @ v < 1e-20 * (1 + tr):
        helper = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
        v = helper - u * (helper @ u)
    v = normalize_or(v, [0, 0, 1])
    return (v, u) if swap else (u, v)


def frame_maps(img, bmin, bmax):
    """`InputFrame::Cloth.image_maps` for one (3, H, W) image in the domain: (to_net, from_net),
    each (m 3x3, t 3) in float64."""
    _, h, w = img.shape
    ext32 = (bmax - bmin).astype(np.float32)
    pos = (bmin[:, None, None] + img * ext32[:, None, None]).astype(np.float32)  # Eq 2, f32
    p = pos.astype(np.float64).transpose(1, 2, 0)  # (H, W, 3): vertex (col i, row j) at [j, i]
    o = p.reshape(-1, 3).mean(0)
    lens = np.concatenate([np.linalg.norm(p[:, 1:] - p[:, :-1], axis=2).ravel(),
                           np.linalg.norm(p[1:] - p[:-1], axis=2).ravel()])
    unit = lens.mean() * max(max(w, h) - 1, 1)
    d = p - o
    a = (d * (np.arange(w) - (w - 1) / 2)[None, :, None]).sum((0, 1))
    b = (d * (np.arange(h) - (h - 1) / 2)[:, None, None]).sum((0, 1))
    e1, e2 = polar_3x2(a, b)
    if not (np.isfinite(unit) and unit > 0 and np.all(np.isfinite(np.r_[e1, e2]))):
        unit, e1, e2 = 1.0, np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    if not np.all(np.isfinite(o)):
        o = np.zeros(3)
    rot = np.stack([e1, e2, np.cross(e1, e2)], axis=1)  # columns e1 e2 e3
    ext = ext32.astype(np.float64)
    # to_net = cf.to_net ∘ decode;  from_net = encode ∘ cf.from_net
    m_to = rot.T / unit
    t_to = 0.5 - m_to @ o
    m_from = rot * unit
    t_from = o - m_from @ np.full(3, 0.5)
    return ((m_to * ext[None, :], m_to @ bmin.astype(np.float64) + t_to),
            (m_from / ext[:, None], (t_from - bmin.astype(np.float64)) / ext))


def apply(aff, img, as_points):
    """`Affine::apply_image` on (3, H, W) f32."""
    m, t = aff
    y = np.einsum("rc,chw->rhw", m, img.astype(np.float64))
    if as_points:
        y = y + t[:, None, None]
    return y.astype(np.float32)


def smooth_in_time(x, k):
    """upscale.rs `smooth_in_time`: binomial weights of radius k, renormalised at the ends."""
    w = np.array([1.0])
    for _ in range(2 * k):
        w = np.convolve(w, [1.0, 1.0])
    out = np.zeros_like(x)
    t = x.shape[0]
    for f in range(t):
        lo, hi = max(f - k, 0), min(f + k, t - 1)
        norm = sum(w[g + k - f] for g in range(lo, hi + 1))
        for g in range(lo, hi + 1):
            out[f] += np.float32(w[g + k - f] / norm) * x[g]
    return out


def compose_maps(a, b):
    """`Affine::after`: a ∘ b."""
    return a[0] @ b[0], a[0] @ b[1] + a[1]


def upscale_numpy(sess, lr, domain, input_frame, eta=0.0, temporal=2, pin_border=False, mirrors=True):
    """The anisocb upscale pipeline (defaults: border not pinned, eta 0, no strain limit,
    mirror averaging; temporal smoothing is off by default, radius 2 here as the check runs it)
    around the ONNX model; lr (T, 3, H, W) in the domain -> (hr, boundary, enhance, x)."""
    bmin, bmax = domain[0], domain[1]
    ident = (np.eye(3), np.zeros(3))
    if input_frame != "cloth-frame":  # "domain": the nets read the stored geometry image
        temporal = 0  # and their residuals are not smoothed in time

    def frame_maps_of(img):
        return frame_maps(img, bmin, bmax) if input_frame == "cloth-frame" else (ident, ident)

    maps = [frame_maps_of(img) for img in lr]
    x = np.stack([apply(m[0], img, True) for m, img in zip(maps, lr)])
    o = dict(zip(OUTPUTS, sess.run(None, {"lr": x})))
    if mirrors:
        # `upscale --mirrors`: every mirror of the LR grid gets its own cloth frame, computed
        # from scratch here (upscale.rs derives it from the grid mirror, cloth_frame.rs
        # `mirror_net_images`); its R goes back through that frame to the domain and into the
        # unmirrored frame, its maps back onto the unmirrored grid; the four are averaged.
        r_sum, b_sum, e_sum = o["r"].astype(np.float64), o["boundary"].astype(np.float64), \
            o["enhance"].astype(np.float64)
        for rows, cols in ((False, True), (True, False), (True, True)):
            axes = tuple(ax for ax, f in ((-2, rows), (-1, cols)) if f)
            lr_m = np.ascontiguousarray(np.flip(lr, axis=axes))
            maps_m = [frame_maps_of(img) for img in lr_m]
            x_m = np.stack([apply(m[0], img, True) for m, img in zip(maps_m, lr_m)])
            om = dict(zip(OUTPUTS, sess.run(None, {"lr": x_m})))
            r_m = np.stack([apply(compose_maps(m[0], mm[1]), img, False)
                            for m, mm, img in zip(maps, maps_m, om["r"])])
            r_sum += np.flip(r_m, axis=axes)
            b_sum += np.flip(om["boundary"], axis=axes)
            e_sum += np.flip(om["enhance"], axis=axes)
        o["r"], o["boundary"], o["enhance"] = (np.float32(v / 4) for v in (r_sum, b_sum, e_sum))
    gb = o["boundary"].copy()
    if pin_border:  # `upscale --pin-border`: set_border
        gb[:, :, 0, :] = gb[:, :, -1, :] = gb[:, :, :, 0] = gb[:, :, :, -1] = 1.0
    r, ge = o["r"], o["enhance"]
    if temporal > 0:  # R and the maps that gate it, the same window (upscale.rs `finish`)
        r, gb, ge = (smooth_in_time(v, temporal) for v in (r, gb, ge))
    u = np.stack([apply(m[1], img, True) for m, img in zip(maps, o["u"])])
    r = np.stack([apply(m[1], img, False) for m, img in zip(maps, r)])
    gain = (np.float32(1) - gb) * (np.float32(1) + np.float32(eta) * ge)  # Eq 12
    return u + gain * r, gb, ge, x


def padding_of(path):
    """The padding of the first net's config.json in a bundle."""
    with zipfile.ZipFile(path) as z:
        name = next(n for n in z.namelist() if n.endswith("config.json"))
        return json.loads(z.read(name))["padding"]


def relabel_padding(src, dst, padding):
    """Copy a bundle with every config.json's padding set to `padding` (same arrays)."""
    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w", zipfile.ZIP_STORED) as zo:
        for n in zi.namelist():
            data = zi.read(n)
            if n.endswith("config.json"):
                c = json.loads(data)
                c["padding"] = padding
                data = json.dumps(c).encode()
            zo.writestr(n, data)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--onnx", help="model from export_onnx.py (default: export --weights in memory)")
    ap.add_argument("--weights", default=os.path.join(REPO, "weights", "anisocb-x2.npz"))
    ap.add_argument("--anisocb", default=os.path.join(REPO, "target", "release", "anisocb"),
                    help="anisocb binary (copied to the temp dir before use)")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--threads", type=int, default=2, help="threads for ORT and anisocb (info timings)")
    ap.add_argument("--keep", help="keep the work files in this directory")
    a = ap.parse_args()

    work = a.keep or tempfile.mkdtemp(prefix="anisocb-onnx-")
    os.makedirs(work, exist_ok=True)
    if not os.path.isfile(a.anisocb):
        sys.exit(f"{a.anisocb}: no such binary (build it with `cargo build --release`)")
    exe = os.path.join(work, "anisocb")
    shutil.copy2(a.anisocb, exe)
    env = dict(os.environ, RAYON_NUM_THREADS=str(a.threads))
    failures = []
    try:
        # The ONNX model, and that it is of these weights.
        if a.onnx:
            model = onnx.load(a.onnx)
        else:
            model, _, _ = export_onnx.build(a.weights)
            onnx.checker.check_model(model, full_check=True)
        meta = {p.key: p.value for p in model.metadata_props}
        sha = export_onnx.sha256(a.weights)
        if meta.get("anisocb.weights_sha256") != sha:
            sys.exit(f"the ONNX model was exported from weights sha256 {meta.get('anisocb.weights_sha256')}, "
                     f"{a.weights} has {sha}")
        print(f"ONNX model: {a.onnx or '(exported now)'} of {a.weights} (sha256 {sha[:16]}…), "
              f"input frame {meta.get('anisocb.input_frame')}; onnxruntime {ort.__version__}, "
              f"onnx {onnx.__version__}, numpy {np.__version__}")
        sess = session(model, a.threads)

        # Demo frames: the held-out flag-sphere, LR 32x32 (with --pair for `anisocb dataset`).
        run_dir, x = nets_frames(exe, env, work, "run", "flag-sphere", "32x32", a.frames, 1000)
        n = x.shape[0]

        # 1. The nets on the same tensor.
        print(f"\n1. nets: {n} frames {x.shape[2]}x{x.shape[3]} in the nets' frame (anisocb dataset), "
              f"ONNX Runtime vs anisocb audit")
        got, t_ort, t_audit = check_nets(exe, env, work, "demo", a.weights, sess, x, failures)

        # 2. The whole pipeline: numpy + ORT vs anisocb upscale (defaults, eta 0, and temporal 2).
        print(f"\n2. pipeline: README recipe (numpy cloth frame + ORT on the grid's four mirrors + "
              f"temporal 2 + Eq 12, eta 0) vs anisocb upscale")
        up = os.path.join(work, "up")
        # `--temporal 2` (off by default) so the check covers the temporal window too.
        t_up, _ = run([exe, "upscale", os.path.join(run_dir, "lr"), "--weights", a.weights, "--out", up,
                       "--maps", "--temporal", "2", "--threads", str(a.threads)], env=env)
        lr_dom = np.load(os.path.join(run_dir, "lr", "geometry.npy"))
        domain = np.load(os.path.join(run_dir, "lr", "domain.npy"))
        hr, gb, ge, x_np = upscale_numpy(sess, lr_dom, domain, meta.get("anisocb.input_frame"))
        compare("frame in", x_np, x, failures)
        compare("hr", hr, np.load(os.path.join(up, "geometry.npy")), failures)
        compare("boundary", gb, np.load(os.path.join(up, "boundary.npy")), failures)
        compare("enhance", ge, np.load(os.path.join(up, "enhance.npy")), failures)

        # 3. The other padding (zero <-> replicate), on the first 4 frames.
        other = "zero" if padding_of(a.weights) == "replicate" else "replicate"
        print(f"\n3. {other} padding: the same weights relabelled padding={other}, ORT vs anisocb audit")
        rep = os.path.join(work, f"{other}.npz")
        relabel_padding(a.weights, rep, other)
        rep_model, _, _ = export_onnx.build(rep)
        onnx.checker.check_model(rep_model, full_check=True)
        check_nets(exe, env, work, "rep", rep, session(rep_model, a.threads), x[:4], failures)
        print(f"   control: the shipped padding against the {other} audit (what a padding mistake gives)")
        for name in ("r", "boundary", "enhance"):
            compare(name, got[name][:4], audit_output(os.path.join(work, "rep_audit"), name),
                    failures, expect_pass=False)

        # 4. Other shapes (dynamic N, H, W): the twist strip, 32x10 vertices, and a 7x13 crop of it.
        _, xt = nets_frames(exe, env, work, "twist", "twist", None, 4, 3)
        for tag, xs in (("twist", xt), ("crop", np.ascontiguousarray(xt[:3, :, :7, :13]))):
            print(f"\n4. shape {xs.shape} ({'twist, seed 3' if tag == 'twist' else 'a 7x13 crop of it'}), "
                  f"ORT vs anisocb audit")
            check_nets(exe, env, work, tag, a.weights, sess, xs, failures)

        print(f"\ntimings (information only, {a.threads} threads, wall, includes I/O): "
              f"ORT {1e3 * t_ort / n:.1f} ms/frame (nets only); "
              f"anisocb audit {1e3 * t_audit / n:.1f} ms/frame (nets + writing every layer as .npy); "
              f"anisocb upscale {1e3 * t_up / n:.1f} ms/frame (whole command: load, nets, pipeline, write)")
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    if failures:
        print(f"\nFAIL: {', '.join(failures)}")
        sys.exit(1)
    print("\nall checks passed")


if __name__ == "__main__":
    main()
