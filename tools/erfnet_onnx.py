#!/usr/bin/python3
"""Exports an airground ErfNet weights file (docs/segmentation.md) to ONNX with torch's exporter, at a
fixed input size: the same network and the same weights for OpenCV's cv::dnn (tests/bench/
bench_segmentation.cpp runs both side by side). Run with Debian's /usr/bin/python3.

  tools/erfnet_onnx.py WEIGHTS.agw OUT.onnx [--width 640 --height 400]
"""
import argparse
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import erfnet_reference  # noqa: E402
import erfnet_weights  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("weights")
    ap.add_argument("out")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=400)
    a = ap.parse_args()
    header, tensors = erfnet_weights.read(a.weights)
    net = erfnet_reference.Net(header["num_classes"]).eval()
    missing, unexpected = net.load_state_dict({n: torch.from_numpy(v.copy()) for n, v in tensors.items()}, strict=False)
    missing = [m for m in missing if not m.startswith("encoder.output_conv") and not m.endswith("num_batches_tracked")]
    if missing or unexpected:
        raise SystemExit(f"{a.weights}: does not fit the reference ErfNet (missing {missing[:1]}, unexpected {unexpected[:1]})")
    with torch.no_grad():
        torch.onnx.export(net, torch.zeros(1, 3, a.height, a.width), a.out, input_names=["image"],
                          output_names=["logits"], opset_version=11, do_constant_folding=True)
    print(f"{a.out}: ErfNet {header['num_classes']} classes at {a.width}x{a.height}")


if __name__ == "__main__":
    main()
