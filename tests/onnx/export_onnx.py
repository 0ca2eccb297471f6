#!/usr/bin/env python3
"""Export an anisocb weights bundle (.npz) to one ONNX model.

    python tests/onnx/export_onnx.py weights/anisocb-x2.npz anisocb-x2.onnx

The model computes exactly what `AnisoCb::forward` (src/nn/bundle.rs) computes:

    lr (N, 3, H, W)  ->  u        (N, 3, rH, rW)  cubic x r, align corners (Keys a = -0.5,
                                                  Catmull-Rom, or -0.75: config `upsample`)
                         r        (N, 3, rH, rW)  GeometryNet's residual R
                         boundary (N, 1, rH, rW)  sigmoid(BoundaryNet logits)   = Gamma_b
                         enhance  (N, 1, rH, rW)  sigmoid(EnhanceNet logits)    = Gamma_e

Op mapping (src/nn/layers.rs `Trunk::run`, src/ops/*):
  conv 3x3, stride 1, bias, "same"   -> Conv(pads=1)                     (padding "zero")
                                        Pad(mode=edge, 1 px) + Conv(pads=0) (padding "replicate")
  relu                                -> Relu
  residual block a + conv2(relu(conv1(a))) (GeometryNet only) -> Add
  pixel shuffle (PyTorch order: y[c, h*r+i, w*r+j] = x[c*r*r + i*r + j, h, w])
                                      -> DepthToSpace(blocksize=r, mode=CRD)
  cubic align-corners resize (src/ops/resample.rs: s = d*(in-1)/(out-1), taps clamped to
  the border) -> Resize(mode=cubic, cubic_coeff_a=A, exclude_outside=0,
                        coordinate_transformation_mode=align_corners, scales=[1,1,r,r])
  sigmoid                             -> Sigmoid

Nothing of the upscale pipeline around the nets (cloth frame, border pinning, temporal
smoothing, Eq 12, strain limit) is in the graph: see tests/onnx/README.md.
"""

import argparse
import hashlib
import json
import sys
import zipfile

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
KINDS = ("geometry", "boundary", "enhance")
# config `upsample` -> Keys' a (src/ops/resample.rs `cubic_a`)
CUBIC_A = {"catmull-rom": -0.5, "bicubic": -0.75}
UPSAMPLE_DOC = {"catmull-rom": "Catmull-Rom",
                "bicubic": "PyTorch F.interpolate(mode='bicubic', align_corners=True)"}
# What this build of anisocb supports (src/nn/config.rs); a bundle claiming otherwise is refused.
IN_CHANNELS, TAIL_CONVS, KERNEL = 3, 4, 3


def load_bundle(path):
    """(configs, arrays) of a bundle: configs[kind] = parsed config.json, arrays[name] = float32."""
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        configs = {}
        for k in KINDS:
            entry = f"{k}.config.json"
            if entry not in names:
                sys.exit(f"{path}: no '{entry}': not an anisocb bundle (weights/README.md)")
            configs[k] = json.loads(z.read(entry).decode("utf-8"))
        # An ensemble's further GeometryNets (`geometry1.`, …): the first's configuration.
        k = 1
        while f"geometry{k}.config.json" in names:
            c = json.loads(z.read(f"geometry{k}.config.json").decode("utf-8"))
            if c != configs["geometry"]:
                sys.exit(f"{path}: geometry{k}.config.json differs from geometry.config.json")
            configs[f"geometry{k}"] = c
            k += 1
    with np.load(path, allow_pickle=False) as npz:
        arrays = {n: npz[n] for n in npz.files if not n.endswith("config.json")}
    for k, c in configs.items():
        if c.get("kind") != k.rstrip("0123456789"):
            sys.exit(f"{path}: {k}.config.json says kind {c.get('kind')!r}")
        for key, want in (("in_channels", IN_CHANNELS), ("tail_convs", TAIL_CONVS), ("kernel", KERNEL)):
            if key in c and c[key] != want:
                sys.exit(f"{path}: {k}.config.json: {key} = {c[key]}, only {want} is supported")
        if c["padding"] not in ("zero", "replicate"):
            sys.exit(f"{path}: {k}.config.json: unknown padding {c['padding']!r}")
    for key in ("scale", "input"):
        vals = {configs[k].get(key, "domain" if key == "input" else None) for k in KINDS}
        if len(vals) != 1:
            sys.exit(f"{path}: the three nets differ in '{key}': {sorted(map(str, vals))}")
    up = configs["geometry"].get("upsample", "bicubic")
    if up not in CUBIC_A:
        sys.exit(f"{path}: geometry.config.json: unknown upsample {up!r} (expected {sorted(CUBIC_A)})")
    return configs, arrays


