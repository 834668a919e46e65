#!/usr/bin/env python3
"""Import cycles between gpustar's source files, and imports that go up the layers of
docs/ARCHITECTURE.md. Reads the `crate::` and `super::` paths of each file under src/ (test
modules left out) and prints the cycles (strongly connected components) and the upward imports;
exits 1 when there is either.  python3 scripts/import_cycles.py [SRC_DIR]"""
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
LAYERS = [
    ["error", "files", "camera", "record", "simd"],
    ["catalog"],
    ["cpu"],
    ["sky"],
    ["io"],
    ["solve"],
    ["gpu"],
    ["simulate"],
    ["streaks"],
    ["products"],
    ["pipeline"],
    ["sequence"],
    ["batch"],
    ["calibrate"],
    ["report"],
    ["cli"],
    ["lib", "main", "fuzz"],
]


def modules():
    root = sys.argv[1] if len(sys.argv) > 1 else ROOT
    out = {}
    for base, _, files in os.walk(root):
        for f in files:
            if f.endswith(".rs"):
                path = os.path.join(base, f)
                name = os.path.relpath(path, root)[:-3].replace("/mod", "").replace("/", "::")
                out[name] = open(path).read().split("#[cfg(test)]")[0]
    return out


def graph(files):
    g = {}
    for m, src in files.items():
        deps = set()
        for path in re.findall(r"crate::([a-z_]+(?:::[a-z_]+)*)", src):
            parts = path.split("::")
            for k in range(len(parts), 0, -1):
                if "::".join(parts[:k]) in files:
                    deps.add("::".join(parts[:k]))
                    break
        parent = m.rsplit("::", 1)[0] if "::" in m else ""
        for name in re.findall(r"super::([a-z_]+)", src):
            sibling = f"{parent}::{name}" if parent else name
            if sibling in files:
                deps.add(sibling)
        deps.discard(m)
        g[m] = deps
    return g


def cycles(g):
    sys.setrecursionlimit(10000)
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            c = []
            while True:
                w = stack.pop()
                on.discard(w)
                c.append(w)
                if w == v:
                    break
            if len(c) > 1:
                found.append(sorted(c))

    for v in g:
        if v not in index:
            visit(v)
    return found


def main():
    g = graph(modules())
    layer = {m: k for k, ms in enumerate(LAYERS) for m in ms}
    top = lambda m: m.split("::")[0]
    upward = sorted(
        f"{a} -> {b}"
        for a in g
        for b in g[a]
        if top(a) != top(b) and layer.get(top(b), -1) > layer.get(top(a), 99)
    )
    unplaced = sorted({top(m) for m in g} - set(layer))
    found = cycles(g)
    print(f"{len(g)} files; cycles: {found or 'none'}; upward imports: {upward or 'none'}")
    if unplaced:
        print(f"modules in no layer of docs/ARCHITECTURE.md: {unplaced}")
    return 1 if found or upward or unplaced else 0


if __name__ == "__main__":
    sys.exit(main())
