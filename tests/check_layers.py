#!/usr/bin/env python3
"""Fails when a lower layer of Tessera includes a higher one (issue 17, docs/architecture.md).

The layers, lowest first, one folder each:
  core (rect, image, math, scene, validation, cost map, glTF) < lb < codecs < renderer
  < protocol < update < actors < net < app
A file may include its own layer and the layers below it, never a layer above, and no
production file includes tests/. Quoted includes ("folder/file.h") are checked; system and
third-party includes (<...>) are not Tessera's.

Usage: check_layers.py ROOT        checks ROOT's folders, prints each violation, exit 1 if any
       check_layers.py --self-test builds a small tree with known violations and checks that
                                   exactly those are found (run by CTest before the real check)
"""
import os
import re
import sys
import tempfile

LAYERS = ["core", "lb", "codecs", "renderer", "protocol", "update", "actors", "net", "app"]
RANK = {name: i for i, name in enumerate(LAYERS)}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
SOURCES = (".h", ".hpp", ".cpp", ".cc", ".inc")


def violations(root):
    found = []
    for layer in LAYERS:
        top = os.path.join(root, layer)
        for dirpath, _, files in os.walk(top):
            for f in sorted(files):
                if not f.endswith(SOURCES):
                    continue
                path = os.path.join(dirpath, f)
                rel = os.path.relpath(path, root)
                with open(path, encoding="utf-8", errors="replace") as fh:
                    text = fh.read()
                for m in INCLUDE.finditer(text):
                    target = m.group(1)
                    head = target.split("/", 1)[0]
                    line = text.count("\n", 0, m.start()) + 1
                    if head == "tests":
                        found.append(f"{rel}:{line}: includes {target}: production code must not include tests/")
                    elif head in RANK and RANK[head] > RANK[layer]:
                        found.append(f"{rel}:{line}: includes {target}: layer '{layer}' must not include "
                                     f"the higher layer '{head}'")
    return found


def self_test():
    with tempfile.TemporaryDirectory() as root:
        files = {
            "core/a.h": '#include "core/b.h"\n',                  # same layer: fine
            "core/bad.h": '#include "renderer/raytracer.h"\n',   # upward: found
            "lb/x.cpp": '#include "core/a.h"\n#include <vector>\n',  # downward: fine
            "protocol/p.cpp": '  #  include "actors/node.h"\n',  # upward, odd spacing: found
            "actors/t.h": '#include "tests/helper.h"\n',        # tests/: found
            "net/s.h": '#include "actors/node.h"\n',              # downward: fine
            "app/m.cpp": '#include "net/s.h"\n',                  # downward: fine
            "core/notes.md": '#include "app/m.cpp"\n',            # not a source: ignored
        }
        for rel, text in files.items():
            os.makedirs(os.path.join(root, os.path.dirname(rel)), exist_ok=True)
            with open(os.path.join(root, rel), "w") as fh:
                fh.write(text)
        got = sorted(v.split(":")[0] for v in violations(root))
        want = sorted(["core/bad.h", "protocol/p.cpp", "actors/t.h"])
        if got != want:
            print(f"check_layers self-test: found {got}, expected {want}")
            return 1
    print("check_layers self-test: ok")
    return 0


def main(argv):
    if len(argv) == 2 and argv[1] == "--self-test":
        return self_test()
    if len(argv) != 2:
        print(__doc__)
        return 2
    missing = [l for l in LAYERS if not os.path.isdir(os.path.join(argv[1], l))]
    if missing:
        print(f"check_layers: no folder for layer(s) {', '.join(missing)} under {argv[1]}")
        return 1
    found = violations(argv[1])
    for v in found:
        print(v)
    print(f"check_layers: {len(found)} violation(s) in {', '.join(LAYERS)}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