def param_shapes(kind, cfg):
    """Names and shapes of every parameter, canonical order (src/nn/layers.rs `param_shapes`)."""
    c, r = cfg["channels"], cfg["scale"]
    out = 3 if kind == "geometry" else 1
    convs = [("conv_in", c, IN_CHANNELS)]
    for k in range(cfg["blocks"]):
        convs += [(f"blocks.{k}.conv1", c, c), (f"blocks.{k}.conv2", c, c)]
    convs.append(("upscale", c * r * r, c))
    convs += [(f"tail.{i}", out if i + 1 == TAIL_CONVS else c, c) for i in range(TAIL_CONVS)]
    for name, o, i in convs:
        yield f"{name}.weight", (o, i, KERNEL, KERNEL)
        yield f"{name}.bias", (o,)


class Graph:
    def __init__(self):
        self.nodes, self.inits = [], []

    def node(self, op, inputs, name, **attrs):
        out = name
        self.nodes.append(helper.make_node(op, inputs, [out], name=name, **attrs))
        return out

    def const(self, name, value):
        self.inits.append(numpy_helper.from_array(value, name))
        return name


def add_trunk(g, kind, cfg, arrays, x, prefix=None):
    """Append one net (`Trunk::run`) reading tensor `x`; returns its output (R or logits).
    `prefix`: its arrays' prefix in the bundle (default `kind`; `geometry1`, … for an
    ensemble's further GeometryNets)."""
    prefix = prefix or kind
    want = dict(param_shapes(kind, cfg))
    have = {n[len(prefix) + 1:] for n in arrays if n.startswith(prefix + ".")}
    missing = [n for n in want if n not in have]
    extra = sorted(have - set(want))
    wrong = [n for n, s in want.items() if n in have and arrays[f"{prefix}.{n}"].shape != s]
    if missing or extra or wrong:
        sys.exit(f"{prefix}: weights do not match config: missing {missing}, unexpected {extra}, "
                 f"wrong shape {wrong}")
    for n in want:
        a = arrays[f"{prefix}.{n}"]
        if a.dtype != np.float32 or not np.all(np.isfinite(a)):
            sys.exit(f"{prefix}.{n}: expected finite float32, got {a.dtype}")
        g.const(f"{prefix}.{n}", a)
    replicate = cfg["padding"] == "replicate"
    p = KERNEL // 2
    pads_const = None
    if replicate:
        pads_const = g.const(f"{prefix}.pads", np.array([0, 0, p, p, 0, 0, p, p], dtype=np.int64))

    def conv(name, inp):
        tag = f"{prefix}/{name}"
        if replicate:
            inp = g.node("Pad", [inp, pads_const], f"{tag}/pad_edge", mode="edge")
            pads = [0, 0, 0, 0]
        else:
            pads = [p, p, p, p]
        return g.node("Conv", [inp, f"{prefix}.{name}.weight", f"{prefix}.{name}.bias"], tag,
                      kernel_shape=[KERNEL, KERNEL], strides=[1, 1], dilations=[1, 1],
                      group=1, pads=pads)

    a = conv("conv_in", x)
    for k in range(cfg["blocks"]):
        t = conv(f"blocks.{k}.conv1", a)
        t = g.node("Relu", [t], f"{prefix}/blocks.{k}.relu")
        t = conv(f"blocks.{k}.conv2", t)
        a = g.node("Add", [t, a], f"{prefix}/blocks.{k}") if kind == "geometry" else t
    z = conv("upscale", a)
    z = g.node("DepthToSpace", [z], f"{prefix}/pixel_shuffle", blocksize=cfg["scale"], mode="CRD")
    for i in range(TAIL_CONVS):
        z = conv(f"tail.{i}", z)
        if i + 1 < TAIL_CONVS:
            z = g.node("Relu", [z], f"{prefix}/tail.{i}.relu")
    return z


DOC = """anisocb x{r} super-resolution nets (GeometryNet, BoundaryNet, EnhanceNet) = AnisoCb::forward.

Input `lr`: float32 (N, 3, H, W), N LR geometry images (x, y, z of grid vertex (row h, col w)
in channels 0..2) already in the nets' input frame `{frame}`.
{frame_doc}
Outputs, all (N, ., {r}H, {r}W) in the same frame: `u` = cubic align-corners x{r} of lr (Keys
a = {a}: {upsample}); `r` = GeometryNet's
residual R; `boundary` = Gamma_b = sigmoid(BoundaryNet logits); `enhance` = Gamma_e =
sigmoid(EnhanceNet logits). anisocb's pipeline runs the model on the LR grid's four mirror
images (each in its own frame; `--mirrors false` skips it) and averages R, Gamma_b and Gamma_e
mapped back onto the grid, then (with `--pin-border` only) sets Gamma_b = 1 on the border
pixels, with `--temporal k` (off by default) averages R, Gamma_b and Gamma_e over +-k frames
(binomial, cloth-frame models), maps u (points) and R
(displacements) back out of the frame and composes HR = U + (1 - Gamma_b)(1 + eta Gamma_e) R
(eta = 0 by default); see tests/onnx/README.md."""

