#!/usr/bin/env python3
"""`make bench-peers`: anisocb, ONNX Runtime, OpenVINO and JAX/XLA timed side by side, interleaved.

    python benches/peers/run.py [--rounds 3] [--out target/bench-peers.md] [GROUP ...]

GROUP: peak, conv, nets, train (default: all). Each round runs anisocb (cargo bench --bench
peers), then ONNX Runtime (ort_bench.py), then OpenVINO (ov_bench.py, the nets only), then JAX
(jax_bench.py), each a fresh process timing every row (median of its calls); rounds repeat
A B C D A B C D ... so all see the same machine state. The tables give, per row, the median over
rounds and the range, and the ratio peer time / anisocb time (> 1: anisocb is faster). Training
rows are samples/s (32 per step), ratio anisocb samples/s / peer samples/s (the same sense).
The nets table compares each side as it runs without being told (its default precision, named
in each cell: anisocb and OpenVINO pick bf16 on a CPU with AMX) and, apart, both forced to fp32.
Nothing else should run meanwhile.
"""
import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
import rows  # noqa: E402

SIDES = {
    "anisocb": lambda g: ["cargo", "bench", "-q", "--bench", "peers", "--"] + g,
    "onnxruntime": lambda g: [sys.executable, os.path.join(HERE, "ort_bench.py")] + [x for x in g if x != "train"],
    "openvino": lambda g: [sys.executable, os.path.join(HERE, "ov_bench.py")] + ["nets"] if "nets" in g else None,
    "jax": lambda g: [sys.executable, os.path.join(HERE, "jax_bench.py")] + [x for x in g if x != "peak"],
}


def run_side(cmd):
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    out = {}
    for line in p.stdout.splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            out[d["row"]] = d
    return out


