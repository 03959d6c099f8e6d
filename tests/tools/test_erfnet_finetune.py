#!/usr/bin/python3
"""tools/erfnet_train.py --images: fine-tuning the shipped ErfNet weights on a user's own labelled images
(docs/segmentation.md, "Training for your own site"). Run by ctest where Debian's python3-torch is installed.

A tiny synthetic site (6 images of 128x96: a road band, a pond and grass, with noise; labels in legend
COLOURS, anti-aliased edges and a patch of a colour the legend lacks) is fine-tuned for 30 s on one thread;
the run exits 0, reports per-class IoU of the classes present before and after, never exports worse than it
started, and writes a weights file our reader loads and that scores what the report says. Bad input (a missing
label, a legend with an unknown class, an unreadable image, --out onto the shipped weights) exits 2 naming the
file and the problem, without a traceback.

  /usr/bin/python3 tests/tools/test_erfnet_finetune.py [-v] [--keep DIR]   (--keep: build the site in DIR and keep it)
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest
import warnings

import numpy as np
from PIL import Image

SOURCE = os.environ.get("AG_SOURCE_DIR") or os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
TOOLS = os.path.join(SOURCE, "tools")
TRAIN = os.path.join(TOOLS, "erfnet_train.py")
SHIPPED = os.path.join(SOURCE, "config", "erfnet", "erfnet_c7.agw")
sys.path.insert(0, TOOLS)
import erfnet_dataset  # noqa: E402

# The legend colours (config/classes.yaml's display colours) and what the images look like per class.
LEGEND_YAML = """# a colour raster legend, as `airground-sim world import` reads it
classes:
  - {color: [128, 64, 128], class: road}
  - {color: [110, 190, 60], class: grass}
  - {color: [40, 110, 210], class: water}
  - {color: [0, 0, 0], class: unknown}