FRAME_DOC = {
    "cloth-frame": (
        "cloth-frame (src/geom/cloth_frame.rs): per frame, with o = centroid of the LR vertices\n"
        "(metres), L = mean grid edge length * (max(W, H) - 1), Rot = [e1 e2 e1xe2] the polar\n"
        "factor of M = sum (p - o)(q - qbar)^T, q = (col, row): n = Rot^T (p - o) / L + 1/2\n"
        "(a flat square sheet fills [0,1]^2 x {1/2}); back with p = o + L Rot (n - 1/2), and\n"
        "the residual, a displacement, with d = L Rot r."),
    "domain": (
        "domain (Eq 1): each coordinate normalised by the sequence's bounding box,\n"
        "n = (p - bmin) / (bmax - bmin), so in [0, 1]."),
}


def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def build(path):
    configs, arrays = load_bundle(path)
    cfg0 = configs["geometry"]
    r, frame = cfg0["scale"], cfg0.get("input", "domain")
    upsample = cfg0.get("upsample", "bicubic")
    g = Graph()
    u = g.node("Resize", ["lr", "", g.const("resize.scales", np.array([1, 1, r, r], np.float32))], "u",
               mode="cubic", cubic_coeff_a=CUBIC_A[upsample], exclude_outside=0,
               coordinate_transformation_mode="align_corners")
    outs = {"u": u}
    more = sorted((k for k in configs if k not in KINDS), key=lambda k: int(k[len("geometry"):]))
    for kind in KINDS:
        y = add_trunk(g, kind, configs[kind], arrays, "lr")
        if kind == "geometry" and more:
            # An ensemble (AnisoCb::forward_with): R = (R_0 + R_1 + …) · (1/K).
            ys = [y] + [add_trunk(g, "geometry", configs[k], arrays, "lr", prefix=k) for k in more]
            total = g.node("Sum", ys, "geometry/ensemble_sum")
            scale = g.const("geometry.ensemble_scale", np.array(1.0 / len(ys), np.float32))
            outs["r"] = g.node("Mul", [total, scale], "r")
        elif kind == "geometry":
            outs["r"] = g.node("Identity", [y], "r")
        else:
            outs[kind] = g.node("Sigmoid", [y], kind)
    lr_info = helper.make_tensor_value_info("lr", TensorProto.FLOAT, ["N", 3, "H", "W"])
    out_info = [helper.make_tensor_value_info(n, TensorProto.FLOAT,
                                              ["N", 3 if n in ("u", "r") else 1, f"{r}H", f"{r}W"])
                for n in ("u", "r", "boundary", "enhance")]
    doc = DOC.format(r=r, frame=frame, frame_doc=FRAME_DOC.get(frame, ""), a=CUBIC_A[upsample],
                     upsample=UPSAMPLE_DOC[upsample])
    graph = helper.make_graph(g.nodes, "anisocb", [lr_info], out_info, initializer=g.inits, doc_string=doc)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="anisocb tests/onnx/export_onnx.py", producer_version="1",
                              doc_string=doc)
    model.ir_version = 8  # opset 17 needs IR >= 8; keep it low so older runtimes load it
    sha = sha256(path)
    meta = {
        "anisocb.weights_sha256": sha,
        "anisocb.weights_file": str(path).replace("\\", "/").split("/")[-1],
        "anisocb.scale": str(r),
        "anisocb.input_frame": frame,
        "anisocb.outputs": "u, r, boundary, enhance (AnisoCb::forward)",
        "anisocb.eq12": "hr = u + (1 - boundary) * (1 + eta * enhance) * r, boundary = 1 on border pixels, eta = 0.5",
    }
    for k in configs:
        meta[f"anisocb.{k}.config"] = json.dumps(configs[k], separators=(",", ":"))
    helper.set_model_props(model, meta)
    return model, configs, sha


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("weights", help="anisocb bundle .npz (e.g. weights/anisocb-x2.npz)")
    ap.add_argument("out", help="output .onnx")
    a = ap.parse_args()
    model, configs, sha = build(a.weights)
    onnx.checker.check_model(model, full_check=True)
    onnx.save_model(model, a.out)
    onnx.checker.check_model(a.out, full_check=True)
    n_params = sum(int(np.prod(t.dims)) for t in model.graph.initializer if t.name.endswith((".weight", ".bias")))
    c = configs["geometry"]
    print(f"wrote {a.out}: opset {OPSET}, {len(model.graph.node)} nodes, {n_params} parameters, "
          f"C={c['channels']}, {c['blocks']} blocks, x{c['scale']}, padding "
          f"{'/'.join(configs[k]['padding'] for k in KINDS)}, input {c.get('input', 'domain')}, "
          f"weights sha256 {sha[:16]}…; onnx.checker passed")


if __name__ == "__main__":
    main()
