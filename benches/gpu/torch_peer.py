#!/usr/bin/env python3
"""The shipped bundle in PyTorch on the same GPU, for benches/gpu-check.sh: the four nets of
weights/anisocb-x2.npz (weights/README.md's reference module), each on the four mirror views of a
chunk of 64x64 frames (16 net passes a frame, what `anisocb upscale` runs), in bf16 and fp16,
channels-last, replayed from a CUDA graph: PyTorch at its best. Prints ms a frame by chunk size.
Usage: python3 benches/gpu/torch_peer.py weights/anisocb-x2.npz  (needs torch with CUDA, numpy)"""
import json, sys, zipfile
import numpy as np
import torch, torch.nn as nn, torch.nn.functional as F


class Net(nn.Module):
    def __init__(self, kind, channels, blocks, scale, padding="zero", **_):
        super().__init__()
        pm = "zeros" if padding == "zero" else "replicate"
        conv = lambda i, o: nn.Conv2d(i, o, 3, padding=1, padding_mode=pm)
        C, out = channels, 3 if kind == "geometry" else 1
        self.kind, self.scale = kind, scale
        self.conv_in = conv(3, C)
        self.blocks = nn.ModuleList(nn.ModuleDict({"conv1": conv(C, C), "conv2": conv(C, C)}) for _ in range(blocks))
        self.upscale = conv(C, C * scale * scale)
        self.tail = nn.ModuleList([conv(C, C), conv(C, C), conv(C, C), conv(C, out)])

    def forward(self, x):
        a = self.conv_in(x)
        for b in self.blocks:
            t = b["conv2"](F.relu(b["conv1"](a)))
            a = a + t if self.kind == "geometry" else t
        z = F.pixel_shuffle(self.upscale(a), self.scale)
        for i, c in enumerate(self.tail):
            z = c(z) if i == 3 else F.relu(c(z))
        return z


def load(path, prefix):
    f, z = np.load(path), zipfile.ZipFile(path)
    cfg = json.loads(z.read(prefix + "config.json.npy") if prefix + "config.json.npy" in z.namelist()
                     else bytes(f[prefix + "config.json"]))
    net = Net(**cfg)
    net.load_state_dict({k: torch.from_numpy(f[prefix + k]) for k in net.state_dict()})
    return net


def main():
    path = sys.argv[1]
    names = [n[: -len("config.json")] for n in np.load(path).files if n.endswith("config.json")]
    print(f"torch {torch.__version__}, {torch.cuda.get_device_name()}; nets: {', '.join(n.rstrip('.') for n in names)}")
    torch.backends.cudnn.benchmark = True
    for dtype in (torch.bfloat16, torch.float16):
        nets = [load(path, p).cuda().to(dtype).to(memory_format=torch.channels_last).eval() for p in names]
        for chunk in (16, 1):
            x = torch.rand(4 * chunk, 3, 64, 64, device="cuda", dtype=dtype).to(memory_format=torch.channels_last)
            with torch.inference_mode():
                for _ in range(3):
                    [n(x) for n in nets]
                torch.cuda.synchronize()
                g = torch.cuda.CUDAGraph()
                with torch.cuda.graph(g):
                    ys = [n(x) for n in nets]
                ms = []
                for _ in range(30):
                    a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
                    a.record(); g.replay(); b.record(); torch.cuda.synchronize()
                    ms.append(a.elapsed_time(b) / chunk)
            ms.sort()
            print(f"pytorch {str(dtype).split('.')[1]:>8} channels-last CUDA graph, chunk {chunk:>2}: "
                  f"{ms[len(ms) // 2]:.3f} ms a frame (median of 30, nets only, data on the GPU)")


main()
