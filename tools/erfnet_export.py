#!/usr/bin/python3
"""Converts a PyTorch ErfNet state_dict (reference module naming, with or without a `module.` prefix, as
saved by the reference training code or by tools/erfnet_train.py) into airground's ErfNet weights file
(docs/segmentation.md), which pipeline/segmentation loads. Run with Debian's /usr/bin/python3.

  tools/erfnet_export.py STATE_DICT.pth OUT_WEIGHTS [--width 640 --height 400] [--fp16]
                         [--class-names road,dirt,...] [--mean 0 0 0 --std 1 1 1] [--onnx OUT.onnx]
"""
import argparse
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import erfnet_reference  # noqa: E402
import erfnet_weights  # noqa: E402


def expected_tensors(num_classes):
    """Names and shapes the C++ loader wants, in file order (the reference Net's, without the encoder's
    unused output_conv and the BN batch counters)."""
    net = erfnet_reference.Net(num_classes)
    out = {}
    for name, t in net.state_dict().items():
        if name.startswith("encoder.output_conv.") or name.endswith("num_batches_tracked"):
            continue
        out[name] = tuple(t.shape)
    return out


def load_state_dict(path):
    obj = torch.load(path, map_location="cpu")
    if isinstance(obj, dict) and "state_dict" in obj and isinstance(obj["state_dict"], dict):
        obj = obj["state_dict"]
    if isinstance(obj, torch.nn.Module):
        obj = obj.state_dict()
    if not isinstance(obj, dict):
        raise SystemExit(f"{path}: not a state_dict (got {type(obj).__name__})")
    return {(k[len("module."):] if k.startswith("module.") else k): v for k, v in obj.items()}


def convert(sd, path="state_dict"):
    """Checks a state_dict against the reference architecture; returns (num_classes, {name: array})."""
    if "decoder.output_conv.weight" not in sd:
        raise SystemExit(f"{path}: no decoder.output_conv.weight: not an ErfNet state_dict with the reference naming")
    w = sd["decoder.output_conv.weight"]
    if w.dim() != 4 or tuple(w.shape[2:]) != (2, 2) or w.shape[0] != 16:
        raise SystemExit(f"{path}: decoder.output_conv.weight has shape {tuple(w.shape)}, want (16, classes, 2, 2)")
    num_classes = int(w.shape[1])
    want = expected_tensors(num_classes)
    missing = [n for n in want if n not in sd]
    if missing:
        raise SystemExit(f"{path}: missing {len(missing)} tensors, first {missing[0]}")
    for n, shape in want.items():
        if tuple(sd[n].shape) != shape:
            raise SystemExit(f"{path}: {n} has shape {tuple(sd[n].shape)}, want {shape}")
    ignored = [n for n in sd if n not in want and not n.endswith("num_batches_tracked")
               and not n.startswith("encoder.output_conv.")]
    if ignored:
        raise SystemExit(f"{path}: unexpected tensor {ignored[0]} ({len(ignored)} in all): not this architecture")
    return num_classes, {n: sd[n].detach().float().numpy() for n in want}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("state_dict", help="PyTorch .pth with a state_dict (or {'state_dict': ...})")
    ap.add_argument("out", help="airground ErfNet weights file to write")
    ap.add_argument("--width", type=int, default=640, help="input width the model is made for (multiple of 8)")
    ap.add_argument("--height", type=int, default=400, help="input height (multiple of 8)")
    ap.add_argument("--mean", type=float, nargs=3, default=[0.0, 0.0, 0.0],
                    help="per-channel mean subtracted after scaling RGB by 1/255 (reference: 0)")
    ap.add_argument("--std", type=float, nargs=3, default=[1.0, 1.0, 1.0], help="per-channel divisor (reference: 1)")
    ap.add_argument("--class-names", default="", help="comma-separated class names, in logit order")
    ap.add_argument("--fp16", action="store_true", help="store tensors as IEEE half floats (half the size)")
    ap.add_argument("--onnx", help="also export the same network to this ONNX file (for cv::dnn)")
    a = ap.parse_args()
    if a.width % 8 or a.height % 8 or a.width <= 0 or a.height <= 0:
        raise SystemExit("--width and --height must be positive multiples of 8")
    if any(s == 0 for s in a.std):
        raise SystemExit("--std must not be 0")
    sd = load_state_dict(a.state_dict)
    num_classes, tensors = convert(sd, a.state_dict)
    names = [s for s in a.class_names.split(",") if s]
    if names and len(names) != num_classes:
        raise SystemExit(f"--class-names lists {len(names)} names but the model has {num_classes} classes")
    size = erfnet_weights.write(a.out, tensors, num_classes, a.width, a.height, a.mean, a.std, names, a.fp16)
    params = sum(t.size for t in tensors.values())
    print(f"{a.out}: {num_classes} classes, {len(tensors)} tensors, {params / 1e6:.3f} M values, "
          f"{'fp16' if a.fp16 else 'fp32'}, {size / 1e6:.2f} MB")
    if a.onnx:
        export_onnx(tensors, num_classes, a.width, a.height, a.onnx)
        print(f"{a.onnx}: ONNX export at {a.width}x{a.height}")


def export_onnx(tensors, num_classes, width, height, path):
    net = erfnet_reference.Net(num_classes).eval()
    net.load_state_dict({n: torch.from_numpy(v) for n, v in tensors.items()}, strict=False)
    torch.onnx.export(net, torch.zeros(1, 3, height, width), path, input_names=["image"], output_names=["logits"],
                      opset_version=11, do_constant_folding=True)


if __name__ == "__main__":
    main()
