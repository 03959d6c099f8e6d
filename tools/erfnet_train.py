#!/usr/bin/python3
"""Trains ErfNet (tools/erfnet_reference.py) on aerial images rendered by the simulator from generated
worlds, with the class table of config/classes.yaml, on the CPU in a bounded time, reports per-class IoU
and mIoU on held-out worlds, and exports the weights in our format (tools/erfnet_export.py, fp16).
Run with Debian's /usr/bin/python3 (python3-torch, python3-numpy, python3-pil).

  tools/erfnet_train.py --sim build/native/sim/airground-sim --work build/erfnet-train \\
      [--train-worlds 8 --val-worlds 2 --images-per-world 16] [--minutes 60] [--threads 1] \\
      [--crop 192 128 --batch 6] [--out config/erfnet/erfnet_c7.agw]

Data: for each world seed, `airground-sim world generate` then `airground-sim render` at random poses
(altitude 30-60 m, any heading, roll/pitch of a few degrees), each render with its own sun azimuth and
elevation and ambient light (camera_shading in a per-render camera.yaml). Camera noise (gain, offset,
per-pixel Gaussian noise) and flips are added at training time. Training: random crops, Adam, cosine
schedule over the time budget, class-weighted cross-entropy (median-frequency weights), unknown (255)
ignored. The held-out worlds' seeds are disjoint from the training ones. Rendered data is cached in
--work, so a second run trains at once.
"""
import argparse
import json
import math
import os
import random
import subprocess
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import erfnet_reference  # noqa: E402

CLASS_NAMES = ["road", "dirt", "grass", "tree", "building", "vehicle", "water"]  # ids 0..6 of config/classes.yaml
NUM_CLASSES = len(CLASS_NAMES)
IGNORE = 255

CAMERA_YAML = """camera:
  width: 1280
  height: 800
  fx: 967.0
  fy: 967.0
  cx: 639.5
  cy: 399.5
  k1: -0.05
  k2: 0.01
  p1: 0.0
  p2: 0.0
  k3: 0.0
camera_shading:
  sun_azimuth_deg: {az:.1f}
  sun_elevation_deg: {el:.1f}
  ambient: {amb:.3f}
  shadows: false
  detail_texture: true
  max_range_m: 5000
"""


def log(msg):
    print(time.strftime("%H:%M:%S"), msg, flush=True)


def render_world(sim, work, seed, n_images, size_m, rng):
    """Generates world `seed` and renders n_images at random poses; returns [(rgb.png, class.png)]."""
    wdir = os.path.join(work, f"world_{seed}")
    if not os.path.exists(os.path.join(wdir, "world.yaml")):
        subprocess.run([sim, "world", "generate", "--seed", str(seed), "--size", str(size_m), "--out", wdir],
                       check=True, stdout=subprocess.DEVNULL)
    pairs = []
    half = size_m / 2 - 45.0  # keep the footprint (about 80 m at 60 m) inside the world
    for k in range(n_images):
        out = os.path.join(wdir, f"render_{k:03d}")
        rgb, cls = os.path.join(out, "rgb.png"), os.path.join(out, "class.png")
        if not (os.path.exists(rgb) and os.path.exists(cls)):
            os.makedirs(out, exist_ok=True)
            cfg = os.path.join(out, "camera.yaml")
            with open(cfg, "w") as f:
                f.write(CAMERA_YAML.format(az=rng.uniform(0, 360), el=rng.uniform(25, 75), amb=rng.uniform(0.25, 0.5)))
            pose = [rng.uniform(-half, half), rng.uniform(-half, half), rng.uniform(30, 60),
                    rng.gauss(0, 0.04), rng.gauss(0, 0.04), rng.uniform(-math.pi, math.pi)]
            subprocess.run([sim, "render", "--world", wdir, "--pose", *[f"{v:.4f}" for v in pose], "--scale", "0.5",
                            "--config", cfg, "--out", out], check=True, stdout=subprocess.DEVNULL)
        pairs.append((rgb, cls))
    return pairs


