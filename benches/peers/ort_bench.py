#!/usr/bin/env python3
"""ONNX Runtime's side of `make bench-peers`: the conv rows and the three nets per frame.

    python benches/peers/ort_bench.py [conv] [nets] [--threads N]

Convs are one-node ONNX graphs (Conv, pads 1, with bias). The nets are the graph
tests/onnx/export_onnx.py builds for anisocb's weights (GeometryNet + BoundaryNet +
EnhanceNet + the cubic U), here with random weights of the small and paper configs: time does
not depend on their values. Session: all graph optimisations, sequential execution,
intra-op threads = the machine's cores (as anisocb's rayon pool).
"""
import os
import sys

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "tests", "onnx"))
import rows  # noqa: E402
import export_onnx as ex  # noqa: E402


def session(model, threads):
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    return ort.InferenceSession(model.SerializeToString(), so, providers=["CPUExecutionProvider"])


def conv_model(n, c, o, h, w, rng):
    wt = numpy_helper.from_array(rng.uniform(-0.5, 0.5, (o, c, 3, 3)).astype(np.float32), "w")
    b = numpy_helper.from_array(rng.uniform(-0.5, 0.5, (o,)).astype(np.float32), "b")
    node = helper.make_node("Conv", ["x", "w", "b"], ["y"], kernel_shape=[3, 3], pads=[1, 1, 1, 1])
    g = helper.make_graph([node], "conv", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [n, c, h, w])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, [n, o, h, w])], initializer=[wt, b])
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", ex.OPSET)])


def nets_model(channels, blocks, rng, size=32):
    cfg = {"channels": channels, "blocks": blocks, "scale": 2, "padding": "zero"}
    g = ex.Graph()
    u = g.node("Resize", ["lr", "", g.const("resize.scales", np.array([1, 1, 2, 2], np.float32))], "u",
               mode="cubic", cubic_coeff_a=-0.5, exclude_outside=0,
               coordinate_transformation_mode="align_corners")
    outs = [u]
    for kind in ex.KINDS:
        arrays = {f"{kind}.{n}": rng.uniform(-0.05, 0.05, s).astype(np.float32)
                  for n, s in ex.param_shapes(kind, cfg)}
        y = ex.add_trunk(g, kind, cfg, arrays, "lr")
        outs.append(g.node("Identity", [y], f"{kind}_out") if kind == "geometry" else g.node("Sigmoid", [y], kind))
    info = [helper.make_tensor_value_info(o, TensorProto.FLOAT, [1, 3 if i < 2 else 1, 2 * size, 2 * size])
            for i, o in enumerate(outs)]
    graph = helper.make_graph(g.nodes, "anisocb", [helper.make_tensor_value_info("lr", TensorProto.FLOAT,
                                                                                [1, 3, size, size])],
                              info, initializer=g.inits)
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", ex.OPSET)])
    onnx.checker.check_model(m)
    return m


def main():
    threads = os.cpu_count()
    if "--threads" in sys.argv:
        threads = int(sys.argv[sys.argv.index("--threads") + 1])
    want = rows.groups([a for a in sys.argv[1:] if not a.isdigit()])
    rng = np.random.default_rng(0)
    if "peak" in want:
        # MLAS SGEMM (ONNX Runtime's own kernel) on a large square MatMul: a known-good
        # measure of what this machine's FMA units deliver, to check anisocb's peak probe by.
        n = rows.SGEMM_N
        b = numpy_helper.from_array(rng.uniform(-1, 1, (n, n)).astype(np.float32), "b")
        gr = helper.make_graph([helper.make_node("MatMul", ["a", "b"], ["y"])], "sgemm",
                               [helper.make_tensor_value_info("a", TensorProto.FLOAT, [n, n])],
                               [helper.make_tensor_value_info("y", TensorProto.FLOAT, [n, n])], initializer=[b])
        s = session(helper.make_model(gr, opset_imports=[helper.make_opsetid("", ex.OPSET)]), threads)
        a = rng.uniform(-1, 1, (n, n)).astype(np.float32)
        ms = rows.median_ms(lambda: s.run(None, {"a": a}), min_calls=5)
        rows.emit(rows.SGEMM_ROW, ms=ms, gflops=2 * n ** 3 / ms / 1e6)
    if "conv" in want:
        for shape in rows.CONVS:
            s = session(conv_model(*shape, rng), threads)
            x = rng.uniform(-0.5, 0.5, shape[:2] + shape[3:]).astype(np.float32)
            rows.emit(rows.conv_row(*shape), rows.median_ms(lambda: s.run(None, {"x": x})))
    if "nets" in want:
        # The CPU provider has no bf16 kernels for these convs: its default is fp32.
        for name, (c, b) in rows.CONFIGS.items():
            for size in rows.NET_SIZES:
                s = session(nets_model(c, b, rng, size), threads)
                x = rng.uniform(0, 1, (1, 3, size, size)).astype(np.float32)
                ms = rows.median_ms(lambda: s.run(None, {"lr": x}))
                rows.emit(rows.nets_row(name, size), ms, precision="fp32")


if __name__ == "__main__":
    main()
