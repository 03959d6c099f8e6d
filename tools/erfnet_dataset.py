"""A user's own labelled aerial images for tools/erfnet_train.py --images DIR --legend LEGEND.yaml.

The folder holds pairs, side by side:

  NAME.png | NAME.jpg | NAME.jpeg | NAME.tif | NAME.tiff     the image (8-bit RGB or grey; EXIF rotation applied)
  NAME_label.png | NAME_label.tif | NAME_label.tiff          its label raster, the same size in pixels

A label raster holds either legend values (one band: 8- or 16-bit grey, or a palette PNG's indices) or legend
colours (RGB, RGBA, grey or paletted), as the legend says; the legend is `airground-sim world import`'s
(docs/simulator.md, sim/world/importer.cpp):

  classes:                                 classes:
    - {value: 1, class: road}          or    - {color: [128, 64, 128], class: road}
    - {value: 0, class: unknown}             - {color: [0, 0, 0], class: unknown}

with the class names of config/classes.yaml (road dirt grass tree building vehicle water, and unknown).
Mapping is the importer's: a value raster maps each value through the legend; a colour raster takes a
pixel within 24 (RGB distance) of a legend colour as that colour, an anti-aliased or JPEG-smeared pixel
(within 48 of a legend colour, or within 20 of the line between two) as the nearest legend colour among the
pure pixels of its 5x5 neighbourhood (any other pixel as its nearest legend colour), and a transparent pixel
(alpha < 128) as unknown. Where `world import` refuses a raster (a value not in the legend, or a colour on at
least 50 pixels and 0.2 % of the raster that is neither near a legend colour nor a mix of two: a missing legend
entry), training instead sets those pixels to unknown (255: ignored by the loss and the scores) and counts and
reports them.
"""
import os

import numpy as np
from PIL import Image, ImageOps

CLASS_NAMES = ["road", "dirt", "grass", "tree", "building", "vehicle", "water"]  # ids 0..6 of config/classes.yaml
CLASS_IDS = {n: i for i, n in enumerate(CLASS_NAMES)}
CLASS_IDS["unknown"] = 255
IGNORE = 255

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
LABEL_SUFFIX = "_label"
LABEL_EXTS = (".png", ".tif", ".tiff")

PURE_DISTANCE = 24       # as sim/world/importer.cpp: kPureColourDistance
EXPLAINED_DISTANCE = 48  # kExplainedDistance
BLEND_DISTANCE = 20.0    # kBlendDistance
MISSING_ENTRY_SHARE = 0.002  # kMissingEntryShare: a colour on this share of the pixels (and at least 50) must be explained


class DataError(Exception):
    """Bad input, with a message naming the file and what is wrong (erfnet_train.py exits 2 on it)."""


class Legend:
    def __init__(self, path):
        self.path = path
        self.by_colour = False
        self.values = {}   # value -> class id
        self.colours = []  # [((r, g, b), class id)]

    def describe(self):
        return f"{len(self.colours)} colour entries" if self.by_colour else f"{len(self.values)} value entries"


# ---------------------------------------------------------------------------------------------- legend

