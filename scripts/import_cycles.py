#!/usr/bin/env python3
"""Import cycles between gpustar's source files, and imports that go up the layers of
docs/ARCHITECTURE.md.

Every path a file names (`use` declarations, grouped `{…}` and nested, and paths written
inline) that starts with `crate::`, `super::`, `self::` or `gpustar::` is resolved to the file
that defines the item: through modules, through `pub use` re-exports (named and glob) and
through `mod.rs` files. So `use super::{Settings, Solver}` in `solve/bands.rs` is an edge to
the files that define `Settings` and `Solver`, not to `solve/mod.rs`, and `crate::Result` is
an edge to `error.rs`, not to `lib.rs`. Intra-doc links (`[x](super::y::x)`, `` [`crate::z`] ``)
count as uses. Test modules (`#[cfg(test)]` items), other comments and string literals are left
out.

Prints the cycles (strongly connected components of two files or more) and the upward imports;
exits 1 when there is either.

    python3 scripts/import_cycles.py [SRC_DIR] [-v]

-v also prints each file's edges."""
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
LAYERS = [
    ["error", "files", "camera", "record", "simd", "choice"],
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
    ["config"],
    ["batch"],
    ["calibrate"],
    ["report"],
    ["cli"],
    ["lib", "main", "fuzz", "front"],
]
# The binary's own modules: `crate::` in them starts at main.rs.
BIN_ROOT, BIN_MODULES = "main", ("main", "cli")
IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
# An intra-doc link's path: [text](path) or [`path`].
DOC_LINK = r"(?:\]\(|\[`)((?:crate|super|self)(?:::" + IDENT + r")+)(?:\)|`\])"


def strip_comments_and_strings(src):
    """The source with comments and string/char literals blanked (lengths kept)."""
    out, i, n = [], 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', src[i:]) and (i == 0 or not re.match(r"\w", src[i - 1])):
            hashes = re.match(r'r(#*)"', src[i:]).group(1)
            end = src.find('"' + hashes, i + 2 + len(hashes))
            j = n if end < 0 else end + 1 + len(hashes)
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            out.append(re.sub(r"[^\n]", " ", src[i : j + 1]))
            i = j + 1
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", src[i:]):
            m = re.match(r"'(\\.|[^\\'])'", src[i:])
            out.append(" " * len(m.group(0)))
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    return "".join(out)


def skip_item(src, i):
    """The index just past the item starting at i: its `;` or its matching `}`."""
    depth = 0
    while i < len(src):
        c = src[i]
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
            if depth == 0:
                return i + 1
        elif c == ";" and depth == 0:
            return i + 1
        i += 1
    return i


def without_tests(src):
    """The source less every `#[cfg(test)]` (or `#[cfg(all(test, …))]`) item, blanked."""
    while True:
        m = re.search(r"#\[cfg\((?:test|all\(test\b[^\]]*)\)\]", src)
        if not m:
            return src
        j = m.end()
        while True:  # further attributes of the same item
            a = re.match(r"\s*#\[[^\]]*\]", src[j:])
            if not a:
                break
            j += a.end()
        end = skip_item(src, j)
        src = src[: m.start()] + re.sub(r"[^\n]", " ", src[m.start() : end]) + src[end:]


def modules(root):
    out = {}
    for base, _, files in os.walk(root):
        for f in files:
            if f.endswith(".rs"):
                path = os.path.join(base, f)
                name = os.path.relpath(path, root)[:-3].replace("/mod", "").replace(os.sep, "::")
                if name == "mod":
                    continue
                raw = open(path).read()
                code = strip_comments_and_strings(raw)
                kept = without_tests(code)
                # Intra-doc links name items too (rustdoc resolves them): a link outside the
                # test items counts as a use of its target.
                links = [
                    m.group(1)
                    for r, c, k in zip(raw.split("\n"), code.split("\n"), kept.split("\n"))
                    if c == k
                    for m in re.finditer(DOC_LINK, r)
                ]
                out[name] = kept + "\n" + "\n".join(links)
    return out


