#!/usr/bin/python3
"""Trains ErfNet (tools/erfnet_reference.py) on aerial images rendered by the simulator from generated
worlds, with the class table of config/classes.yaml, on the CPU in a bounded time, reports per-class IoU
and mIoU on held-out worlds, and exports the weights in our format (tools/erfnet_export.py, fp16).
Or, with --images DIR --legend LEGEND.yaml --out NEW.agw, fine-tunes the shipped weights on a team's own
labelled aerial images (below). Run with Debian's /usr/bin/python3 (python3-torch, python3-numpy, python3-pil).

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
    """Median-frequency class weights raised to `power` (1: the usual weights, 0: unweighted). `labels`: an
    N x H x W array or a list of H x W arrays (images of different sizes)."""
    counts = np.zeros(NUM_CLASSES)
    for lab in labels:
        counts += np.bincount(lab[lab != IGNORE].ravel(), minlength=NUM_CLASSES)[:NUM_CLASSES]
    freq = counts / max(counts.sum(), 1)
    present = freq > 0
    w = np.zeros(NUM_CLASSES)
    w[present] = (np.median(freq[present]) / freq[present]) ** power
    return torch.tensor(np.clip(w, 0.05, 10.0), dtype=torch.float32), counts


def rare_pixels(labels, cls):
    """(image, row, col) of every pixel of class `cls`, for crops centred on it."""
    found = [np.argwhere(lab == cls) for lab in labels]
    found = [np.concatenate([np.full((len(a), 1), i), a], axis=1) for i, a in enumerate(found) if len(a)]
    return np.concatenate(found) if found else np.zeros((0, 3), dtype=np.int64)


def batch(imgs, labels, n, crop_w, crop_h, rng, rare=None, rare_prob=0.0, transpose=False):
    """n augmented crops. imgs, labels: N x H x W (x 3) arrays or lists of images of any size (at least the
    crop). transpose: also cut crops of the swapped size and transpose them (with the flips: all 8 rotations
    and mirrorings, for images taken at one heading)."""
    xs, ys = [], []
    for _ in range(n):
        use_rare = rare is not None and len(rare) and rng.random() < rare_prob
        if use_rare:
            i, cy, cx = (int(v) for v in rare[rng.randrange(len(rare))])
        else:
            i = rng.randrange(len(labels))
        H, W = labels[i].shape
        swap = transpose and H >= crop_w and W >= crop_h and rng.random() < 0.5
        cw, ch = (crop_h, crop_w) if swap else (crop_w, crop_h)
        if use_rare:
            y0 = min(max(cy - ch // 2 + rng.randrange(-ch // 4, ch // 4 + 1), 0), H - ch)
            x0 = min(max(cx - cw // 2 + rng.randrange(-cw // 4, cw // 4 + 1), 0), W - cw)
        else:
            y0, x0 = rng.randrange(H - ch + 1), rng.randrange(W - cw + 1)
        img = imgs[i][y0:y0 + ch, x0:x0 + cw].astype(np.float32) / 255.0
        lab = labels[i][y0:y0 + ch, x0:x0 + cw]
        if swap:
            img, lab = img.transpose(1, 0, 2), lab.T
        if rng.random() < 0.5:
            img, lab = img[:, ::-1], lab[:, ::-1]
        if rng.random() < 0.5:
            img, lab = img[::-1], lab[::-1]
        # camera noise: gain, offset, per-channel tint, sensor noise
        img = img * rng.uniform(0.75, 1.25) + rng.uniform(-0.08, 0.08)
        img = img * np.array([rng.uniform(0.92, 1.08) for _ in range(3)], dtype=np.float32)
        img = img + np.random.default_rng(rng.randrange(1 << 30)).normal(0, rng.uniform(0.0, 0.03), img.shape).astype(np.float32)
        xs.append(np.clip(img, 0, 1).transpose(2, 0, 1).copy())
        ys.append(lab.astype(np.int64))
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(ys))


TILE_W, TILE_H = 640, 400  # the uav's frame: larger images are scored in windows of this size


def _starts(size, tile):
    if size <= tile:
        return [0]
    n = -(-size // tile)
    return sorted({round(k * (size - tile) / (n - 1)) for k in range(n)})


def predict(net, img):
    """Argmax classes of an H x W x 3 uint8 image: padded to multiples of 8 by repeating edge pixels (as
    `airground-sim segment`); an image larger than the uav's 640x400 frame is run in overlapping 640x400
    windows whose logits are averaged."""
    H, W = img.shape[:2]
    ph, pw = -H % 8, -W % 8
    x = np.pad(img, ((0, ph), (0, pw), (0, 0)), mode="edge") if ph or pw else img
    x = torch.from_numpy(x.astype(np.float32).transpose(2, 0, 1) / 255.0)[None]
    Hp, Wp = x.shape[2:]
    if Hp <= TILE_H and Wp <= TILE_W:
        return net(x)[0].argmax(0).numpy()[:H, :W]
    th, tw = min(TILE_H, Hp), min(TILE_W, Wp)
    acc = torch.zeros(NUM_CLASSES, Hp, Wp)
    hits = torch.zeros(1, Hp, Wp)
    for y0 in _starts(Hp, th):
        for x0 in _starts(Wp, tw):
            acc[:, y0:y0 + th, x0:x0 + tw] += net(x[:, :, y0:y0 + th, x0:x0 + tw])[0]
            hits[:, y0:y0 + th, x0:x0 + tw] += 1
    return (acc / hits).argmax(0).numpy()[:H, :W]


def evaluate(net, imgs, labels):
    """Per-class IoU and mIoU (over classes present in the labels or predicted) on full frames."""
    net.eval()
    inter = np.zeros(NUM_CLASSES)
    union = np.zeros(NUM_CLASSES)
    correct = total = 0
    with torch.no_grad():
        for i in range(len(imgs)):
            pred = predict(net, imgs[i])
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


def keep_best(net, x, y, it, best, what="selection worlds", seen=None):
    """Evaluates on `x, y` and returns the better of `best` and the current weights (ties keep `best`):
    (mIoU, state_dict, iteration, (iou, mIoU, pixel accuracy)). `seen`: a list the figures are appended to."""
    iou, miou, acc = evaluate(net, x, y)
    if seen is not None:
        seen.append((iou, miou, acc))
    if what:
        log(f"{what} at iteration {it}: mIoU {miou:.3f}, vehicle {iou.get('vehicle', 0):.3f}, pixel accuracy {acc:.3f}")
    if best is None or miou > best[0]:
        return (miou, {k: v.detach().clone() for k, v in net.state_dict().items()}, it, (iou, miou, acc))
    return best


def train(net, a, tr_x, tr_y, weights, rng, rare=None, transpose=False, every=None):
    """Adam with a cosine schedule over a.minutes of wall clock on random crops; `every`: (seconds, callback(it))
    called that often. Returns the iteration count."""
    opt = torch.optim.Adam(net.parameters(), lr=a.lr, weight_decay=1e-4)
    budget = a.minutes * 60.0
    next_eval = every[0] if every else None
    t0 = time.time()
    it = 0
    last_log = t0
    while time.time() - t0 < budget:
        frac = (time.time() - t0) / budget
        for g in opt.param_groups:
            g["lr"] = a.lr * 0.5 * (1 + math.cos(math.pi * frac))
        x, y = batch(tr_x, tr_y, a.batch, a.crop[0], a.crop[1], rng, rare, a.vehicle_crops, transpose)
        loss = F.cross_entropy(net(x), y, weight=weights, ignore_index=IGNORE)
        opt.zero_grad()
        loss.backward()
        opt.step()
        it += 1
        if time.time() - last_log > 60 or it == 1:
            last_log = time.time()
            log(f"iteration {it}, {(time.time() - t0) / 60:.1f} of {a.minutes:g} min, loss {loss.item():.3f}, lr {opt.param_groups[0]['lr']:.2e}")
        if every and time.time() - t0 >= next_eval:
            next_eval += every[0]
            every[1](it)
    return it


def export(net, pth, out):
    """The network's weights to `out` in our format (fp16, the class names, made for 640x400)."""
    torch.save(net.state_dict(), pth)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    subprocess.run([sys.executable, os.path.join(HERE, "erfnet_export.py"), pth, out, "--fp16", "--width", "640",
                    "--height", "400", "--class-names", ",".join(CLASS_NAMES)], check=True)


