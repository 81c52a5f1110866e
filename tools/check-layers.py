#!/usr/bin/env python3
"""Fail on any import cycle between the library's top-level modules.

The library is built in one-way layers (README, "Layers"): each top-level module of
`src/` may use the modules below it and never one above it. This script reads every
`crate::NAME` path in non-test code under `src/` (the `gsi` binary, which lives in
`cli/`, is an application on top and is not scanned), builds the graph of top-level
modules, and exits 1 with the cycle if there is one. It also refuses any library use of
`synth`, the test-data generator, which only tests, benches and tools may use.

Test code (items under `#[cfg(test)]`) may use anything, as tests sit above every
layer; those items are skipped. Comments are skipped too (doc links are not imports).

Usage: tools/check-layers.py   (prints the layers, lowest first)
"""
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src")
PATH = re.compile(r"\$?crate::(\{[^}]*\}|[A-Za-z_][A-Za-z0-9_]*)")


def reexports(root):
    """Names the crate root re-exports (`pub use module::{A, b}`), by the module they
    come from, so that `crate::Reader` counts as a use of `decode`."""
    with open(os.path.join(root, "lib.rs"), encoding="utf-8") as f:
        text = f.read()
    names = {}
    for module, group in re.findall(r"pub use (\w+)::\{([^}]*)\}", text):
        for name in re.findall(r"\w+", group):
            names[name] = module
    for module, name in re.findall(r"pub use (\w+)::(\w+);", text):
        names[name] = module
    return names


def targets(line, names):
    """The top-level modules a line's `crate::` paths name."""
    for path in PATH.findall(line):
        heads = re.findall(r"(?:^|[{,])\s*(\w+)", path) if path.startswith("{") else [path]
        for head in heads:
            yield names.get(head, head)


def module_of(rel):
    parts = rel[:-3].split(os.sep)
    if parts[-1] == "mod":
        parts = parts[:-1]
    return parts[0] if parts and parts[0] != "lib" else None


def code_lines(text):
    """The file's lines outside comments and outside `#[cfg(test)]` items."""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        stripped = lines[i].strip()
        if stripped.startswith("#[cfg(test)]"):
            # Skip the attribute and the item it gates: a one-line item, or the
            # lines up to its matching closing brace.
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


def graph(root=ROOT):
    edges = {}
    skip = test_files(root)
    names = reexports(root)
    for dirpath, _, files in os.walk(root):
        for name in files:
            if not name.endswith(".rs"):
                continue
            full = os.path.join(dirpath, name)
            if full in skip:
                continue
            rel = os.path.relpath(full, root)
            if rel.startswith("bin" + os.sep):
                continue
            src = module_of(rel)
            if src is None:
                continue
            with open(full, encoding="utf-8") as f:
                for line in code_lines(f.read()):
                    for dst in targets(line, names):
                        if dst != src and dst != "self":
                            edges.setdefault(src, {}).setdefault(dst, set()).add(rel)
            edges.setdefault(src, {})
    return edges


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


def self_test():
    """The checker must see a cycle through a `use` group, a root re-export and a macro
    path, and must not see one through test code or comments."""
    import tempfile

    files = {
        "lib.rs": "pub mod a;\npub mod b;\npub mod c;\npub use c::Thing;\n",
        "a.rs": "use crate::{b::x, model};\n",
        "b.rs": "// crate::c in a comment\n#[cfg(test)]\nmod tests {\n    use crate::c::y;\n}\n"
        "fn f() { $crate::c::z(); }\n",
        "c.rs": "use crate::Thing;\nfn g() -> crate::a::T {}\n",
    }
    with tempfile.TemporaryDirectory() as root:
        for name, text in files.items():
            with open(os.path.join(root, name), "w", encoding="utf-8") as f:
                f.write(text)
        cycle = find_cycle(graph(root))
        assert cycle and set(cycle) == {"a", "b", "c"}, cycle
        with open(os.path.join(root, "b.rs"), "w", encoding="utf-8") as f:
            f.write(files["b.rs"].replace("$crate::c::z()", "z()"))
        assert find_cycle(graph(root)) is None


def main():
    self_test()
    edges = graph()
    failed = False
    cycle = find_cycle(edges)
    if cycle:
        failed = True
        print("import cycle between modules: " + " -> ".join(cycle))
        for a, b in zip(cycle, cycle[1:]):
            print(f"  {a} -> {b}: {', '.join(sorted(edges[a][b]))}")
    users = sorted(m for m in edges if "synth" in edges[m])
    if users:
        failed = True
        for m in users:
            print(f"library module {m} uses synth (test data only): "
                  + ", ".join(sorted(edges[m]["synth"])))
    if failed:
        return 1
    if True:
        for k, mods in enumerate(layers(edges)):
            deps = sorted({d for m in mods for d in edges[m]})
            print(f"layer {k}: {', '.join(mods)}" + (f"  (uses {', '.join(deps)})" if deps else ""))
        print("no import cycle between the library's modules")
    return 0


if __name__ == "__main__":
    sys.exit(main())
