"""The package's layers: imports point one way, there are no cycles, and no module is too long.

Every import inside ``snapmem/`` counts, at module level or inside a function (a lazy import
hides a cycle, it does not remove it). Layers, bottom to top (docs/ARCHITECTURE.md):

0. errors, threads, io (no physics)
1. kernels: compiled functions on arrays, the band linear algebra
2. model: meridian, laws, terms, contact, the scene
3. solvers: statuses, Newton
4. continuation, dynamics
5. applications: statics, scene catalog and robots, sweeps, reference solutions, viz, CLI, studies
"""

from __future__ import annotations

import ast
from pathlib import Path


PACKAGE = Path(__file__).resolve().parents[1] / "snapmem"
LAYERS = {"errors": 0, "threads": 0, "io": 0, "_moved": 0, "_version": 0, "_lazy": 0, "_numba_cache": 0, "_scipy_blas": 0,
          "kernels": 1, "model": 2, "solvers": 3, "continuation": 4, "dynamics": 4}
MAX_LINES = 500


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer(module: str) -> int:
    top = module.split(".")[1] if "." in module else ""
    return LAYERS.get(top, 5)


def imports() -> dict[str, set[str]]:
    """snapmem module -> the snapmem modules it imports (resolved to modules, not names)."""
    files = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = name.split(".") if is_package else name.split(".")[:-1]
                    anchor = anchor[:len(anchor) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                found = [f"{base}.{a.name}" for a in node.names] + [base]
            else:
                continue
            for target in found:
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != name and target.startswith("snapmem"):
                    targets.add(target)
        graph[name] = targets
    return graph


def cycles(graph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert cycles(imports()) == []


def test_imports_point_down_the_layers():
    upward = [(a, b) for a, targets in imports().items() if a != "snapmem"
              for b in targets if layer(b) > layer(a)]
    assert upward == []


def test_package_code_uses_the_new_module_paths():
    from snapmem._moved import MOVED
    old = {f"snapmem.{name}" for name in MOVED}
    stale = [(a, b) for a, targets in imports().items() for b in targets if b in old]
    assert stale == []


def test_no_module_over_500_lines():
    long = {module_name(p): n for p in PACKAGE.rglob("*.py") if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_the_checker_sees_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_file_carries_a_merge_conflict_marker():
    """A conflict left in a doc or module after a merge (it happened once, in docs/MODEL.md)."""
    root = Path(__file__).resolve().parents[1]
    markers = ("<<<<<<< ", ">>>>>>> ")
    bad = []
    for path in [*root.glob("snapmem/**/*.py"), *root.glob("docs/**/*.md"), *root.glob("tests/*.py"),
                 *root.glob("studies/*.py"), root / "README.md", root / "pyproject.toml"]:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if line.startswith(markers):
                bad.append(f"{path.relative_to(root)}:{n}")
    assert not bad, bad