SHIPPED = os.path.normpath(os.path.join(HERE, "..", "config", "erfnet", "erfnet_c7.agw"))
INSTALLED = "/usr/share/airground/erfnet_c7.agw"
SIM_ONLY = dict(sim=None, train_worlds=8, val_worlds=2, images_per_world=16, world_size=300, select_worlds=0,
                eval_every=10.0)
FINETUNE_ONLY = dict(legend=None, holdout=0.2, scale=1.0, force=False)
DEFAULTS = {  # option: (simulator renders, --images)
    "work": (os.path.join(HERE, "..", "build", "erfnet-train"), os.path.join(HERE, "..", "build", "erfnet-finetune")),
    "minutes": (60.0, 30.0),
    "lr": (2e-3, 5e-4),
    "weight_power": (1.0, 0.5),
    "init": (None, SHIPPED),
    "out": (SHIPPED, None),
}

HELP = __doc__ + r"""
Fine-tuning on your own labelled aerial images (--images DIR --legend LEGEND.yaml --out NEW.agw), instead of
the simulator's renders; see docs/segmentation.md, "Training for your own site":

  tools/erfnet_train.py --images site/ --legend site/legend.yaml --out site/erfnet_site.agw \
      [--holdout 0.2 --seed 1] [--scale 0.5] [--minutes 30] [--threads 1] [--init config/erfnet/erfnet_c7.agw]

  DIR holds pairs side by side: NAME.png|.jpg|.jpeg|.tif|.tiff (8-bit RGB, as displayed: EXIF rotation applied)
  and NAME_label.png|.tif (lossless), the same size in pixels. A half pair or a size mismatch is an error
  naming the file.
  LEGEND is `airground-sim world import`'s: `classes: [{value: N, class: road}, ...]` for a one-band value
  raster (8/16-bit grey or a palette PNG's indices), or `classes: [{color: [R, G, B], class: road}, ...]` for
  a colour raster; classes road dirt grass tree building vehicle water, and unknown (ignored). Colours are
  matched as the importer matches them (within 24 of a legend colour; anti-aliased edges to the nearest pure
  neighbour; alpha < 128 is unknown). Where the importer would refuse the raster - a value not in the legend, or
  a colour on >= 50 pixels and 0.2 % of it that is neither near a legend colour nor a mix of two (a missing
  legend entry) - those pixels become unknown (255, ignored by the loss and the scores), counted and reported.
  --holdout F of the pairs (round(F x N), at least 1, chosen by --seed) are held out: per-class IoU and mIoU on
  them are printed for the starting weights before training and for the trained ones after, and written to
  WORK/finetune_report.json and WORK/finetune_report.md (and OUT's name with .json). A fine-tune never ships
  worse: OUT gets the better of the starting and the trained weights by held-out mIoU (ties: the starting).
  Scale: the shipped weights learnt renders of the simulated uav camera at 640x400 (fx 483.5 px) from 30-60 m
  above the ground: 0.06-0.12 m per pixel (0.083 at the default survey's 40 m). Give --scale so that your
  images come to about that: --scale = (your m/px) / 0.08, e.g. 0.375 for 3 cm/px imagery (the real camera's
  lens is not in uav.yaml: measure its m/px at your altitude). Images are resampled (classes by
  nearest neighbour) before training; images larger than --crop are random-cropped, smaller ones padded
  (unknown labels); scoring runs on full images, in 640x400 windows where larger.
  Defaults differ from the renders' training: --init the shipped weights, --lr 5e-4, --minutes 30,
  --weight-power 0.5, --work build/erfnet-finetune, crops also transposed; --out has no default, and OUT may
  not be the shipped or starting weights (nor /usr/share/airground/erfnet_c7.agw) unless --force.
  Bad input (a missing or malformed legend, an unknown class name, an unreadable image, a missing label)
  stops with a message naming the file and exit status 2.

Load the result on the uav with `segmentation.weights: /path/to/NEW.agw` in /etc/airground/uav.yaml.
"""


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = ap.add_mutually_exclusive_group()
    source.add_argument("--sim", help="simulator renders (the default source): the airground-sim binary "
                        "(default build/native/sim/airground-sim)")
    source.add_argument("--images", metavar="DIR", help="your own labelled images instead: DIR of NAME.png|jpg|tif and "
                        "NAME_label.png pairs (needs --legend and --out)")
    ap.add_argument("--work", help="working folder: renders cache, .pth, reports (default build/erfnet-train; "
                    "with --images build/erfnet-finetune)")
    rs = ap.add_argument_group("simulator renders only")
    rs.add_argument("--train-worlds", type=int, help="generated worlds trained on (8; seeds 1000+)")
    rs.add_argument("--val-worlds", type=int, help="held-out worlds scored (2; seeds 9000+)")
    rs.add_argument("--images-per-world", type=int, help="renders per world (16)")
    rs.add_argument("--world-size", type=int, help="[m] side of each generated world (300)")
    rs.add_argument("--select-worlds", type=int,
                    help="worlds (seeds 8000+, neither trained on nor held out) on which the best checkpoint is picked")
    rs.add_argument("--eval-every", type=float, help="[min] between checkpoint evaluations (with --select-worlds; 10)")
    ft = ap.add_argument_group("your own images only (--images)")
    ft.add_argument("--legend", help="the legend YAML, `world import`'s form: {value: N, class: NAME} or "
                    "{color: [R, G, B], class: NAME} entries")
    ft.add_argument("--holdout", type=float, help="share of the pairs held out for scoring (0.2; at least 1 image)")
    ft.add_argument("--scale", type=float, help="resample images and labels by this factor first (1.0): "
                    "about (your m/px) / 0.08")
    ft.add_argument("--force", action="store_true", help="allow --out to be the shipped or the starting weights file")
    ap.add_argument("--minutes", type=float, help="training time budget, wall clock (60; with --images 30)")
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    ap.add_argument("--crop", type=int, nargs=2, default=[192, 128], metavar=("W", "H"), help="multiples of 8")
    ap.add_argument("--batch", type=int, default=6)
    ap.add_argument("--lr", type=float, help="peak learning rate (2e-3; with --images 5e-4)")
    ap.add_argument("--seed", type=int, default=1, help="the random seed (training, and which images are held out)")
    ap.add_argument("--init", help="weights to start from (resume): a state_dict .pth or one of our .agw files "
                    "(with --images: config/erfnet/erfnet_c7.agw, the shipped weights)")
    ap.add_argument("--weight-power", type=float,
                    help="exponent of the median-frequency class weights (1: full weights, 0.5: softer, 0: none; "
                    "default 1, with --images 0.5)")
    ap.add_argument("--vehicle-crops", type=float, default=0.0,
                    help="share of crops centred on a vehicle pixel (the rarest, smallest class)")
    ap.add_argument("--out", help="weights file to write (default config/erfnet/erfnet_c7.agw; with --images "
                    "required, and not the shipped file)")
    a = ap.parse_args(argv)
    fine = a.images is not None
    wrong = [k for k in (SIM_ONLY if fine else FINETUNE_ONLY) if getattr(a, k) not in (None, False)]
    if wrong:
        ap.error(f"--{wrong[0].replace('_', '-')} " + ("is for simulator renders, not with --images" if fine
                                                        else "is for your own images: it needs --images DIR"))
    for k, v in (FINETUNE_ONLY if fine else SIM_ONLY).items():
        if getattr(a, k) is None:
            setattr(a, k, v)
    for k, (sim, own) in DEFAULTS.items():
        if getattr(a, k) is None:
            setattr(a, k, own if fine else sim)
    if a.sim is None:
        a.sim = os.path.join(HERE, "..", "build", "native", "sim", "airground-sim")
    if a.crop[0] % 8 or a.crop[1] % 8 or min(a.crop) <= 0:
        ap.error("--crop sizes must be positive multiples of 8")
    if a.threads < 1 or a.batch < 1 or a.minutes < 0 or a.lr <= 0:
        ap.error("--threads and --batch must be at least 1, --minutes at least 0, --lr positive")
    if fine:
        if not a.legend:
            ap.error("--images needs --legend LEGEND.yaml (the classes of the label rasters)")
        if not a.out:
            ap.error("--images needs --out NEW.agw (the shipped weights are never overwritten by default)")
        if not 0 < a.holdout < 1:
            ap.error("--holdout must be a share between 0 and 1 (e.g. 0.2)")
        if not 0.01 <= a.scale <= 10:
            ap.error("--scale must be in [0.01, 10]")
        same = {os.path.realpath(p) for p in (SHIPPED, INSTALLED, a.init) if p}
        if os.path.realpath(a.out) in same and not a.force:
            ap.error(f"--out {a.out} is the shipped or the starting weights file; write elsewhere (or add --force)")
    return a