def cpu_name():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def nets_table(got, series, cell):
    """The three nets per frame: each side at its default precision, the ratios to anisocb's
    default (taken round by round: each peer ran right after anisocb), and anisocb and OpenVINO
    forced to fp32."""
    out = ["| nets, one frame | anisocb default | OpenVINO default | ONNX Runtime | JAX/XLA | "
           "OpenVINO ÷ anisocb | ONNX Runtime ÷ anisocb | anisocb fp32 | OpenVINO fp32 |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def side(s, row):
        ms, prec = series(s, row, "ms"), series(s, row, "precision")
        text = cell(ms, lambda x: f"{x:.2f}") + (" ms" if ms else "")
        return text + (f" {'/'.join(sorted(set(prec)))}" if prec else "")

    for name in rows.CONFIGS:
        for size in rows.NET_SIZES:
            d, f = rows.nets_row(name, size), rows.nets_row(name, size, "fp32")
            txt = {s: side(s, d) for s in ("anisocb", "openvino", "onnxruntime", "jax")}
            fp = {s: side(s, f) for s in ("anisocb", "openvino")}

            def ratio(peer):
                # Round by round (the two ran one after the other), then the median and range;
                # then each side's fastest round against the other's: on a shared host whose
                # speed drifts by 2× within minutes, the quietest moment each side saw.
                pairs = [p[d]["ms"] / a[d]["ms"] for a, p in zip(got["anisocb"], got[peer]) if d in a and d in p]
                if not pairs:
                    return "—"
                m = statistics.median(pairs)
                if len(pairs) == 1:
                    return f"**{m:.2f}×**"
                best = min(series(peer, d, "ms")) / min(series("anisocb", d, "ms"))
                return f"**{m:.2f}×** ({min(pairs):.2f}–{max(pairs):.2f}); fastest rounds {best:.2f}×"

            out.append(f"| {name} {size}² → {2 * size}² | {txt['anisocb']} | {txt['openvino']} | "
                       f"{txt['onnxruntime']} | {txt['jax']} | {ratio('openvino')} | {ratio('onnxruntime')} | "
                       f"{fp['anisocb']} | {fp['openvino']} |")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "target", "bench-peers.md"))
    ap.add_argument("groups", nargs="*")
    a = ap.parse_args()
    groups = rows.groups(a.groups)
    got = {s: [] for s in SIDES}  # side -> [ {row: dict} per round ]
    for r in range(a.rounds):
        for side, cmd in SIDES.items():
            if cmd(groups) is None:
                continue
            print(f"round {r + 1}/{a.rounds}: {side} …", file=sys.stderr, flush=True)
            got[side].append(run_side(cmd(groups)))

    def series(side, row, key):
        return [d[row][key] for d in got[side] if row in d and key in d[row]]

    def cell(v, fmt):
        if not v:
            return "—"
        m = statistics.median(v)
        return f"{fmt(m)} ({fmt(min(v))}–{fmt(max(v))})" if len(v) > 1 else fmt(m)

    lines = [
        f"anisocb vs peers — {datetime.date.today().isoformat()}, {cpu_name()}, {os.cpu_count()} cores, "
        f"{a.rounds} interleaved rounds (anisocb, ONNX Runtime, OpenVINO, JAX), medians (range)",
        "",
    ]
    if "peak" in groups:
        pk, sg = series("anisocb", "fma peak", "gflops"), series("onnxruntime", rows.SGEMM_ROW, "gflops")
        f1 = lambda v: f"{v:.0f}"  # noqa: E731
        lines += [f"- fp32 FMA peak probe (anisocb, all threads): {cell(pk, f1)} GFLOP/s",
                  f"- ONNX Runtime MLAS SGEMM {rows.SGEMM_N}² (known-good cross-check): {cell(sg, f1)} GFLOP/s"
                  + (f" = {100 * statistics.median(sg) / statistics.median(pk):.0f} % of the probe" if pk and sg else ""),
                  ""]
    table = ["| row | ratio vs ONNX Runtime | ratio vs JAX | anisocb | ONNX Runtime | JAX/XLA |",
             "|---|---:|---:|---:|---:|---:|"]
    names = []
    if "conv" in groups:
        names += [(rows.conv_row(*s), "ms", s) for s in rows.CONVS]
    if "train" in groups:
        names += [(rows.train_row(n), "train", None) for n in rows.CONFIGS]
    pk = statistics.median(series("anisocb", "fma peak", "gflops") or [0]) or None
    for row, kind, conv in names:
        ms = {s: series(s, row, "ms") for s in SIDES}
        med = {s: statistics.median(v) if v else None for s, v in ms.items()}
        if kind == "train":
            per_s = {s: [1e3 * rows.TRAIN_BATCH / t for t in v] for s, v in ms.items()}
            vals = {s: cell(v, lambda x: f"{x:.1f}/s") for s, v in per_s.items()}
        else:
            vals = {s: cell(v, lambda x: f"{x:.3f} ms") for s, v in ms.items()}
            if conv and pk:
                n, c, o, h, w = conv
                for side in ("anisocb", "onnxruntime"):
                    if med[side]:
                        gf = 2 * n * c * o * 9 * h * w / med[side] / 1e6
                        vals[side] += f", {100 * gf / pk:.0f} % peak"

        def ratio(peer):
            if not med[peer] or not med["anisocb"]:
                return "—"
            return f"**{med[peer] / med['anisocb']:.2f}×**"

        table.append(f"| {row} | {ratio('onnxruntime')} | {ratio('jax')} | {vals['anisocb']} | "
                     f"{vals['onnxruntime']} | {vals['jax']} |")
    if "conv" in groups and pk:
        table += ["", "% peak: a direct 3×3 convolution's 2·N·C·O·9·H·W FLOPs per second over the probe. "
                  "anisocb's Winograd F(2×2, 3×3) path (C_in a multiple of 16, C_out > 4) does 16 "
                  "multiply-adds per 2×2 outputs instead of 36, so its figure can pass 100 %."]
    if not names:
        table = []
    if "nets" in groups:
        table += ([""] if table else []) + nets_table(got, series, cell)
    text = "\n".join(lines + table) + "\n"
    print(text)
    os.makedirs(os.path.dirname(a.out), exist_ok=True)
    tmp = a.out + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, a.out)
    print(f"wrote {a.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
