"""The package's import graph: no cycles, and no layer imports one above it.

Layers, lowest first (a module may import its own layer and the layers below):

core (error kinds, estimate and report, rigid body, array, log, motion, rotations, noise policy, option declarations, progress, forked workers, bundled data)
← io (formats, readers, outputs) and simulate (synthetic logs), side by side
← estimators (the papers' per-sample methods, the per-sample bound, calibration and its errors read off a fit)
← smoother (factors, model, solvers, tuning, fixed lag)
← methods (the registry of every method by name)
← evaluation (metrics, comparison study, plots)
← pipeline (one log, many logs or a live stream, read to written: gfimu.pipeline, gfimu.batch, gfimu.live)
← cli
← the package's own names (``gfimu/__init__.py``: ``from gfimu import estimate_log``, loaded on first use).

Every ``import`` statement counts, at module level or inside a function, so an import
placed in a function to hide a cycle still fails here; so do the modules named in a module's
``_LAZY`` table (names loaded on first use). The graph is read from the sources
with :mod:`ast`; nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "gfimu"

LAYERS: list[tuple[str, int, tuple[str, ...]]] = [
    ("core", 0, ("gfimu.errors", "gfimu.estimate", "gfimu.rigid_body", "gfimu.rotations", "gfimu.motion", "gfimu.array", "gfimu.log",
                 "gfimu.noise", "gfimu.option", "gfimu.progress", "gfimu.parallel", "gfimu.readings", "gfimu.screen_kernels",
                 "gfimu.datasets*")),
    ("io", 1, ("gfimu.io*",)),
    ("simulate", 1, ("gfimu.simulate*",)),
    ("estimators", 2, ("gfimu.estimators*", "gfimu.crb", "gfimu.calibration", "gfimu.array_misfit")),
    ("smoother", 3, ("gfimu.factors*", "gfimu.smoother*")),
    ("methods", 4, ("gfimu.methods",)),
    ("evaluation", 5, ("gfimu.evaluation", "gfimu.compare", "gfimu.plots", "gfimu.diagnose")),
    ("pipeline", 6, ("gfimu.pipeline", "gfimu.batch", "gfimu.live")),
    ("cli", 7, ("gfimu.cli*", "gfimu.__main__")),
    ("surface", 8, ("gfimu",)),
]

def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def package_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """gfimu modules that ``name`` imports anywhere in its source (``from X import m`` counts as
    importing X.m when that is a module), plus literal ``importlib.import_module("gfimu...")`` targets
    and the modules (relative to the package) of a ``_LAZY = {name: module}`` table."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "gfimu")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "gfimu":
                continue
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules]
            out.update(subs)
            if len(subs) < len(node.names):
                out.add(target)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and node.args[0].value.startswith("gfimu")):
            out.add(node.args[0].value)
        elif (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets)
              and isinstance(node.value, ast.Dict)):
            out.update(f"{package}.{v.value}" for v in node.value.values
                       if isinstance(v, ast.Constant) and isinstance(v.value, str))
    out.discard(name)
    return {m for m in out if m in modules}


def layer_of(name: str) -> tuple[str, int]:
    for layer, rank, patterns in LAYERS:
        for p in patterns:
            if name == p or (p.endswith("*") and (name == p[:-1] or name.startswith(p[:-1] + "."))):
                return layer, rank
    raise AssertionError(f"module {name} belongs to no layer: add it to LAYERS in {Path(__file__).name}")


def graph() -> dict[str, set[str]]:
    modules = package_modules()
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph (as a closed list of nodes), or None."""
    colour: dict[str, int] = {}
    stack: list[str] = []

    def visit(u: str) -> list[str] | None:
        colour[u] = 1
        stack.append(u)
        for v in sorted(edges.get(u, ())):
            if colour.get(v) == 1:
                return stack[stack.index(v):] + [v]
            if v not in colour:
                found = visit(v)
                if found:
                    return found
        stack.pop()
        colour[u] = 2
        return None

    for u in sorted(edges):
        if u not in colour:
            found = visit(u)
            if found:
                return found
    return None


def test_every_module_has_a_layer():
    for name in package_modules():
        layer_of(name)


def test_no_import_cycle():
    cycle = find_cycle(graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def folder_of(name: str) -> str:
    """The top folder a module lives in (``gfimu.smoother.model.problem`` -> ``gfimu.smoother``); a module at the
    package's top is its own unit (``gfimu.methods``)."""
    parts = name.split(".")
    return ".".join(parts[:2])


