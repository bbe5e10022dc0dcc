#!/usr/bin/env python3
"""Checks that ARCHITECTURE.md's list of libraries is true.

The list (the first fenced block under "## Libraries") names each library of lib/ once, one
layer per line, in order; a line may hold several libraries separated by ',' or '|'. A library
may use only libraries on lines above its own, or earlier on its line. The uses are read from
each lib/<name>/CMakeLists.txt (`th_library(th_<name> DEPS ...)`).

Prints one summary line and exits 0 when every use goes up the list and every library is listed
once; otherwise lists each problem on stderr and exits 1.

Usage: scripts/check-layers.py [REPOSITORY_ROOT]   (default: this script's parent folder)
"""
import pathlib
import re
import sys


def layer_list(architecture: pathlib.Path):
    text = architecture.read_text()
    section = text.split("## Libraries", 1)
    if len(section) != 2:
        sys.exit(f"check-layers: error: {architecture} has no '## Libraries' section")
    block = re.search(r"```\n(.*?)```", section[1], re.S)
    if not block:
        sys.exit(f"check-layers: error: {architecture}: no fenced list under '## Libraries'")
    order = {}
    position = 0
    for line in block.group(1).splitlines():
        if not line or line[0].isspace():
            continue  # a continuation of the description above
        names = re.split(r"\s{2,}", line.strip(), maxsplit=1)[0]
        for name in re.split(r"\s*[,|]\s*", names):
            if name in order:
                sys.exit(f"check-layers: error: {architecture}: '{name}' is listed twice")
            order[name] = position
            position += 1
    return order


def uses(lib: pathlib.Path):
    out = {}
    for cmake in sorted(lib.glob("*/CMakeLists.txt")):
        text = cmake.read_text()
        match = re.search(r"th_library\(th_(\w+)\s+DEPS([^)]*)\)", text) or re.search(
            r"target_link_libraries\(th_(\w+)\s+PUBLIC([^)]*)\)", text)
        if not match:
            continue
        out[match.group(1)] = [d[3:] for d in match.group(2).split() if d.startswith("th_") and d != "th_pch"]
    return out


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parent.parent)
    order = layer_list(root / "ARCHITECTURE.md")
    libraries = uses(root / "lib")
    problems = []
    for name in sorted(set(libraries) - set(order)):
        problems.append(f"lib/{name}: not in ARCHITECTURE.md's list of libraries")
    for name in sorted(set(order) - set(libraries)):
        problems.append(f"ARCHITECTURE.md lists '{name}', which is not a library of lib/")
    for name, deps in sorted(libraries.items()):
        for dep in deps:
            if name in order and dep in order and order[dep] >= order[name]:
                problems.append(f"lib/{name}/CMakeLists.txt: th_{name} uses th_{dep}, which ARCHITECTURE.md lists below it")
    if problems:
        for p in problems:
            print(f"check-layers: {p}", file=sys.stderr)
        sys.exit(1)
    edges = sum(len(d) for d in libraries.values())
    print(f"check-layers: {len(libraries)} libraries, {edges} uses, each up ARCHITECTURE.md's list")


if __name__ == "__main__":
    main()