"""
ROAD, GRASS, WATER = (128, 64, 128), (110, 190, 60), (40, 110, 210)
LOOK = {ROAD: (95, 95, 100), GRASS: (85, 125, 55), WATER: (45, 65, 85)}
ODD = (255, 255, 255)  # a colour the legend lacks: unknown, counted


def airground_sim():
    """The build's airground-sim (ctest's AG_BINARY_DIR, else build/native), or None when it is not built."""
    exe = os.path.join(os.environ.get("AG_BINARY_DIR") or os.path.join(SOURCE, "build", "native"), "sim", "airground-sim")
    return exe if os.access(exe, os.X_OK) else None


def make_site(folder, n=6, w=128, h=96, seed=7):
    """n image / colour-label pairs in `folder` and legend.yaml; returns (legend path, odd-colour pixel count)."""
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    odd = 0
    yy, xx = np.mgrid[0:h, 0:w]
    for k in range(n):
        cls = np.zeros((h, w), dtype=np.uint8)  # 0 grass, 1 road, 2 water
        if k % 2:
            c = rng.integers(20, w - 40)
            cls[:, c:c + rng.integers(18, 30)] = 1
        else:
            r = rng.integers(20, h - 40)
            cls[r:r + rng.integers(16, 26), :] = 1
        cy, cx, rad = rng.integers(20, h - 20), rng.integers(20, w - 20), rng.integers(12, 22)
        cls[(yy - cy) ** 2 + (xx - cx) ** 2 < rad ** 2] = 2
        keys = [GRASS, ROAD, WATER]
        label = np.array(keys, dtype=np.float32)[cls]
        look = np.array([LOOK[c] for c in keys], dtype=np.float32)[cls]
        img = look * rng.uniform(0.85, 1.15) + rng.normal(0, 8, look.shape)
        # anti-aliased label edges: the mean of the two colours where a class meets another
        edge = (cls != np.roll(cls, 1, axis=1)) & (xx > 0)
        label[edge] = (label[edge] + np.array(keys, dtype=np.float32)[np.roll(cls, 1, axis=1)[edge]]) / 2
        if k == 0:  # at least 50 pixels: a missing legend entry by `world import`'s rule, not a smear
            label[2:10, 2:12] = ODD
            odd += 8 * 10
        Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(os.path.join(folder, f"site_{k:02d}.png"))
        Image.fromarray(np.round(label).astype(np.uint8)).save(os.path.join(folder, f"site_{k:02d}_label.png"))
    legend = os.path.join(folder, "legend.yaml")
    with open(legend, "w") as f:
        f.write(LEGEND_YAML)
    return legend, odd


def run(*args):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run(["/usr/bin/python3", TRAIN, *args], capture_output=True, text=True, env=env)


class FineTune(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.site = os.path.join(cls.tmp.name, "site")
        cls.legend, cls.odd = make_site(cls.site)
        cls.work = os.path.join(cls.tmp.name, "work")
        cls.out = os.path.join(cls.tmp.name, "out", "erfnet_site.agw")
        cls.r = run("--images", cls.site, "--legend", cls.legend, "--out", cls.out, "--work", cls.work,
                    "--minutes", "0.5", "--threads", "1", "--crop", "64", "48", "--batch", "4", "--holdout", "0.34")
        path = os.path.join(cls.work, "finetune_report.json")
        cls.report = None
        if os.path.exists(path):
            with open(path) as f:
                cls.report = json.load(f)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_runs_and_reports_per_class_iou_before_and_after(self):
        self.assertEqual(self.r.returncode, 0, self.r.stdout + self.r.stderr)
        r = self.report
        self.assertEqual(r["pairs"], 6)
        self.assertEqual(len(r["held_out_images"]), 2)  # round(0.34 x 6)
        self.assertFalse(set(r["held_out_images"]) & set(r["train_images"]))
        self.assertGreater(r["iterations"], 0)
        for stage in ("before", "trained", "after"):
            for name in ("road", "grass", "water"):  # every class present in the held-out labels is scored
                self.assertGreater(r["label_pixels"]["held_out"][name], 0)
                self.assertIn(name, r[stage]["iou"], stage)
                self.assertTrue(0.0 <= r[stage]["iou"][name] <= 1.0)
        self.assertIn("BEFORE (starting weights) on the held-out images: mIoU", self.r.stdout)
        self.assertIn("AFTER (trained weights", self.r.stdout)
        with open(os.path.join(self.work, "finetune_report.md")) as f:
            md = f.read()
        self.assertIn("| **mIoU** |", md)
        self.assertTrue(os.path.exists(os.path.splitext(self.out)[0] + ".json"))
        print(f"\nheld-out mIoU before {r['before']['miou']:.3f}, after training {r['trained']['miou']:.3f}, "
              f"exported ({r['exported']}) {r['after']['miou']:.3f}; {r['iterations']} iterations", file=sys.stderr)

    def test_never_exports_worse_than_it_started(self):
        r = self.report
        self.assertGreaterEqual(r["after"]["miou"], r["before"]["miou"])
        self.assertAlmostEqual(r["after"]["miou"], max(r["before"]["miou"], r["trained"]["miou"]), places=9)
        self.assertEqual(r["exported"], "fine-tuned" if r["trained"]["miou"] > r["before"]["miou"] else "starting")

    def test_colour_labels_go_through_the_legend(self):
        lp = self.report["label_pixels"]
        self.assertEqual(lp["unmapped"], self.odd)  # the white patch: not in the legend
        self.assertEqual(self.report["unmapped"][0]["what"], "colour [255, 255, 255]")
        self.assertGreater(lp["blended"], 0)  # the anti-aliased edges, matched to a neighbouring class
        self.assertEqual(lp["unknown"], self.odd)
        for name in ("dirt", "tree", "building", "vehicle"):
            self.assertEqual(lp["train"][name], 0)

    def test_the_exported_weights_load_and_score_what_the_report_says(self):
        import erfnet_reference
        import erfnet_train
        import erfnet_weights
        self.assertTrue(os.path.exists(self.out))
        with warnings.catch_warnings():  # erfnet_weights.read leaves its file to the garbage collector
            warnings.simplefilter("ignore", ResourceWarning)
            header, _ = erfnet_weights.read(self.out)  # checks magic and CRC
            state = erfnet_train.load_init(self.out)  # the script's own loader (the one --init uses)
        self.assertEqual(header["num_classes"], 7)
        self.assertEqual(header["class_names"], erfnet_train.CLASS_NAMES)
        self.assertEqual((header["input_width"], header["input_height"]), (640, 400))
        net = erfnet_reference.Net(7)
        net.load_state_dict(state)
        legend = erfnet_dataset.read_legend(self.legend)
        data, _ = erfnet_dataset.load(self.site, legend)
        held = [d for d in data if d[0] in self.report["held_out_images"]]
        iou, miou, acc = erfnet_train.evaluate(net, [d[1] for d in held], [d[2] for d in held])
        self.assertAlmostEqual(miou, self.report["after"]["miou"], places=6)
        self.assertAlmostEqual(acc, self.report["after"]["pixel_accuracy"], places=6)

    # ---- bad input: exit 2, a message naming the file and the problem, no traceback

    def bad_run(self, site, legend, *extra):
        r = run("--images", site, "--legend", legend, "--out", os.path.join(self.tmp.name, "bad.agw"),
                "--work", os.path.join(self.tmp.name, "badwork"), "--minutes", "0", *extra)
        self.assertEqual(r.returncode, 2, r.stdout + r.stderr)
        self.assertNotIn("Traceback", r.stderr)
        return r.stderr

    def copy_site(self, name):
        d = os.path.join(self.tmp.name, name)
        shutil.copytree(self.site, d)
        return d

    def test_a_missing_label_is_refused_naming_the_file(self):
        d = self.copy_site("no_label")
        os.remove(os.path.join(d, "site_03_label.png"))
        err = self.bad_run(d, os.path.join(d, "legend.yaml"))
        self.assertIn(os.path.join(d, "site_03.png"), err)
        self.assertIn("no label raster", err)
        self.assertIn("site_03_label.png", err)

    def test_a_legend_with_an_unknown_class_is_refused_naming_it(self):
        legend = os.path.join(self.tmp.name, "rock.yaml")
        with open(legend, "w") as f:
            f.write(LEGEND_YAML + "  - {color: [200, 200, 200], class: rock}\n")
        err = self.bad_run(self.site, legend)
        self.assertIn(f"legend {legend}:7: unknown class 'rock'", err)

    def test_an_unreadable_image_and_a_size_mismatch_are_refused_naming_the_file(self):
        d = self.copy_site("broken")
        with open(os.path.join(d, "site_02.png"), "wb") as f:
            f.write(b"not a png at all")
        err = self.bad_run(d, os.path.join(d, "legend.yaml"))
        self.assertIn(f"image {os.path.join(d, 'site_02.png')}: cannot read it as an image", err)
        d = self.copy_site("sizes")
        Image.new("RGB", (64, 48)).save(os.path.join(d, "site_01_label.png"))
        err = self.bad_run(d, os.path.join(d, "legend.yaml"))
        self.assertIn(f"label raster {os.path.join(d, 'site_01_label.png')} is 64x48 but image", err)
        self.assertIn("sizes differ", err)

    def test_a_missing_legend_and_out_onto_the_shipped_weights_are_refused(self):
        missing = os.path.join(self.tmp.name, "nope.yaml")
        self.assertIn(f"legend {missing}: missing (no such file)", self.bad_run(self.site, missing))
        r = run("--images", self.site, "--legend", self.legend, "--out", SHIPPED, "--minutes", "0")
        self.assertEqual(r.returncode, 2)
        self.assertIn("is the shipped or the starting weights file", r.stderr)
        r = run("--images", self.site, "--legend", self.legend)
        self.assertEqual(r.returncode, 2)
        self.assertIn("--images needs --out", r.stderr)


class Legend(unittest.TestCase):
    """The legend and label-raster rules, in process (no training)."""

    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()

    def tearDown(self):
        self.tmp.cleanup()

    def write(self, name, text):
        p = os.path.join(self.tmp.name, name)
        with open(p, "w") as f:
            f.write(text)
        return p

    def test_value_rasters_map_through_the_legend_and_count_what_it_lacks(self):
        legend = erfnet_dataset.read_legend(self.write("v.yaml", "classes:\n  - {value: 1, class: road}\n"
                                                       "  - {value: 7, class: water}\n  - {value: 0, class: unknown}\n"))
        self.assertFalse(legend.by_colour)
        grey = np.array([[1, 7, 0, 9], [9, 9, 1, 1]], dtype=np.uint8)
        stats = {}
        out = erfnet_dataset.labels_from_values(Image.fromarray(grey), legend, "g.png", stats)
        np.testing.assert_array_equal(out, [[0, 6, 255, 255], [255, 255, 0, 0]])
        self.assertEqual(stats["unmapped_pixels"], 3)
        self.assertEqual(stats["unmapped"], [dict(file="g.png", what="value 9", pixels=3)])
        with self.assertRaisesRegex(erfnet_dataset.DataError, "has 3 bands but the legend lists values"):
            erfnet_dataset.labels_from_values(Image.new("RGB", (4, 2)), legend, "c.png", {})

    def test_legend_rules_are_world_imports(self):
        bad = {
            "classes: []\n": "expected a non-empty 'classes:' list",
            "classes:\n  - {value: 1, color: [1, 2, 3], class: road}\n": "either 'value' or 'color', not both",
            "classes:\n  - {value: 1, class: road}\n  - {value: 1, class: dirt}\n": ":3: value 1 is listed twice",
            "classes:\n  - {value: 1, class: road}\n  - {color: [1, 2, 3], class: dirt}\n": "mixes value and color",
            "classes:\n  - {color: [1, 2, 300], class: road}\n": "color components must be 0..255",
            "classes:\n  - {value: 1}\n": "entry has no 'class:'",
            "classes:\n  - {value: 1, class: Road}\n": "unknown class 'Road' \\(known: road, dirt",
        }
        for text, msg in bad.items():
            with self.assertRaisesRegex(erfnet_dataset.DataError, msg, msg=text):
                erfnet_dataset.read_legend(self.write("bad.yaml", text))

    @unittest.skipUnless(airground_sim(), "no built airground-sim to compare with")
    def test_colour_rasters_map_as_world_import_maps_them(self):
        """A blurred (anti-aliased), JPEG-smeared colour raster with a transparent hole: the class ids are
        `airground-sim world import`'s, pixel for pixel."""
        import io
        from PIL import ImageFilter
        site = os.path.join(self.tmp.name, "site")
        legend_path, _ = make_site(site, n=2)
        lab = Image.open(os.path.join(site, "site_01_label.png")).convert("RGB").resize((256, 192), Image.NEAREST)
        buf = io.BytesIO()
        lab.filter(ImageFilter.GaussianBlur(1.2)).save(buf, "JPEG", quality=85)
        rgb = np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGB"))
        rgba = np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)])
        rgba[10:20, 10:30, 3] = 0
        raster = os.path.join(self.tmp.name, "smeared.png")
        Image.fromarray(rgba).save(raster)
        world = os.path.join(self.tmp.name, "world")
        r = subprocess.run([airground_sim(), "world", "import", "--classes", raster, "--legend", legend_path,
                            "--resolution", "0.25", "--out", world], capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        stats = {}
        ours = erfnet_dataset.read_label(raster, erfnet_dataset.read_legend(legend_path), stats)
        np.testing.assert_array_equal(ours, np.asarray(Image.open(os.path.join(world, "class.png"))))
        self.assertEqual(stats["transparent_pixels"], 200)
        self.assertGreater(stats["blended_pixels"], 1000)

    def test_the_plain_reader_agrees_with_pyyaml(self):
        """Without python3-yaml the legend is read by a reader of the documented forms; it reads them as PyYAML does."""
        block = "classes:\n  - value: 3   # a comment\n    class: tree\n  - value: 4\n    class: 'building'\n"
        cases = {block: [(2, {"value": 3, "class": "tree"}), (4, {"value": 4, "class": "building"})],
                 LEGEND_YAML: [(3, {"color": [128, 64, 128], "class": "road"}), (4, {"color": [110, 190, 60], "class": "grass"}),
                               (5, {"color": [40, 110, 210], "class": "water"}), (6, {"color": [0, 0, 0], "class": "unknown"})]}
        for text, want in cases.items():
            self.assertEqual(erfnet_dataset._legend_entries_plain("x.yaml", text), want)
            try:
                import yaml  # noqa: F401
            except ImportError:
                continue
            self.assertEqual(erfnet_dataset._legend_entries("x.yaml", text), want)

if __name__ == "__main__":
    if "--keep" in sys.argv:  # build the synthetic site only (for measuring by hand)
        folder = sys.argv[sys.argv.index("--keep") + 1]
        n = int(sys.argv[sys.argv.index("--n") + 1]) if "--n" in sys.argv else 6
        print(make_site(folder, n=n))
        sys.exit(0)
    unittest.main()