def folder_graph(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for src, targets in edges.items():
        for dst in targets:
            if folder_of(src) != folder_of(dst):
                out.setdefault(folder_of(src), set()).add(folder_of(dst))
    return out


def test_no_import_cycle_between_folders():
    cycle = find_cycle(folder_graph(graph()))
    assert cycle is None, "folders importing each other: " + " -> ".join(cycle)


def top_package(name: str, modules: dict[str, Path]) -> str:
    """``gfimu.smoother`` for ``gfimu.smoother.model.problem``; ``gfimu`` for a module at the package's top."""
    path = modules.get(name)
    if path is not None and path.parent == PACKAGE and path.name != "__init__.py":
        return "gfimu"
    return ".".join(name.split(".")[:2])


def private_imports() -> list[str]:
    """``from X import _name`` (or of a module ``X._mod``) where X is in another top package than the importer."""
    modules = package_modules()
    bad = []
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                names = [f"{target}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for full in names:
                parts = full.split(".")
                if parts[0] != "gfimu" or not any(p.startswith("_") and not p.startswith("__") for p in parts[1:]):
                    continue
                owner = full if full in modules else full.rpartition(".")[0]
                if top_package(owner, modules) != top_package(name, modules):
                    bad.append(f"{name} imports {full}")
    return bad


def test_no_private_name_crosses_packages():
    bad = private_imports()
    assert not bad, "private names used from another package:\n" + "\n".join(bad)


def test_no_upward_or_sideways_import():
    bad = []
    for src, targets in graph().items():
        layer, rank = layer_of(src)
        for dst in sorted(targets):
            dlayer, drank = layer_of(dst)
            if drank > rank or (drank == rank and dlayer != layer):
                bad.append(f"{src} ({layer}) imports {dst} ({dlayer})")
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_the_checks_catch_a_cycle_and_an_upward_import():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert layer_of("gfimu.smoother.batch.engine")[1] > layer_of("gfimu.estimators.ml")[1]
    assert layer_of("gfimu.io.readers.mimu4444") == ("io", 1)
    assert "gfimu.pipeline" in graph()["gfimu"]  # the package's lazy names are read as imports
    # the registry names once resolved from gfimu.methods by gfimu.estimators: one arrow up, one cycle
    shim = {"gfimu.estimators": {"gfimu.methods"}, "gfimu.methods": {"gfimu.estimators.ml", "gfimu.smoother.batch.engine"},
            "gfimu.smoother.batch.engine": {"gfimu.estimators.ml"}, "gfimu.estimators.ml": set()}
    assert find_cycle(folder_graph(shim)) == ["gfimu.estimators", "gfimu.methods", "gfimu.estimators"]
    assert layer_of("gfimu.methods")[1] > layer_of("gfimu.estimators")[1]


def test_io_readers_sit_above_the_rest_of_io():
    """The readers (gfimu/io/readers) use io's tables, units and errors; nothing else in io imports a reader
    (a live byte stream decodes MIMU4444 packets with gfimu.io.mimu4444_packets), so the two do not loop."""
    edges = graph()
    up = sorted(f"{src} -> {dst}" for src, targets in edges.items() for dst in targets
                if src.startswith("gfimu.io") and not src.startswith("gfimu.io.readers")
                and dst.startswith("gfimu.io.readers"))
    assert up == []
    assert "gfimu.io.mimu4444_packets" in edges["gfimu.io.readers.mimu4444"]
    assert "gfimu.io.mimu4444_packets" in edges["gfimu.io.sources"]
