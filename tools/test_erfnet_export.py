#!/usr/bin/python3
"""Tests of tools/erfnet_export.py (run by ctest where python3-torch is installed): a reference
state_dict with or without the `module.` prefix converts to our format with the class count of its output
layer; wrong shapes, missing and unexpected tensors are refused naming the tensor."""
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import erfnet_export  # noqa: E402
import erfnet_reference  # noqa: E402
import erfnet_weights  # noqa: E402

EXPORT = os.path.join(HERE, "erfnet_export.py")


def run(*args):
    return subprocess.run([sys.executable, EXPORT, *args], capture_output=True, text=True)


class Export(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        torch.manual_seed(3)
        cls.net = erfnet_reference.Net(20)  # Cityscapes' class count
        with torch.no_grad():
            for m in cls.net.modules():
                if isinstance(m, torch.nn.BatchNorm2d):
                    m.running_mean.uniform_(-1, 1)
                    m.running_var.uniform_(0.5, 2)
        cls.sd = cls.net.state_dict()

    def path(self, name):
        return os.path.join(self.tmp.name, name)

    def save(self, sd, name):
        p = self.path(name)
        torch.save(sd, p)
        return p

    def test_prefixed_state_dict_converts_with_the_output_layers_class_count(self):
        src = self.save({"module." + k: v for k, v in self.sd.items()}, "prefixed.pth")
        r = run(src, self.path("out.agw"), "--width", "512", "--height", "384")
        self.assertEqual(r.returncode, 0, r.stderr)
        header, tensors = erfnet_weights.read(self.path("out.agw"))
        self.assertEqual(header["num_classes"], 20)
        self.assertEqual((header["input_width"], header["input_height"]), (512, 384))
        self.assertNotIn("encoder.output_conv.weight", tensors)
        self.assertEqual(len(tensors), 304)
        for k, v in tensors.items():
            np.testing.assert_array_equal(v, self.sd[k].numpy(), err_msg=k)

    def test_plain_state_dict_in_a_checkpoint_and_fp16(self):
        src = self.save({"state_dict": dict(self.sd), "epoch": 3}, "ckpt.pth")
        classes, tensors = erfnet_export.convert(erfnet_export.load_state_dict(src), src)
        self.assertEqual(classes, 20)
        erfnet_weights.write(self.path("half.agw"), tensors, classes, 640, 400, fp16=True)
        _, tensors = erfnet_weights.read(self.path("half.agw"))
        w = tensors["encoder.layers.7.conv3x1_2.weight"]
        np.testing.assert_allclose(w, self.sd["encoder.layers.7.conv3x1_2.weight"].numpy(), atol=1e-3)
        self.assertLess(os.path.getsize(self.path("half.agw")), 4.3e6)

    def refused(self, sd):
        with self.assertRaises(SystemExit) as e:
            erfnet_export.convert(sd, "sd.pth")
        return str(e.exception.code)

    def test_refusals_name_the_tensor(self):
        bad = dict(self.sd)
        bad["encoder.layers.3.conv1x3_1.weight"] = torch.zeros(64, 64, 3, 1)
        self.assertIn("encoder.layers.3.conv1x3_1.weight has shape (64, 64, 3, 1), want (64, 64, 1, 3)", self.refused(bad))
        missing = {k: v for k, v in self.sd.items() if k != "decoder.layers.4.bn2.running_var"}
        self.assertIn("decoder.layers.4.bn2.running_var", self.refused(missing))
        extra = dict(self.sd)
        extra["decoder.layers.6.conv.weight"] = torch.zeros(1)
        self.assertIn("unexpected tensor decoder.layers.6.conv.weight", self.refused(extra))
        self.assertIn("no decoder.output_conv.weight", self.refused({"foo": torch.zeros(1)}))
        r = run(self.save(dict(self.sd), "ok.pth"), self.path("x.agw"), "--width", "100")
        self.assertNotEqual(r.returncode, 0)
        self.assertIn("multiples of 8", r.stderr)

    def test_training_resumes_from_our_weights_file(self):
        import erfnet_train  # noqa: E402 (the trainer's --init reads .agw files as well as state_dicts)
        torch.manual_seed(5)
        net7 = erfnet_reference.Net(erfnet_train.NUM_CLASSES)
        classes, tensors = erfnet_export.convert(net7.state_dict(), "net7")
        erfnet_weights.write(self.path("seven.agw"), tensors, classes, 640, 400)
        state = erfnet_train.load_init(self.path("seven.agw"))
        for k, v in net7.state_dict().items():
            if not k.startswith("encoder.output_conv.") and not k.endswith("num_batches_tracked"):
                torch.testing.assert_close(state[k], v, msg=k)
        erfnet_reference.Net(erfnet_train.NUM_CLASSES).load_state_dict(state)
        classes20, tensors20 = erfnet_export.convert(self.sd, "sd")
        erfnet_weights.write(self.path("twenty.agw"), tensors20, classes20, 640, 400)
        with self.assertRaises(SystemExit) as e:
            erfnet_train.load_init(self.path("twenty.agw"))
        self.assertIn("20 classes, training needs 7", str(e.exception.code))


if __name__ == "__main__":
    unittest.main()