def _legend_entries(path, text):
    """[(line, {key: value})] of the legend's `classes:` list, through PyYAML when installed (python3-yaml),
    else through a reader of the forms docs/simulator.md shows (flow maps, or block maps, in a block list)."""
    try:
        import yaml
    except ImportError:
        return _legend_entries_plain(path, text)
    try:
        root = yaml.safe_load(text)
        node = yaml.compose(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        raise DataError(f"legend {path}{':' + str(mark.line + 1) if mark else ''}: malformed YAML: "
                        f"{getattr(e, 'problem', None) or e}")
    if not isinstance(root, dict) or not isinstance(root.get("classes"), list) or not root["classes"]:
        raise DataError(f"legend {path}: expected a non-empty 'classes:' list of {{value: N, class: NAME}} "
                        "or {color: [R, G, B], class: NAME}")
    seq = next(v for k, v in node.value if k.value == "classes")
    return [(n.start_mark.line + 1, e) for n, e in zip(seq.value, root["classes"])]


def _scalar(s):
    s = s.strip()
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "'\"":
        return s[1:-1]
    if s.startswith("[") and s.endswith("]"):
        return [_scalar(p) for p in s[1:-1].split(",") if p.strip()]
    try:
        return int(s, 0)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return s


def _flow_map(path, line, s):
    """'{color: [1, 2, 3], class: road}' -> dict (no nesting beyond one list)."""
    body, out, depth, part = s.strip()[1:-1], {}, 0, ""
    parts = []
    for ch in body:
        depth += ch == "["
        depth -= ch == "]"
        if ch == "," and depth == 0:
            parts.append(part)
            part = ""
        else:
            part += ch
    parts.append(part)
    for p in parts:
        if not p.strip():
            continue
        if ":" not in p:
            raise DataError(f"legend {path}:{line}: malformed entry '{s.strip()}'")
        k, v = p.split(":", 1)
        out[k.strip()] = _scalar(v)
    return out


def _legend_entries_plain(path, text):
    entries, in_classes, cur = [], False, None
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split(" #")[0].rstrip() if not raw.lstrip().startswith("#") else ""
        if not line.strip():
            continue
        if not line[0].isspace() and not line.startswith("-"):
            in_classes = line.split(":")[0].strip() == "classes"
            continue
        if not in_classes:
            continue
        s = line.strip()
        if s.startswith("-"):
            s = s[1:].strip()
            cur = (n, {})
            entries.append(cur)
            if s.startswith("{"):
                cur[1].update(_flow_map(path, n, s))
                continue
        if cur is None or ":" not in s:
            raise DataError(f"legend {path}:{n}: malformed YAML (expected '- {{value: N, class: NAME}}')")
        k, v = s.split(":", 1)
        cur[1][k.strip()] = _scalar(v)
    if not entries:
        raise DataError(f"legend {path}: expected a non-empty 'classes:' list of {{value: N, class: NAME}} "
                        "or {color: [R, G, B], class: NAME}")
    return entries


def read_legend(path):
    """The legend, with `world import`'s rules and messages; DataError naming the file and line otherwise."""
    if not path:
        raise DataError("no legend file given (--legend)")
    if not os.path.exists(path):
        raise DataError(f"legend {path}: missing (no such file)")
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(f"legend {path}: cannot open ({e})")
    legend = Legend(path)
    any_value = any_colour = False
    known = ", ".join(list(CLASS_IDS))
    for line, e in _legend_entries(path, text):
        where = f"legend {path}:{line}"
        if not isinstance(e, dict):
            raise DataError(f"{where}: each entry must be a map")
        if "class" not in e:
            raise DataError(f"{where}: entry has no 'class:'")
        name = str(e["class"])
        if name not in CLASS_IDS:
            raise DataError(f"{where}: unknown class '{name}' (known: {known})")
        cls = CLASS_IDS[name]
        if "value" in e and "color" in e:
            raise DataError(f"{where}: an entry has either 'value' or 'color', not both")
        if "value" in e:
            any_value = True
            v = e["value"]
            if isinstance(v, bool) or not isinstance(v, int):
                raise DataError(f"{where}: bad entry: value '{v}' is not an integer")
            if v < -2 ** 31 or v > 2 ** 32 - 1:
                raise DataError(f"{where}: value out of range")
            if legend.values.get(v, cls) != cls:
                raise DataError(f"{where}: value {v} is listed twice with different classes")
            legend.values[v] = cls
        elif "color" in e:
            any_colour = True
            c = e["color"]
            if not isinstance(c, list) or len(c) != 3:
                raise DataError(f"{where}: color must be [R, G, B]")
            if not all(isinstance(k, int) and not isinstance(k, bool) for k in c):
                raise DataError(f"{where}: bad entry: color components must be integers")
            if any(k < 0 or k > 255 for k in c):
                raise DataError(f"{where}: color components must be 0..255")
            rgb = tuple(c)
            if any(o == rgb and oc != cls for o, oc in legend.colours):
                raise DataError(f"{where}: color listed twice with different classes")
            legend.colours.append((rgb, cls))
        else:
            raise DataError(f"{where}: entry needs 'value: N' (value rasters) or 'color: [R, G, B]' (colour rasters)")
    if len(legend.colours) > 100:
        raise DataError(f"legend {path}: at most 100 color entries")
    if any_value and any_colour:
        raise DataError(f"legend {path}: mixes value and color entries; a legend describes either a value raster "
                        "or a colour raster")
    legend.by_colour = any_colour
    return legend


# ------------------------------------------------------------------------------------------- the pairs

def find_pairs(folder):
    """[(name, image path, label path)] sorted by name; DataError naming the file for a half pair."""
    if not os.path.isdir(folder):
        raise DataError(f"images folder {folder}: missing (no such directory)")
    files = sorted(f for f in os.listdir(folder) if not f.startswith(".") and os.path.isfile(os.path.join(folder, f)))
    images, labels = {}, {}
    for f in files:
        stem, ext = os.path.splitext(f)
        ext = ext.lower()
        if stem.endswith(LABEL_SUFFIX) and ext in LABEL_EXTS:
            labels.setdefault(stem[:-len(LABEL_SUFFIX)], []).append(f)
        elif stem.endswith(LABEL_SUFFIX) and ext in IMAGE_EXTS:
            raise DataError(f"{os.path.join(folder, f)}: a label raster must be lossless: "
                            f"{' or '.join(LABEL_EXTS)} (JPEG smears the class colours)")
        elif ext in IMAGE_EXTS:
            images.setdefault(stem, []).append(f)
    for stem, fs in list(images.items()) + list(labels.items()):
        if len(fs) > 1:
            raise DataError(f"{folder}: {' and '.join(fs)} have the same name; keep one")
    for stem, (f,) in labels.items():
        if stem not in images:
            raise DataError(f"{os.path.join(folder, f)}: label raster without an image "
                            f"(expected {stem}{IMAGE_EXTS[0]}, {', '.join(IMAGE_EXTS[1:])})")
    pairs = []
    for stem, (f,) in sorted(images.items()):
        if stem not in labels:
            raise DataError(f"{os.path.join(folder, f)}: no label raster "
                            f"(expected {os.path.join(folder, stem + LABEL_SUFFIX + '.png')})")
        pairs.append((stem, os.path.join(folder, f), os.path.join(folder, labels[stem][0])))
    if not pairs:
        raise DataError(f"images folder {folder}: no image / label pairs (NAME.png|jpg|tif with NAME_label.png)")
    return pairs


def _open(path, what):
    try:
        im = Image.open(path)
        im.load()
        return im
    except Image.DecompressionBombError as e:
        raise DataError(f"{what} {path}: too large to read ({e}); cut it into tiles")
    except (OSError, ValueError, SyntaxError) as e:
        raise DataError(f"{what} {path}: cannot read it as an image ({e})")


def read_image(path):
    """H x W x 3 uint8, as displayed (EXIF orientation applied)."""
    im = _open(path, "image")
    try:
        im = ImageOps.exif_transpose(im)
    except Exception:  # a broken EXIF block: take the pixels as stored
        pass
    if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        raise DataError(f"image {path}: {im.mode} (16-bit or float) pixels; export it as 8-bit RGB")
    if im.mode not in ("RGB", "RGBA", "L", "LA", "P", "CMYK", "YCbCr", "1"):
        raise DataError(f"image {path}: unsupported pixel format {im.mode}; export it as 8-bit RGB")
    return np.asarray(im.convert("RGB"))


def read_label(path, legend, stats):
    """H x W uint8 class ids (255 unknown) through the legend; stats counts what was set to unknown."""
    im = _open(path, "label raster")
    return (labels_from_colours if legend.by_colour else labels_from_values)(im, legend, path, stats)


def labels_from_values(im, legend, path, stats):
    if im.mode in ("RGB", "RGBA", "CMYK", "YCbCr", "LA", "RGBX"):
        raise DataError(f"label raster {path} has {len(im.getbands())} bands but the legend lists values; a value "
                        "raster has one band (use color: entries for colour rasters)")
    v = np.asarray(im)
    if v.dtype.kind == "f":
        if not np.all(np.isfinite(v)) or np.any(v != np.floor(v)):
            bad = np.argwhere(~np.isfinite(v) | (v != np.floor(v)))[0]
            raise DataError(f"label raster {path}: value {v[tuple(bad)]} at ({bad[1]}, {bad[0]}) is not an integer "
                            "class value")
    v = v.astype(np.int64)
    uniq, inv = np.unique(v, return_inverse=True)
    lut = np.array([legend.values.get(int(u), -1) for u in uniq], dtype=np.int64)
    out = lut[inv.reshape(v.shape)]
    missing = out < 0
    if missing.any():
        counts = np.bincount(inv.ravel()[missing.ravel()], minlength=len(uniq))
        for k in np.nonzero(counts)[0]:
            stats.setdefault("unmapped", []).append(dict(file=path, what=f"value {int(uniq[k])}", pixels=int(counts[k])))
        stats["unmapped_pixels"] = stats.get("unmapped_pixels", 0) + int(missing.sum())
        out[missing] = IGNORE
    return out.astype(np.uint8)


def _segment_distance(p, a, b):
    ab = b - a
    l2 = float(ab @ ab)
    t = np.clip(((p - a) @ ab) / l2, 0.0, 1.0) if l2 > 0 else np.zeros(len(p))
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def labels_from_colours(im, legend, path, stats):
    alpha = None
    transparent = np.zeros(im.size[::-1], dtype=bool)
    if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        raise DataError(f"label raster {path}: colours must be 8-bit (got {im.mode})")
    if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
        rgba = np.asarray(im.convert("RGBA"))
        rgb, alpha = rgba[..., :3], rgba[..., 3]
    else:
        rgb = np.asarray(im.convert("RGB"))
    lc = np.array([c for c, _ in legend.colours], dtype=np.int64)  # n x 3
    lcls = np.array([k for _, k in legend.colours], dtype=np.int64)
    key = (rgb[..., 0].astype(np.int64) << 16) | (rgb[..., 1].astype(np.int64) << 8) | rgb[..., 2]
    uniq, inv = np.unique(key, return_inverse=True)
    inv = inv.reshape(key.shape)
    ucol = np.stack([uniq >> 16, (uniq >> 8) & 255, uniq & 255], axis=1)  # U x 3
    d2 = ((ucol[:, None, :] - lc[None, :, :]) ** 2).sum(axis=2)            # U x n
    nearest = d2.argmin(axis=1)                                           # first on ties, as the importer
    pure = d2[np.arange(len(uniq)), nearest] <= PURE_DISTANCE ** 2
    explained = np.sqrt(d2.min(axis=1)) <= EXPLAINED_DISTANCE
    for i in range(len(lc)):
        for j in range(i + 1, len(lc)):
            explained |= _segment_distance(ucol.astype(np.float64), lc[i].astype(np.float64),
                                           lc[j].astype(np.float64)) <= BLEND_DISTANCE
    # Per pixel: its nearest legend entry, whether pure; blends take the nearest pure neighbour's (5x5).
    entry = nearest[inv]
    is_pure = pure[inv]
    pick = entry.copy()
    blend = ~is_pure
    if blend.any():
        H, W = key.shape
        ys, xs = np.nonzero(blend)
        big = np.iinfo(np.int64).max
        best = np.full(len(ys), big, dtype=np.int64)
        for dy in range(-2, 3):
            for dx in range(-2, 3):
                yy, xx = ys + dy, xs + dx
                ok = (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
                yy, xx = np.clip(yy, 0, H - 1), np.clip(xx, 0, W - 1)
                ne = entry[yy, xx]
                score = np.where(ok & is_pure[yy, xx], d2[inv[ys, xs], ne] * 128 + ne, big)  # nearest, then earlier entry
                best = np.minimum(best, score)
        found = best != big
        pick[ys[found], xs[found]] = best[found] % 128
    out = lcls[pick]
    if alpha is not None:
        transparent = alpha < 128
        out[transparent] = IGNORE
        stats["transparent_pixels"] = stats.get("transparent_pixels", 0) + int(transparent.sum())
    # A colour used a lot (the importer's threshold) that is neither near a legend colour nor a mix of two is a
    # missing legend entry: `world import` refuses the raster, training sets its pixels to unknown.
    counts = np.bincount(inv[~transparent], minlength=len(uniq))
    missing_entry = ~explained & (counts >= max(50.0, MISSING_ENTRY_SHARE * key.size))
    unexplained = missing_entry[inv] & ~transparent
    if unexplained.any():
        for k in np.argsort(-np.where(missing_entry, counts, 0))[:8]:
            if not missing_entry[k]:
                break
            r, g, b = (int(x) for x in ucol[k])
            stats.setdefault("unmapped", []).append(dict(file=path, what=f"colour [{r}, {g}, {b}]", pixels=int(counts[k])))
        stats["unmapped_pixels"] = stats.get("unmapped_pixels", 0) + int(unexplained.sum())
        out[unexplained] = IGNORE
    stats["blended_pixels"] = stats.get("blended_pixels", 0) + int((blend & ~unexplained & ~transparent).sum())
    return out.astype(np.uint8)


# --------------------------------------------------------------------------------------- loading it all

def _resize(img, lab, scale):
    h, w = lab.shape
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    im = Image.fromarray(img).resize(size, Image.BOX if scale < 1 else Image.BILINEAR)
    lb = Image.fromarray(lab).resize(size, Image.NEAREST)
    return np.asarray(im), np.asarray(lb)


def load(folder, legend, scale=1.0, min_size=(0, 0)):
    """[(name, image H x W x 3 uint8, labels H x W uint8)] and stats; each pair checked, resampled by `scale`
    (image box/bilinear, classes nearest) and padded (edge pixels, unknown labels) to at least min_size (W, H)."""
    stats = {}
    out = []
    for name, ipath, lpath in find_pairs(folder):
        img = read_image(ipath)
        lab = read_label(lpath, legend, stats)
        if img.shape[:2] != lab.shape:
            raise DataError(f"label raster {lpath} is {lab.shape[1]}x{lab.shape[0]} but image {ipath} is "
                            f"{img.shape[1]}x{img.shape[0]}: sizes differ (a label must cover its image pixel for pixel)")
        if scale != 1.0:
            img, lab = _resize(img, lab, scale)
        ph, pw = max(0, min_size[1] - lab.shape[0]), max(0, min_size[0] - lab.shape[1])
        if ph or pw:
            img = np.pad(img, ((0, ph), (0, pw), (0, 0)), mode="edge")
            lab = np.pad(lab, ((0, ph), (0, pw)), constant_values=IGNORE)
            stats.setdefault("padded", []).append(name)
        out.append((name, np.ascontiguousarray(img), np.ascontiguousarray(lab)))
    return out, stats


def split(names, holdout, seed):
    """(training names, held-out names): round(holdout x N) held out, at least 1, at least 1 left to train on;
    the same for the same names, fraction and seed."""
    import random
    if len(names) < 2:
        raise DataError(f"{len(names)} image / label pair: need at least 2 (one to train on, one held out)")
    n = min(max(1, int(round(holdout * len(names)))), len(names) - 1)
    held = set(random.Random(seed).sample(sorted(names), n))
    return [s for s in names if s not in held], [s for s in names if s in held]