def definitions(src):
    """Names of the items a file defines at any depth (fn, struct, enum, …)."""
    kinds = r"fn|struct|enum|trait|type|const|static|union|mod"
    pat = r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:(?:async|unsafe|extern\s+\"C\"|const)\s+)*(?:" + kinds + r")\s+(" + IDENT + r")"
    names = set(re.findall(pat, src, re.M))
    names |= set(re.findall(r"macro_rules!\s*(" + IDENT + ")", src))
    return names


class Resolver:
    def __init__(self, files):
        self.files = files
        self.defs = {m: definitions(src) for m, src in files.items()}
        # name → path of each named `pub use`; glob re-export targets
        self.reexports, self.globs = {}, {}
        for m, src in files.items():
            named, globs = {}, []
            for m2 in re.finditer(r"\bpub(?:\([^)]*\))?\s+use\s+([^;]*);", src):
                raw = m2.group(1)
                for path in expand_use_with_alias(raw):
                    segs, alias = path
                    if segs and segs[-1] == "*":
                        globs.append(segs[:-1])
                    elif segs:
                        named[alias or segs[-1]] = segs
            self.reexports[m], self.globs[m] = named, globs

    def root_of(self, m):
        return BIN_ROOT if m.split("::")[0] in BIN_MODULES else "lib"

    def child(self, module, name):
        if module in ("lib", "main"):
            return name if name in self.files else None
        c = f"{module}::{name}"
        return c if c in self.files else None

    def parent(self, module):
        if module in ("lib", "main"):
            return module
        return module.rsplit("::", 1)[0] if "::" in module else self.root_of(module)

    def start(self, m, segs):
        """The module a path starts in and the segments after its head."""
        head = segs[0]
        if head == "crate":
            return self.root_of(m), segs[1:]
        if head == "gpustar":
            return "lib", segs[1:]
        if head in ("self", "super"):
            cur, k = m, 0
            while k < len(segs) and segs[k] in ("self", "super"):
                cur = self.parent(cur) if segs[k] == "super" else cur
                k += 1
            return cur, segs[k:]
        return None, None

    def resolve_in(self, module, segs, seen):
        """The file that defines segs[0] (then the rest) starting in module."""
        for k, name in enumerate(segs):
            if name == "*":
                return module
            sub = self.child(module, name)
            if sub:
                module = sub
                continue
            if name in self.defs.get(module, ()):
                return module
            key = (module, name)
            if key in seen:
                return module
            seen = seen | {key}
            target = self.reexports.get(module, {}).get(name)
            if target:
                start, rest = self.start(module, target)
                if start is None:  # `pub use child::x` written relative to the module
                    start, rest = module, target
                return self.resolve_in(start, rest + segs[k + 1 :], seen) or module
            for g in self.globs.get(module, ()):
                start, rest = self.start(module, g)
                if start is None:
                    start, rest = module, g
                base = self.resolve_in(start, rest, seen) if rest else start
                if base and base in self.files and (
                    name in self.defs.get(base, ()) or self.child(base, name) or name in self.reexports.get(base, {})
                ):
                    return self.resolve_in(base, segs[k:], seen)
            return module
        return module

    def resolve(self, m, segs):
        start, rest = self.start(m, segs)
        if start is None:
            return None
        if not rest:
            return start
        return self.resolve_in(start, rest, frozenset())


def expand_use_with_alias(raw):
    """The paths of a `use` tree, `a::{b, c::{d, e as f}, self}`, each with its `as` alias:
    [([a, b], None), ([a, c, d], None), ([a, c, e], f), ([a], None)]."""
    leaves = []

    def parse(s, prefix):
        depth, start, parts = 0, 0, []
        for k, c in enumerate(s):
            if c == "{":
                depth += 1
            elif c == "}":
                depth -= 1
            elif c == "," and depth == 0:
                parts.append(s[start:k])
                start = k + 1
        parts.append(s[start:])
        for part in (p.strip() for p in parts):
            if not part:
                continue
            if "{" in part:
                head, inner = part.split("{", 1)
                parse(inner[: inner.rindex("}")], prefix + [x for x in re.split(r"\s*::\s*", head.strip()) if x])
            else:
                alias = None
                a = re.match(r"(.*?)\s+as\s+(" + IDENT + r")$", part, re.S)
                if a:
                    part, alias = a.group(1), a.group(2)
                segs = [x for x in re.split(r"\s*::\s*", part.strip()) if x]
                if segs and segs[-1] == "self":
                    segs = segs[:-1]
                leaves.append((prefix + segs, alias))

    parse(raw, [])
    return leaves


def graph(files):
    r = Resolver(files)
    g = {}
    for m, src in files.items():
        deps, spans = set(), []
        for u in re.finditer(r"(\bpub(?:\([^)]*\))?\s+)?\buse\s+([^;]*);", src):
            spans.append(u.span())
            for segs, _ in expand_use_with_alias(u.group(2)):
                if segs and r.child(m, segs[0]):  # a child module, named without `self::`
                    segs = ["self"] + segs
                if segs and segs[0] in ("crate", "super", "self", "gpustar"):
                    if segs[-1] == "*":
                        segs = segs[:-1]
                    deps.add(r.resolve(m, segs))
        rest = src
        for a, b in reversed(spans):
            rest = rest[:a] + " " * (b - a) + rest[b:]
        for p in re.finditer(r"\b(?:crate|super|self|gpustar)(?:\s*::\s*" + IDENT + ")+", rest):
            segs = re.split(r"\s*::\s*", p.group(0))
            deps.add(r.resolve(m, segs))
        # paths into a child module written without `self::`: `hints::run(…)`
        for p in re.finditer(r"(?<![\w:])(" + IDENT + r")(?:\s*::\s*" + IDENT + ")+", rest):
            segs = re.split(r"\s*::\s*", p.group(0))
            if r.child(m, segs[0]):
                deps.add(r.resolve(m, ["self"] + segs))
        deps.discard(None)
        deps.discard(m)
        g[m] = {d for d in deps if d in files}
    return g


def cycles(g):
    sys.setrecursionlimit(10000)
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
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

    for v in sorted(g):
        if v not in index:
            visit(v)
    return sorted(found)


def main():
    args = [a for a in sys.argv[1:] if a != "-v"]
    g = graph(modules(args[0] if args else ROOT))
    if "-v" in sys.argv:
        for m in sorted(g):
            print(f"{m}: {', '.join(sorted(g[m]))}")
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
    edges = sum(len(d) for d in g.values())
    print(f"{len(g)} files, {edges} edges; cycles: {len(found)}; upward imports: {len(upward)}")
    for c in found:
        print("cycle: " + " <-> ".join(c))
    for u in upward:
        print("upward: " + u)
    if unplaced:
        print(f"modules in no layer of docs/ARCHITECTURE.md: {unplaced}")
    return 1 if found or upward or unplaced else 0


if __name__ == "__main__":
    sys.exit(main())
