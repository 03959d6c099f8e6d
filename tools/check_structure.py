#!/usr/bin/python3
"""The tree's structure rules (docs/architecture.md), checked at every ctest run.

  check_structure.py layers [ROOT]   every #include "airground/..." goes to the same layer or one below
  check_structure.py sizes  [ROOT]   no source file over 700 lines, no function over 150, in the robot
                                     and simulator code (platform/, messages/, pipeline/, drivers/, sim/)

Exit status 0 when the rules hold, 1 with one line per breach naming the file (and line), 2 on bad usage.
"""
import os
import re
import sys

# Bottom to top. A file may include its own layer and any layer below; never one above.
LAYERS = ["platform", "messages", "drivers", "pipeline", "firmware_host", "sim"]
RULES = {
    "platform": "the runtime: knows nothing of robots",
    "messages": "the messages between drivers, pipeline and simulator: platform only",
    "drivers": "devices behind one interface each (live, replay, fake): platform and messages",
    "pipeline": "the algorithms and their stages: drivers' contracts, messages, platform",
    "firmware_host": "one role table per robot and its main: everything below",
    "sim": "the simulator and its evaluations: everything below, the role tables included",
}
SIZE_ROOTS = ["platform", "messages", "pipeline", "drivers", "sim"]
MAX_FILE_LINES = 700
MAX_FUNCTION_LINES = 150
SKIP_DIRS = {".git", "build", "node_modules"}


def layer_of(rel):
    top = rel.split("/")[0]
    if top in LAYERS:
        return top
    return None  # tests/, tools/: may include anything


def sources(root, tops):
    for top in tops:
        base = os.path.join(root, top)
        for dirpath, dirnames, filenames in os.walk(base):
            dirnames[:] = [d for d in dirnames if d not in SKIP_DIRS]
            for f in sorted(filenames):
                if f.endswith((".cpp", ".hpp", ".h", ".cc")):
                    full = os.path.join(dirpath, f)
                    yield full, os.path.relpath(full, root)


def header_layers(root):
    """airground/... include path -> the layer of the folder that holds it."""
    out = {}
    for full, rel in sources(root, LAYERS):
        m = re.search(r"/include/(airground/.+)$", rel)
        if m:
            out[m.group(1)] = layer_of(rel)
    return out


def check_layers(root):
    where = header_layers(root)
    rank = {name: i for i, name in enumerate(LAYERS)}
    breaches = []
    for full, rel in sources(root, LAYERS):
        mine = layer_of(rel)
        with open(full, errors="replace") as f:
            for n, line in enumerate(f, 1):
                m = re.match(r'\s*#\s*include\s*"(airground/[^"]+)"', line)
                if not m:
                    continue
                theirs = where.get(m.group(1))
                if theirs is not None and rank[theirs] > rank[mine]:
                    breaches.append(f"{rel}:{n}: {mine} includes {m.group(1)} of {theirs}, a layer above "
                                    f"({mine}: {RULES[mine]})")
    return breaches


def strip_code(text):
    """Comments, strings and character literals blanked out; line breaks kept."""
    keep_lines = lambda m: "\n" * m.group(0).count("\n")
    text = re.sub(r'R"(\w*)\((.*?)\)\1"', lambda m: '""' + keep_lines(m), text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    text = re.sub(r"/\*.*?\*/", keep_lines, text, flags=re.S)
    text = re.sub(r'"(\\.|[^"\\\n])*"', '""', text)
    return re.sub(r"'(\\.|[^'\\\n])*'", "''", text)


def function_lengths(text):
    """(first line, lines) of every brace block that opens at namespace or class scope after a parameter
    list: the functions, member functions and lambdas at that scope (not namespaces, classes, enums or
    data initialisers such as a table's `= {`)."""
    out = []
    stack = []  # "scope" (namespace, class...), "data", ("fn", line) or "inner"
    head = ""   # the text since the last ';', '{' or '}': what a brace opens
    for n, line in enumerate(strip_code(text).split("\n"), 1):
        for ch in line:
            if ch == "{":
                if any(isinstance(s, tuple) or s == "data" for s in stack):
                    stack.append("inner")
                elif re.search(r"\b(namespace|extern)\b", head) or re.search(r"\b(class|struct|enum|union)\b[^;()=]*$", head):
                    stack.append("scope")
                elif ")" in head:
                    stack.append(("fn", n))
                else:
                    stack.append("data")
                head = ""
            elif ch == "}":
                if stack:
                    top = stack.pop()
                    if isinstance(top, tuple):
                        out.append((top[1], n - top[1] + 1))
                head = ""
            elif ch == ";":
                head = ""
            else:
                head += ch
        head += " "
    return out


def check_sizes(root):
    breaches = []
    for full, rel in sources(root, SIZE_ROOTS):
        with open(full, errors="replace") as f:
            text = f.read()
        lines = text.count("\n")
        if lines > MAX_FILE_LINES:
            breaches.append(f"{rel}: {lines} lines, more than {MAX_FILE_LINES}: split it into files by responsibility")
        for first, length in function_lengths(text):
            if length > MAX_FUNCTION_LINES:
                breaches.append(f"{rel}:{first}: a function of {length} lines, more than {MAX_FUNCTION_LINES}")
    return breaches


def main(argv):
    if len(argv) < 2 or argv[1] in ("-h", "--help") or argv[1] not in ("layers", "sizes"):
        print(__doc__.strip())
        return 0 if len(argv) >= 2 and argv[1] in ("-h", "--help") else 2
    root = argv[2] if len(argv) > 2 else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    breaches = check_layers(root) if argv[1] == "layers" else check_sizes(root)
    for b in breaches:
        print(b)
    if breaches:
        print(f"{len(breaches)} breach(es) of the {argv[1]} rule (docs/architecture.md)")
        return 1
    print(f"{argv[1]}: the rule holds")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