def load_pairs(pairs):
    imgs = np.stack([np.asarray(Image.open(r).convert("RGB")) for r, _ in pairs])  # N H W 3 uint8
    labels = np.stack([np.asarray(Image.open(c)) for _, c in pairs]).astype(np.int64)  # N H W
    labels[labels >= NUM_CLASSES] = IGNORE
    return imgs, labels


def class_weights(labels, power=1.0):
    """Median-frequency class weights raised to `power` (1: the usual weights, 0: unweighted)."""
    counts = np.bincount(labels[labels != IGNORE].ravel(), minlength=NUM_CLASSES).astype(np.float64)
    freq = counts / max(counts.sum(), 1)
    present = freq > 0
    w = np.zeros(NUM_CLASSES)
    w[present] = (np.median(freq[present]) / freq[present]) ** power
    return torch.tensor(np.clip(w, 0.05, 10.0), dtype=torch.float32), counts


def rare_pixels(labels, cls):
    """(image, row, col) of every pixel of class `cls`, for crops centred on it."""
    return np.argwhere(labels == cls)


def batch(imgs, labels, n, crop_w, crop_h, rng, rare=None, rare_prob=0.0):
    xs, ys = [], []
    N, H, W = labels.shape
    for _ in range(n):
        if rare is not None and len(rare) and rng.random() < rare_prob:
            i, cy, cx = (int(v) for v in rare[rng.randrange(len(rare))])
            y0 = min(max(cy - crop_h // 2 + rng.randrange(-crop_h // 4, crop_h // 4 + 1), 0), H - crop_h)
            x0 = min(max(cx - crop_w // 2 + rng.randrange(-crop_w // 4, crop_w // 4 + 1), 0), W - crop_w)
        else:
            i = rng.randrange(N)
            y0, x0 = rng.randrange(H - crop_h + 1), rng.randrange(W - crop_w + 1)
        img = imgs[i, y0:y0 + crop_h, x0:x0 + crop_w].astype(np.float32) / 255.0
        lab = labels[i, y0:y0 + crop_h, x0:x0 + crop_w]
        if rng.random() < 0.5:
            img, lab = img[:, ::-1], lab[:, ::-1]
        if rng.random() < 0.5:
            img, lab = img[::-1], lab[::-1]
        # camera noise: gain, offset, per-channel tint, sensor noise
        img = img * rng.uniform(0.75, 1.25) + rng.uniform(-0.08, 0.08)
        img = img * np.array([rng.uniform(0.92, 1.08) for _ in range(3)], dtype=np.float32)
        img = img + np.random.default_rng(rng.randrange(1 << 30)).normal(0, rng.uniform(0.0, 0.03), img.shape).astype(np.float32)
        xs.append(np.clip(img, 0, 1).transpose(2, 0, 1).copy())
        ys.append(lab.copy())
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(ys))


def evaluate(net, imgs, labels):
    """Per-class IoU and mIoU (over classes present in the labels or predicted) on full frames."""
    net.eval()
    inter = np.zeros(NUM_CLASSES)
    union = np.zeros(NUM_CLASSES)
    correct = total = 0
    with torch.no_grad():
        for i in range(len(imgs)):
            x = torch.from_numpy(imgs[i].astype(np.float32).transpose(2, 0, 1) / 255.0)[None]
            pred = net(x)[0].argmax(0).numpy()
            lab = labels[i]
            valid = lab != IGNORE
            correct += int((pred[valid] == lab[valid]).sum())
            total += int(valid.sum())
            for c in range(NUM_CLASSES):
                p, t = (pred == c) & valid, (lab == c) & valid
                inter[c] += (p & t).sum()
                union[c] += (p | t).sum()
    net.train()
    iou = {CLASS_NAMES[c]: inter[c] / union[c] for c in range(NUM_CLASSES) if union[c] > 0}
    return iou, float(np.mean(list(iou.values()))) if iou else 0.0, correct / max(total, 1)


def load_init(path):
    """A state_dict to start from: a PyTorch .pth, or the tensors of one of our .agw weights files (which hold
    the unfolded state_dict, BatchNorm statistics included)."""
    if path.endswith(".agw"):
        import erfnet_weights  # noqa: E402
        header, tensors = erfnet_weights.read(path)
        if header["num_classes"] != NUM_CLASSES:
            raise SystemExit(f"{path}: {header['num_classes']} classes, training needs {NUM_CLASSES}")
        state = erfnet_reference.Net(NUM_CLASSES).state_dict()
        # encoder.output_conv only serves the reference's encoder-only training: not in our files, not in the output
        missing = [k for k in state if k not in tensors and not k.endswith("num_batches_tracked")
                   and not k.startswith("encoder.output_conv.")]
        if missing:
            raise SystemExit(f"{path}: no tensor {missing[0]} (and {len(missing) - 1} more)")
        for k in state:
            if k in tensors:
                if tuple(tensors[k].shape) != tuple(state[k].shape):
                    raise SystemExit(f"{path}: tensor {k} has shape {tensors[k].shape}, the network needs {tuple(state[k].shape)}")
                state[k] = torch.from_numpy(tensors[k].copy())
        return state
    sd = torch.load(path, map_location="cpu")
    return sd.get("state_dict", sd) if isinstance(sd, dict) else sd


def keep_best(net, x, y, it, best):
    """Evaluates on the selection worlds and returns the better of `best` and the current weights."""
    iou, miou, acc = evaluate(net, x, y)
    log(f"selection worlds at iteration {it}: mIoU {miou:.3f}, vehicle {iou.get('vehicle', 0):.3f}, pixel accuracy {acc:.3f}")
    if best is None or miou > best[0]:
        return (miou, {k: v.detach().clone() for k, v in net.state_dict().items()}, it)
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim", default=os.path.join(HERE, "..", "build", "native", "sim", "airground-sim"))
    ap.add_argument("--work", default=os.path.join(HERE, "..", "build", "erfnet-train"))
    ap.add_argument("--train-worlds", type=int, default=8)
    ap.add_argument("--val-worlds", type=int, default=2)
    ap.add_argument("--images-per-world", type=int, default=16)
    ap.add_argument("--world-size", type=int, default=300, help="[m] side of each generated world")
    ap.add_argument("--minutes", type=float, default=60.0, help="training time budget (wall clock)")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    ap.add_argument("--crop", type=int, nargs=2, default=[192, 128], metavar=("W", "H"), help="multiples of 8")
    ap.add_argument("--batch", type=int, default=6)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--init", help="weights to start from (resume): a state_dict .pth or one of our .agw files")
    ap.add_argument("--select-worlds", type=int, default=0,
                    help="worlds (seeds 8000+, neither trained on nor held out) on which the best checkpoint is picked")
    ap.add_argument("--eval-every", type=float, default=10.0, help="[min] between checkpoint evaluations (with --select-worlds)")
    ap.add_argument("--weight-power", type=float, default=1.0,
                    help="exponent of the median-frequency class weights (1: full weights, 0.5: softer, 0: none)")
    ap.add_argument("--vehicle-crops", type=float, default=0.0,
                    help="share of crops centred on a vehicle pixel (the rarest, smallest class)")
    ap.add_argument("--out", default=os.path.join(HERE, "..", "config", "erfnet", "erfnet_c7.agw"))
    a = ap.parse_args()
    if a.crop[0] % 8 or a.crop[1] % 8:
        raise SystemExit("--crop sizes must be multiples of 8")
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    rng = random.Random(a.seed)
    os.makedirs(a.work, exist_ok=True)

    train_seeds = [1000 + k for k in range(a.train_worlds)]
    val_seeds = [9000 + k for k in range(a.val_worlds)]  # held out: never trained on
    log(f"rendering {a.train_worlds} training and {a.val_worlds} held-out worlds x {a.images_per_world} images")
    select_seeds = [8000 + k for k in range(a.select_worlds)]  # checkpoint selection only
    train_pairs, val_pairs, sel_pairs = [], [], []
    for s in train_seeds + val_seeds + select_seeds:
        p = render_world(a.sim, a.work, s, a.images_per_world, a.world_size, random.Random(s))
        (train_pairs if s in train_seeds else val_pairs if s in val_seeds else sel_pairs).extend(p)
        log(f"  world {s}: {len(p)} images")
    tr_x, tr_y = load_pairs(train_pairs)
    va_x, va_y = load_pairs(val_pairs)
    se_x, se_y = load_pairs(sel_pairs) if sel_pairs else (None, None)
    weights, counts = class_weights(tr_y, a.weight_power)
    rare = rare_pixels(tr_y, CLASS_NAMES.index("vehicle")) if a.vehicle_crops > 0 else None
    log("class pixels (train): " + ", ".join(f"{n} {int(c)}" for n, c in zip(CLASS_NAMES, counts)))
    log("class weights: " + ", ".join(f"{n} {w:.2f}" for n, w in zip(CLASS_NAMES, weights.tolist())))

    net = erfnet_reference.Net(NUM_CLASSES)
    if a.init:
        net.load_state_dict(load_init(a.init))
        log(f"starting from {a.init}")
    net.train()
    best = None  # (selection mIoU, state_dict, iteration)
    if se_x is not None and a.init:  # the starting point is a candidate too: a fine-tune never ships worse
        best = keep_best(net, se_x, se_y, 0, best)
    next_eval = a.eval_every * 60.0
    opt = torch.optim.Adam(net.parameters(), lr=a.lr, weight_decay=1e-4)
    budget = a.minutes * 60.0
    t0 = time.time()
    it = 0
    last_log = t0
    while time.time() - t0 < budget:
        frac = (time.time() - t0) / budget
        for g in opt.param_groups:
            g["lr"] = a.lr * 0.5 * (1 + math.cos(math.pi * frac))
        x, y = batch(tr_x, tr_y, a.batch, a.crop[0], a.crop[1], rng, rare, a.vehicle_crops)
        loss = F.cross_entropy(net(x), y, weight=weights, ignore_index=IGNORE)
        opt.zero_grad()
        loss.backward()
        opt.step()
        it += 1
        if time.time() - last_log > 60 or it == 1:
            last_log = time.time()
            log(f"iteration {it}, {(time.time() - t0) / 60:.1f} of {a.minutes:.0f} min, loss {loss.item():.3f}, lr {opt.param_groups[0]['lr']:.2e}")
        if se_x is not None and time.time() - t0 >= next_eval:
            next_eval += a.eval_every * 60.0
            best = keep_best(net, se_x, se_y, it, best)

    if se_x is not None:
        best = keep_best(net, se_x, se_y, it, best)
        net.load_state_dict(best[1])
        log(f"keeping the checkpoint of iteration {best[2]} (selection mIoU {best[0]:.3f})")
    iou, miou, acc = evaluate(net, va_x, va_y)
    log(f"held-out worlds {val_seeds}: mIoU {miou:.3f}, pixel accuracy {acc:.3f}; " +
        ", ".join(f"{k} {v:.3f}" for k, v in iou.items()))
    pth = os.path.join(a.work, "erfnet_c7.pth")
    torch.save(net.state_dict(), pth)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    subprocess.run([sys.executable, os.path.join(HERE, "erfnet_export.py"), pth, a.out, "--fp16", "--width", "640",
                    "--height", "400", "--class-names", ",".join(CLASS_NAMES)], check=True)
    report = dict(iterations=it, minutes=a.minutes, threads=a.threads, crop=a.crop, batch=a.batch,
                  train_worlds=train_seeds, held_out_worlds=val_seeds, selection_worlds=select_seeds,
                  images_per_world=a.images_per_world, init=os.path.basename(a.init) if a.init else None,
                  weight_power=a.weight_power, vehicle_crops=a.vehicle_crops, lr=a.lr,
                  kept_iteration=best[2] if best else it,
                  miou=miou, pixel_accuracy=acc, iou=iou)
    with open(os.path.splitext(a.out)[0] + ".json", "w") as f:
        json.dump(report, f, indent=1)
    log(f"wrote {a.out} and {os.path.splitext(a.out)[0]}.json")


if __name__ == "__main__":
    main()
