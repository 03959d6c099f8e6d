#!/usr/bin/python3
"""Writes the ErfNet numerics fixtures under tests/data/segmentation/: a reference network
(tools/erfnet_reference.py) with random weights and random BN statistics, exported through
tools/erfnet_export.py (from a DataParallel-style state_dict with the `module.` prefix, fp16 storage),
and, for a random image, the logits torch computes in float64 with exactly those (fp16-representable)
weights. tests/unit/segmentation/test_numerics.cpp compares the C++ engine against them.

  tools/erfnet_goldens.py [--out tests/data/segmentation] [--width 64 --height 48 --classes 7 --seed 9]

Golden file (little-endian): "AGSEGGLD" | u32 width | u32 height | u32 classes | u8 rgb[h][w][3] |
f32 logits[classes][h][w].
"""
import argparse
import os
import struct
import subprocess
import sys
import tempfile

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import erfnet_reference  # noqa: E402


def randomise(net, gen):
    """Random weights (PyTorch's default init scale) and random BN statistics, rounded to fp16."""
    with torch.no_grad():
        for name, m in net.named_modules():
            if isinstance(m, (torch.nn.Conv2d, torch.nn.ConvTranspose2d)):
                fan_in = m.weight[0].numel() if isinstance(m, torch.nn.Conv2d) else m.weight.shape[0] * m.weight[0, 0].numel()
                bound = (3.0 / fan_in) ** 0.5  # unit-variance signal through a ReLU network, about
                if name == "decoder.output_conv":
                    bound *= 4.0  # logits of order 1, so that 1e-3 is a tight tolerance
                m.weight.uniform_(-bound, bound, generator=gen)
                m.bias.uniform_(-0.1, 0.1, generator=gen)
            elif isinstance(m, torch.nn.BatchNorm2d):
                m.weight.uniform_(0.5, 1.5, generator=gen)
                m.bias.uniform_(-0.3, 0.3, generator=gen)
                m.running_mean.uniform_(-0.3, 0.3, generator=gen)
                m.running_var.uniform_(0.5, 2.0, generator=gen)
        for t in list(net.parameters()) + list(net.buffers()):
            if t.dtype.is_floating_point:
                t.copy_(t.half().float())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "data", "segmentation"))
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--classes", type=int, default=7)
    ap.add_argument("--seed", type=int, default=9)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    gen = torch.Generator().manual_seed(a.seed)
    net = erfnet_reference.Net(a.classes).eval()
    randomise(net, gen)

    weights = os.path.join(a.out, f"erfnet_random_c{a.classes}.agw")
    with tempfile.TemporaryDirectory() as tmp:
        pth = os.path.join(tmp, "state_dict.pth")
        torch.save({"module." + k: v for k, v in net.state_dict().items()}, pth)
        subprocess.run([sys.executable, os.path.join(HERE, "erfnet_export.py"), pth, weights, "--fp16",
                        "--width", str(a.width), "--height", str(a.height)], check=True)

    rng = np.random.default_rng(a.seed)
    # Smooth random image (blobs plus noise), so that the network sees structure at every scale.
    small = rng.integers(0, 256, size=(a.height // 8 + 1, a.width // 8 + 1, 3)).astype(np.float64)
    yy, xx = np.mgrid[0:a.height, 0:a.width] / 8.0
    y0, x0 = yy.astype(int), xx.astype(int)
    fy, fx = (yy - y0)[..., None], (xx - x0)[..., None]
    img = (small[y0, x0] * (1 - fy) * (1 - fx) + small[y0 + 1, x0] * fy * (1 - fx) + small[y0, x0 + 1] * (1 - fy) * fx +
           small[y0 + 1, x0 + 1] * fy * fx)
    img = np.clip(img + rng.normal(0, 20, img.shape), 0, 255).astype(np.uint8)

    net64 = net.double()
    x = torch.from_numpy(img.astype(np.float64) / 255.0).permute(2, 0, 1)[None].contiguous()
    with torch.no_grad():
        logits = net64(x)[0].numpy()
    top2 = np.sort(logits, axis=0)[-2:]
    margin = top2[1] - top2[0]
    print(f"logits: std {logits.std():.3f}, range [{logits.min():.2f}, {logits.max():.2f}]; "
          f"argmax margins < 1e-3 on {(margin < 1e-3).mean() * 100:.2f}% of pixels; "
          f"class histogram {np.bincount(logits.argmax(0).ravel(), minlength=a.classes).tolist()}")
    golden = os.path.join(a.out, f"erfnet_random_c{a.classes}_{a.width}x{a.height}.golden")
    with open(golden, "wb") as f:
        f.write(b"AGSEGGLD" + struct.pack("<III", a.width, a.height, a.classes))
        f.write(img.tobytes())
        f.write(logits.astype("<f4").tobytes())
    print(f"{weights}, {golden}")


if __name__ == "__main__":
    main()
