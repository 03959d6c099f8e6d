#!/usr/bin/python3
"""tools/check_structure.py on small trees made here: it finds what it must and nothing else."""
import os
import subprocess
import sys
import tempfile
import unittest

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "check_structure.py")


def write(root, rel, text):
    path = os.path.join(root, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def check(root, rule):
    r = subprocess.run([sys.executable, TOOL, rule, root], capture_output=True, text=True)
    return r.returncode, r.stdout


class Layers(unittest.TestCase):
    def tree(self, root):
        write(root, "platform/include/airground/platform/ring.hpp", "#pragma once\n")
        write(root, "messages/include/airground/messages/messages.hpp", '#include "airground/platform/ring.hpp"\n')
        write(root, "pipeline/localization/include/airground/localization/pf.hpp", '#include "airground/messages/messages.hpp"\n')

    def test_includes_below_pass(self):
        with tempfile.TemporaryDirectory() as root:
            self.tree(root)
            self.assertEqual(check(root, "layers")[0], 0)

    def test_an_include_from_a_layer_above_is_named(self):
        with tempfile.TemporaryDirectory() as root:
            self.tree(root)
            write(root, "drivers/can/src/bus.cpp", '// ok\n#include "airground/localization/pf.hpp"\n')
            rc, out = check(root, "layers")
            self.assertEqual(rc, 1)
            self.assertIn("drivers/can/src/bus.cpp:2: drivers includes airground/localization/pf.hpp of pipeline", out)


class Sizes(unittest.TestCase):
    def test_a_long_function_and_a_long_file_are_named(self):
        with tempfile.TemporaryDirectory() as root:
            body = lambda n: "".join(f"  x += {i};\n" for i in range(n))
            # f: lines 3-152, 150 lines with its braces (within the rule); g: lines 154-305, 152 lines.
            write(root, "sim/a.cpp", "namespace ag {\nstruct S {\n  int f() {\n" + body(148) + "  }\n};\nint g() {\n" + body(149) +
                  "  return 0; // {\n}\n}\n")
            rc, out = check(root, "sizes")
            self.assertEqual(rc, 1)
            self.assertIn("sim/a.cpp:154: a function of 152 lines", out)
            self.assertNotIn("sim/a.cpp:3:", out)
            write(root, "sim/a.cpp", "int x;\n" * 701)
            rc, out = check(root, "sizes")
            self.assertIn("sim/a.cpp: 701 lines", out)

    def test_small_code_passes(self):
        with tempfile.TemporaryDirectory() as root:
            write(root, "platform/b.cpp", 'namespace ag {\nint f() { return 1; }\nconst char* s = "}}}";\n}\n')
            table = "".join(f"    {{{i}, {i * 2}}},\n" for i in range(300))  # a generated table is data, not a function
            write(root, "drivers/t.cpp", "namespace ag {\nconstexpr Row kRows[] = {\n" + table + "};\n}\n")
            self.assertEqual(check(root, "sizes"), (0, "sizes: the rule holds\n"))


if __name__ == "__main__":
    unittest.main()