def fail(msg):
    """Bad input: one line naming the file and the problem, exit status 2, no traceback."""
    print(f"{os.path.basename(sys.argv[0])}: error: {msg}", file=sys.stderr, flush=True)
    sys.exit(2)


def round_fp16(net):
    """Rounds every weight and statistic to fp16 in place: the network as the exported file holds it."""
    with torch.no_grad():
        for t in net.state_dict().values():
            if t.is_floating_point():
                t.copy_(t.half().float())


def figures(iou, miou, acc, labelled):
    """The report's figures; miou_labelled: the mean over the classes in `labelled` only (those with held-out
    label pixels), which does not count a class predicted where none is labelled."""
    lab = [float(iou.get(n, 0.0)) for n in labelled]
    return dict(miou=float(miou), miou_labelled=float(np.mean(lab)) if lab else 0.0, pixel_accuracy=float(acc),
                iou={k: float(v) for k, v in iou.items()})


def figure_line(f):
    return (f"mIoU {f['miou']:.3f} (labelled classes only {f['miou_labelled']:.3f}), pixel accuracy "
            f"{f['pixel_accuracy']:.3f}; " + ", ".join(f"{k} {v:.3f}" for k, v in f["iou"].items()))


def markdown_report(r):
    rows = ["# ErfNet fine-tune report", "",
            f"- images: `{r['images']}` ({r['pairs']} pairs, scale {r['scale']:g}), legend `{r['legend']}` "
            f"({r['legend_entries']})",
            f"- trained on {len(r['train_images'])}, held out {len(r['held_out_images'])} (seed {r['seed']}, "
            f"holdout {r['holdout']:g}): {', '.join(r['held_out_images'])}",
            f"- started from `{r['init']}`; {r['minutes']:g} min, {r['iterations']} iterations, lr {r['lr']:g}, "
            f"crop {r['crop'][0]}x{r['crop'][1]}, batch {r['batch']}, {r['threads']} thread(s)",
            f"- exported `{r['out']}`: **the {r['exported']} weights** (held-out mIoU {r['before']['miou']:.3f} before, "
            f"{r['trained']['miou']:.3f} after training, {r['after']['miou']:.3f} exported)", "",
            "| class | held-out pixels | IoU before | IoU after training | IoU exported |", "|---|---|---|---|---|"]
    names = [n for n in CLASS_NAMES if any(n in r[k]["iou"] for k in ("before", "trained", "after"))]
    cell = lambda k, n: f"{r[k]['iou'][n]:.3f}" if n in r[k]["iou"] else "–"
    for n in names:
        rows.append(f"| {n} | {r['label_pixels']['held_out'][n]} | {cell('before', n)} | {cell('trained', n)} | {cell('after', n)} |")
    rows.append(f"| **mIoU** | | **{r['before']['miou']:.3f}** | **{r['trained']['miou']:.3f}** | **{r['after']['miou']:.3f}** |")
    rows.append(f"| mIoU, labelled classes only | | {r['before']['miou_labelled']:.3f} | {r['trained']['miou_labelled']:.3f} | "
                f"{r['after']['miou_labelled']:.3f} |")
    rows.append(f"| pixel accuracy | | {r['before']['pixel_accuracy']:.3f} | {r['trained']['pixel_accuracy']:.3f} | "
                f"{r['after']['pixel_accuracy']:.3f} |")
    rows += ["", "IoU is over the held-out images at full size. mIoU averages the classes labelled or predicted "
             "there (a class predicted where none is labelled counts 0); it picks the exported weights. "
             "\"Labelled classes only\" averages the classes with held-out label pixels.", ""]
    lp = r["label_pixels"]
    rows.append("Labels: training pixels " + ", ".join(f"{n} {lp['train'][n]}" for n in CLASS_NAMES) +
                f"; unknown (ignored) {lp['unknown']}. In the label rasters as given" +
                (" (before --scale)" if r["scale"] != 1 else "") + f": {lp['unmapped']} pixels not in the legend, "
                f"{lp['transparent']} transparent, {lp['blended']} anti-aliased edge pixels matched to a neighbouring class.")
    for u in r["unmapped"][:20]:
        rows.append(f"- `{u['file']}`: {u['what']} not in the legend, {u['pixels']} pixels set to unknown")
    return "\n".join(rows) + "\n"


