#!/usr/bin/env python3
"""Checks raycut's layering: no file includes a file of a higher layer, and no include cycle.

Layers, lowest first: core < cpu < cuda < optix < backends < sph < mpi. tools (raycut::tools:
generators, comparison, position files) stands aside: it may include core, and only sph, mpi
and the programs (apps, tests, bench, examples, python) may include it. Every quoted or angled
include of a file in the repository counts, .cu and .cuh included, whether or not a
preprocessor condition guards it.

    scripts/check_layers.py [REPOSITORY_ROOT]

Prints each violation and cycle and exits 1, or prints a summary and exits 0.
"""

import pathlib
import re
import sys

ORDER = ["core", "cpu", "cuda", "optix", "backends", "sph", "mpi"]
# What each layer may include besides itself and the layers below it.
EXTRA = {"sph": {"tools"}, "mpi": {"tools"}, "tools": {"core"}}

# Where each layer's files live (the first matching prefix wins).
PLACES = [
    ("include/raycut/tools/", "tools"),
    ("include/raycut/detail/cuda/", "cuda"),
    ("include/raycut/cuda/", "cuda"),
    ("include/raycut/mpi/", "mpi"),
    ("include/raycut/sph/", "sph"),
    ("include/raycut/", "core"),
    ("src/core/", "core"),
    ("src/tools/", "tools"),
    ("src/cpu/", "cpu"),
    ("src/cuda/", "cuda"),
    ("src/geometry/", "optix"),  # the ray-tracing methods' geometry
    ("src/optix/", "optix"),
    ("src/backends/", "backends"),
    ("src/sph/", "sph"),
    ("src/mpi/", "mpi"),
]
SOURCES = (".hpp", ".cpp", ".h", ".cu", ".cuh")
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.MULTILINE)


def layer_of(path):
    for prefix, layer in PLACES:
        if path.startswith(prefix):
            return layer
    return None


def allowed(layer):
    if layer == "tools":
        return {"tools"} | EXTRA["tools"]
    below = set(ORDER[: ORDER.index(layer) + 1])
    return below | EXTRA.get(layer, set())


def resolve(root, source, name):
    """The repository path an include names, or None (a system or third-party header)."""
    for base in (source.parent, root / "src", root / "include"):
        candidate = (base / name).resolve()
        if candidate.is_file() and root in candidate.parents:
            return candidate.relative_to(root).as_posix()
    return None


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
    files = sorted(
        p
        for top in ("src", "include")
        for p in (root / top).rglob("*")
        if p.is_file() and p.suffix in SOURCES
    )
    graph, problems = {}, []
    for path in files:
        rel = path.relative_to(root).as_posix()
        layer = layer_of(rel)
        if layer is None:
            problems.append(f"{rel}: in no layer (add its folder to scripts/check_layers.py)")
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        edges = graph.setdefault(rel, [])
        for match in INCLUDE.finditer(text):
            target = resolve(root, path, match.group(1))
            if target is None or target == rel:
                continue
            edges.append(target)
            target_layer = layer_of(target)
            if target_layer is not None and target_layer not in allowed(layer):
                line = text.count("\n", 0, match.start()) + 1
                problems.append(
                    f"{rel}:{line}: {layer} includes {target} ({target_layer}), a layer it may "
                    f"not use (it may use: {', '.join(sorted(allowed(layer)))})"
                )

    # Include cycles, by depth-first search.
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in graph.get(node, []):
            if state.get(nxt) == "open":
                cycle = stack[stack.index(nxt):] + [nxt]
                problems.append("include cycle: " + " -> ".join(cycle))
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = "done"

    sys.setrecursionlimit(10000)
    for node in graph:
        if node not in state:
            visit(node)

    for problem in problems:
        print(problem)
    if problems:
        print(f"check_layers: {len(problems)} problem(s)")
        return 1
    edges = sum(len(v) for v in graph.values())
    print(f"check_layers: {len(graph)} files, {edges} includes, layers respected, no cycle")
    return 0


if __name__ == "__main__":
    sys.exit(main())
