#!/usr/bin/env python3
"""Fail on what Cargo cannot see about the layers: a cycle between the files of a crate,
and a library's use of the test-data generator.

The layers are crates (README, "Architecture"), and Cargo refuses a cycle between crates.
Inside a crate it allows any: this script reads every `crate::` and `super::` path in
non-test code, builds the graph of the crate's modules one level below its home (the
files of `enhance/` in gsi-enhance, the top-level modules of a crate that has several),
and exits 1 with the cycle if there is one. It also refuses any use of the test-data
generator (`gsi_synth`, the facade's `synth`) outside tests, the facade's `synth` module
that re-exports it, and the tools.

Test code (items under `#[cfg(test)]`, files declared `#[cfg(test)] mod NAME;`) may use
anything; comments are skipped (doc links are not imports).

Usage: tools/check-layers.py   (prints each crate's modules, lowest first)
"""
import os
import re
import sys

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
PATH = re.compile(r"(?<![\w$])(\$?crate|super)::(\{[^}]*\}|[A-Za-z_][A-Za-z0-9_]*(?:::[A-Za-z_][A-Za-z0-9_]*)*)")


def crates():
    """`(name, src folder)` of every library crate of the workspace."""
    out = [("gsi", os.path.join(REPO, "src"))]
    base = os.path.join(REPO, "crates")
    for name in sorted(os.listdir(base)):
        src = os.path.join(base, name, "src")
        if os.path.isdir(src):
            out.append(("gsi-" + name, src))
    return out


def code_lines(text):
    """The file's lines outside comments and outside `#[cfg(test)]` items."""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        stripped = lines[i].strip()
        if stripped.startswith("#[cfg(test)]") or stripped.startswith("#[cfg(all(test"):
            i += 1
            depth, opened = 0, False
            while i < len(lines):
                s = lines[i].split("//")[0]
                depth += s.count("{") - s.count("}")
                opened = opened or "{" in s
                i += 1
                if (opened and depth <= 0) or (not opened and s.rstrip().endswith(";")):
                    break
            continue
        if not stripped.startswith("//"):
            yield lines[i].split("//")[0]
        i += 1


def test_files(root):
    """Files that are whole test modules (`#[cfg(test)] mod NAME;`)."""
    skip = set()
    decl = re.compile(r"#\[cfg\(test\)\]\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+([a-z_0-9]+)\s*;")
    for dirpath, _, files in os.walk(root):
        for name in files:
            if name.endswith(".rs"):
                with open(os.path.join(dirpath, name), encoding="utf-8") as f:
                    for m in decl.findall(f.read()):
                        skip.add(os.path.join(dirpath, m + ".rs"))
                        skip.add(os.path.join(dirpath, m, "mod.rs"))
    return skip


def module_path(rel):
    """`enhance/tone.rs` -> ["enhance", "tone"]; `enhance/mod.rs` -> ["enhance"]."""
    parts = rel[:-3].split(os.sep)
    if parts[-1] in ("mod", "lib"):
        parts = parts[:-1]
    return parts


def homes(root):
    """The crate's top-level modules (`mod`/`pub mod` in lib.rs)."""
    with open(os.path.join(root, "lib.rs"), encoding="utf-8") as f:
        return re.findall(r"^\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([a-z]+\))?\s+)?mod\s+(\w+)", f.read(), re.M)


def graph(root):
    """Edges between sibling modules, by the folder that holds them (`()` for the crate's
    top-level modules, `("enhance",)` for the files of `enhance/`, and so on down): a
    path from a file under `a` to a module under its sibling `b` is an edge `a -> b` of
    their folder. Also the files that use the test data."""
    skip = test_files(root)
    edges, synth = {}, []
    for dirpath, _, files in os.walk(root):
        for name in files:
            full = os.path.join(dirpath, name)
            if not name.endswith(".rs") or full in skip:
                continue
            rel = os.path.relpath(full, root)
            here = module_path(rel)
            for depth in range(len(here)):
                edges.setdefault(tuple(here[:depth]), {}).setdefault(here[depth], {})
            with open(full, encoding="utf-8") as f:
                text = f.read()
            for line in code_lines(text):
                if "gsi_synth" in line or re.search(r"crate::synth\b", line):
                    synth.append(rel)
                for kind, path in PATH.findall(line):
                    groups = (re.findall(r"(?:^|[{,])\s*([\w:]+)", path[1:-1])
                              if path.startswith("{") else [path])
                    for g in groups:
                        segs = [x for x in g.split("::") if x]
                        # `super::x` in a/b.rs and in a/b/mod.rs both name a::x.
                        target = (here[:-1] + segs) if kind == "super" else segs
                        n = 0
                        while n < min(len(here), len(target)) and here[n] == target[n]:
                            n += 1
                        if n < len(here) and n < len(target):
                            folder, a, b = tuple(here[:n]), here[n], target[n]
                            if b in names_of(root, list(folder)):
                                edges.setdefault(folder, {}).setdefault(a, {}).setdefault(
                                    b, set()).add(rel)
    return edges, sorted(set(synth))


_NAMES = {}


def names_of(root, prefix):
    """The module names that exist at `prefix` (files or folders)."""
    key = (root, tuple(prefix))
    if key not in _NAMES:
        folder = os.path.join(root, *prefix)
        names = set()
        if os.path.isdir(folder):
            for n in os.listdir(folder):
                if n.endswith(".rs") and n not in ("mod.rs", "lib.rs"):
                    names.add(n[:-3])
                elif os.path.isdir(os.path.join(folder, n)):
                    names.add(n)
        _NAMES[key] = names
    return _NAMES[key]


def find_cycle(edges):
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(edges.get(n, {})):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(edges):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


def layers(edges):
    """Modules grouped by height: a module's layer is one above its highest import."""
    height = {}

    def h(n):
        if n not in height:
            height[n] = 1 + max((h(m) for m in edges.get(n, {}) if m in edges), default=-1)
        return height[n]

    for n in edges:
        h(n)
    out = {}
    for n, k in height.items():
        out.setdefault(k, []).append(n)
    return [sorted(out[k]) for k in sorted(out)]


def main():
    failed = False
    for name, root in crates():
        by_folder, synth = graph(root)
        for folder, edges in sorted(by_folder.items()):
            cycle = find_cycle(edges)
            if cycle:
                failed = True
                where = "::".join(folder) or "the crate root"
                print(f"{name}: import cycle between the modules of {where}: "
                      + " -> ".join(cycle))
                for a, b in zip(cycle, cycle[1:]):
                    print(f"  {a} -> {b}: {', '.join(sorted(edges[a][b]))}")
        allowed = {"synth.rs"} if name == "gsi" else set()
        users = [f for f in synth if f not in allowed]
        if users:
            failed = True
            print(f"{name}: library code uses the test data (gsi_synth): {', '.join(users)}")
        top = by_folder.get((), {})
        print(f"{name}: " + " < ".join(", ".join(l) for l in layers(top)))
    if failed:
        return 1
    print("no import cycle inside any crate; no library use of the test data")
    return 0


if __name__ == "__main__":
    sys.exit(main())