def finetune(a):
    """--images: fine-tunes on a user's labelled images; scores a held-out part before and after; exports the better."""
    import erfnet_dataset
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    rng = random.Random(a.seed)
    try:
        legend = erfnet_dataset.read_legend(a.legend)
        data, stats = erfnet_dataset.load(a.images, legend, a.scale, (a.crop[0], a.crop[1]))
        train_names, held_names = erfnet_dataset.split([d[0] for d in data], a.holdout, a.seed)
        if not os.path.exists(a.init):
            raise erfnet_dataset.DataError(f"starting weights {a.init}: missing (no such file)")
        net = erfnet_reference.Net(NUM_CLASSES)
        try:
            net.load_state_dict(load_init(a.init))
        except SystemExit as e:
            raise erfnet_dataset.DataError(f"starting weights {e.code}")
        except Exception as e:  # torch.load and load_state_dict raise many kinds: one line naming the file
            raise erfnet_dataset.DataError(f"starting weights {a.init}: not ErfNet weights with our "
                                           f"{NUM_CLASSES} classes ({str(e).splitlines()[0] if str(e) else type(e).__name__})")
    except erfnet_dataset.DataError as e:
        fail(str(e))
    os.makedirs(a.work, exist_ok=True)
    by = {d[0]: d for d in data}
    tr_x, tr_y = [by[n][1] for n in train_names], [by[n][2] for n in train_names]
    va_x, va_y = [by[n][1] for n in held_names], [by[n][2] for n in held_names]
    log(f"{len(data)} image / label pairs in {a.images} (legend {a.legend}: {legend.describe()}), scale {a.scale:g}: "
        f"training on {len(train_names)}, holding out {len(held_names)}: {', '.join(held_names)}")
    for n in stats.get("padded", []):
        log(f"  {n} is smaller than the {a.crop[0]}x{a.crop[1]} crop: padded with unknown labels")
    count = lambda labs: np.bincount(np.concatenate([l.ravel() for l in labs]), minlength=256)
    tr_counts, va_counts = count(tr_y), count(va_y)
    unknown = int(tr_counts[IGNORE] + va_counts[IGNORE])
    log("class pixels (training): " + ", ".join(f"{n} {int(c)}" for n, c in zip(CLASS_NAMES, tr_counts)))
    log("class pixels (held out): " + ", ".join(f"{n} {int(c)}" for n, c in zip(CLASS_NAMES, va_counts)))
    log(f"unknown (ignored) pixels: {unknown}; in the label rasters as given{' (before --scale)' if a.scale != 1 else ''}: "
        f"not in the legend {stats.get('unmapped_pixels', 0)}, transparent {stats.get('transparent_pixels', 0)}, "
        f"anti-aliased edge pixels matched to a neighbouring class {stats.get('blended_pixels', 0)}")
    for u in sorted(stats.get("unmapped", []), key=lambda u: -u["pixels"])[:10]:
        log(f"  {u['file']}: {u['what']} is not in the legend: {u['pixels']} pixels set to unknown (missing legend entry?)")
    missing = [n for k, n in enumerate(CLASS_NAMES) if tr_counts[k] == 0]
    if missing:
        log(f"no training pixels of {', '.join(missing)}: not trained, may be forgotten (label some if the site has them)")
    if not (va_counts[:NUM_CLASSES] > 0).any():
        log("warning: the held-out images have no labelled pixels: the scores say nothing")

    weights, _ = class_weights(tr_y, a.weight_power)
    rare = rare_pixels(tr_y, CLASS_NAMES.index("vehicle")) if a.vehicle_crops > 0 else None
    log("class weights: " + ", ".join(f"{n} {w:.2f}" for n, w in zip(CLASS_NAMES, weights.tolist())))
    round_fp16(net)  # as an exported file holds it (an .agw start is fp16 already)
    net.train()
    log(f"starting from {a.init}")
    best = keep_best(net, va_x, va_y, 0, None, None)
    labelled = [n for k, n in enumerate(CLASS_NAMES) if va_counts[k] > 0]
    before = figures(*best[3], labelled)
    log(f"BEFORE (starting weights) on the held-out images: {figure_line(before)}")
    it = train(net, a, tr_x, tr_y, weights, rng, rare, transpose=True)
    round_fp16(net)
    seen = []
    best = keep_best(net, va_x, va_y, it, best, None, seen)
    trained = figures(*seen[0], labelled)
    log(f"AFTER (trained weights, {it} iterations) on the held-out images: {figure_line(trained)}")
    exported = "fine-tuned" if best[2] == it and it > 0 else "starting"
    net.load_state_dict(best[1])
    after = figures(*best[3], labelled)
    if exported == "starting":
        log(f"the trained weights are not better on the held-out images (mIoU {trained['miou']:.3f} against "
            f"{before['miou']:.3f}): exporting the starting weights unchanged")
    export(net, os.path.join(a.work, "erfnet_finetune.pth"), a.out)
    report = dict(mode="finetune", images=a.images, legend=a.legend, legend_entries=legend.describe(),
                  scale=a.scale, pairs=len(data), train_images=train_names, held_out_images=held_names,
                  holdout=a.holdout, seed=a.seed, init=a.init, out=a.out, iterations=it, minutes=a.minutes,
                  threads=a.threads, crop=a.crop, batch=a.batch, lr=a.lr, weight_power=a.weight_power,
                  vehicle_crops=a.vehicle_crops,
                  label_pixels=dict(train={n: int(tr_counts[k]) for k, n in enumerate(CLASS_NAMES)},
                                    held_out={n: int(va_counts[k]) for k, n in enumerate(CLASS_NAMES)},
                                    unknown=unknown, unmapped=int(stats.get("unmapped_pixels", 0)),
                                    transparent=int(stats.get("transparent_pixels", 0)),
                                    blended=int(stats.get("blended_pixels", 0))),
                  unmapped=sorted(stats.get("unmapped", []), key=lambda u: -u["pixels"]),
                  before=before, trained=trained, after=after, exported=exported)
    paths = [os.path.join(a.work, "finetune_report.json"), os.path.splitext(a.out)[0] + ".json"]
    for p in paths:
        with open(p, "w") as f:
            json.dump(report, f, indent=1)
    md = os.path.join(a.work, "finetune_report.md")
    with open(md, "w") as f:
        f.write(markdown_report(report))
    log(f"held-out mIoU: before {before['miou']:.3f}, after training {trained['miou']:.3f}; exported the "
        f"{exported} weights (mIoU {after['miou']:.3f}) to {a.out}")
    log(f"reports: {paths[0]}, {md}, {paths[1]}")
    return 0


def main():
    a = parse_args()
    if a.images is not None:
        sys.exit(finetune(a))
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
    best = None  # (selection mIoU, state_dict, iteration, figures)
    if se_x is not None and a.init:  # the starting point is a candidate too: a fine-tune never ships worse
        best = keep_best(net, se_x, se_y, 0, best)

    def select(it):
        nonlocal best
        best = keep_best(net, se_x, se_y, it, best)

    it = train(net, a, tr_x, tr_y, weights, rng, rare,
               every=(a.eval_every * 60.0, select) if se_x is not None else None)

    if se_x is not None:
        best = keep_best(net, se_x, se_y, it, best)
        net.load_state_dict(best[1])
        log(f"keeping the checkpoint of iteration {best[2]} (selection mIoU {best[0]:.3f})")
    iou, miou, acc = evaluate(net, va_x, va_y)
    log(f"held-out worlds {val_seeds}: mIoU {miou:.3f}, pixel accuracy {acc:.3f}; " +
        ", ".join(f"{k} {v:.3f}" for k, v in iou.items()))
    export(net, os.path.join(a.work, "erfnet_c7.pth"), a.out)
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
