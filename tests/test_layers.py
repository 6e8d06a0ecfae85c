"""The package imports one way: no import circle, and no arrow from a lower layer to a higher one.

Every module under ``scipctl/`` is parsed with :mod:`ast` (nothing is imported); every ``import`` and
``from ... import`` counts, at module level and inside functions (``scipctl`` imports its heavy modules inside
functions, and a circle through a function-level import is still a circle), relative or absolute. An arrow goes
from the importing module to each ``scipctl`` module the statement names: ``from .x import y`` names ``x`` and,
if ``x`` is a package holding a module ``y``, ``x.y``; a package's ``__init__`` counts as the package itself.

Layers, lowest first; a module may import its own layer or lower ones, never a higher one:

0. base      ``scipctl`` (``__init__``), ``scipctl.errors``, ``scipctl.jsonutil`` -- exceptions and plain-data
             helpers everything may use (``errors.InputError`` / ``CommandFailed``).
1. core      ``scipctl.core`` -- pure numerics (cameras, transforms, stereo, tracking, handoff methods);
             never prints, never touches files.
2. model/io  ``scipctl.model`` (the in-memory downlink) and ``scipctl.io`` (readers, writers, workspaces,
             reports' HTML). ``model`` decodes PNG bytes with ``io.images`` on demand; ``io`` builds ``model``
             records; the two share a layer and must not form a circle.
3. sim, pipeline
             ``scipctl.sim`` (synthetic downlinks: renders through core's camera models into ``model`` records,
             encodes with ``io.images``) and ``scipctl.pipeline`` (designate, handoff, chain, predict, sequence,
             report data: core algorithms over a ``model.Downlink``). Beside each other: neither imports the other.
4. campaign  ``scipctl.campaign`` -- validation campaigns: orchestrates ``sim`` (rendering synthetic downlinks) and
             ``pipeline`` (handoff, chain, prediction) over many downlinks on a Dask cluster; never prints.
5. commands  ``scipctl.commands`` -- one module per command: parse arguments, call the pipeline (or the campaign),
             print (``commands.output``: JSON/stderr helpers and exit codes).
6. cli       ``scipctl.cli`` -- the typer application; imports ``commands`` inside each command.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = "scipctl"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE

# (module name or package prefix, layer); the longest matching entry wins
LAYERS = {
    "scipctl": 0,
    "scipctl.errors": 0,
    "scipctl.jsonutil": 0,
    "scipctl.core": 1,
    "scipctl.model": 2,
    "scipctl.io": 2,
    "scipctl.sim": 3,
    "scipctl.pipeline": 3,
    "scipctl.campaign": 4,
    "scipctl.commands": 5,
    "scipctl.cli": 6,
}
LAYER_NAMES = {0: "base", 1: "core", 2: "model/io", 3: "sim/pipeline", 4: "campaign", 5: "commands", 6: "cli"}
# siblings in one layer that must not import each other (either way)
APART = (("scipctl.sim", "scipctl.pipeline"),)


def module_files() -> dict[str, Path]:
    """``{"scipctl.io.images": Path(...), "scipctl.io": Path(.../io/__init__.py), ...}``."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_package(name: str, modules: dict) -> bool:
    return modules[name].name == "__init__.py"


def imports_of(name: str, modules: dict) -> dict[str, int]:
    """``{imported scipctl module: line}`` for every import statement in module ``name`` (any depth)."""
    tree = ast.parse(modules[name].read_text(encoding="utf-8"), filename=str(modules[name]))
    package = name if _is_package(name, modules) else name.rpartition(".")[0]
    found: dict[str, int] = {}

    def add(target: str, line: int):
        # the longest prefix of ``target`` that is a scipctl module
        parts = target.split(".")
        while parts and ".".join(parts) not in modules:
            parts.pop()
        if parts:
            found.setdefault(".".join(parts), line)

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == PACKAGE or alias.name.startswith(PACKAGE + "."):
                    add(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                if node.level > 1:
                    base = base[: -(node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
                if not (target == PACKAGE or target.startswith(PACKAGE + ".")):
                    continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in modules:  # ``from . import downlink``, ``from .commands import ingest``
                    add(sub, node.lineno)
                else:
                    add(target, node.lineno)
    found.pop(name, None)
    return found


def import_graph() -> dict[str, dict[str, int]]:
    modules = module_files()
    return {name: imports_of(name, modules) for name in modules}


def layer_of(name: str) -> tuple[str, int]:
    """``(matching LAYERS key, layer)`` for a module name."""
    best = max((k for k in LAYERS if name == k or name.startswith(k + ".")), key=len, default=None)
    if best is None:
        raise KeyError(f"{name}: in no layer; add it to LAYERS in {__file__}")
    return best, LAYERS[best]


def find_cycle(graph: dict[str, dict[str, int]]):
    """One import circle as a list of modules ``[a, b, ..., a]``, or None."""
    WHITE, GREY, BLACK = 0, 1, 2
    colour = {n: WHITE for n in graph}
    stack: list[str] = []

    def visit(n):
        colour[n] = GREY
        stack.append(n)
        for m in sorted(graph[n]):
            if colour[m] == GREY:
                return stack[stack.index(m):] + [m]
            if colour[m] == WHITE:
                c = visit(m)
                if c:
                    return c
        stack.pop()
        colour[n] = BLACK
        return None

    for n in sorted(graph):
        if colour[n] == WHITE:
            c = visit(n)
            if c:
                return c
    return None


@pytest.fixture(scope="module")
def graph():
    return import_graph()


def test_graph_sees_function_level_and_relative_imports(graph):
    """The parser itself: known arrows of each kind are found (a broken parser would pass everything)."""
    # module level, relative, two dots
    assert "scipctl.core.camera" in graph["scipctl.model"]
    # function level, relative (cli imports each command inside the command)
    assert "scipctl.commands.ingest" in graph["scipctl.cli"]
    # ``from . import x``: the module x
    assert "scipctl.io.downlink_records" in graph["scipctl.io.downlink_dir"]
    assert len(graph) > 50 and sum(map(len, graph.values())) > 150


def test_every_module_has_a_layer(graph):
    for name in graph:
        layer_of(name)


def test_no_import_circle(graph):
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(
        f"{a} (line {graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"


def test_no_import_from_a_lower_layer_to_a_higher_one(graph):
    bad = []
    for src, targets in sorted(graph.items()):
        _, ls = layer_of(src)
        for dst, line in sorted(targets.items()):
            _, ld = layer_of(dst)
            if ld > ls:
                bad.append(f"{src} ({LAYER_NAMES[ls]}) line {line} imports {dst} ({LAYER_NAMES[ld]})")
    assert not bad, "imports up the layers:\n" + "\n".join(bad)


def test_siblings_kept_apart(graph):
    bad = []
    for a, b in APART:
        for src, targets in sorted(graph.items()):
            for dst, line in sorted(targets.items()):
                for x, y in ((a, b), (b, a)):
                    if (src == x or src.startswith(x + ".")) and (dst == y or dst.startswith(y + ".")):
                        bad.append(f"{src} line {line} imports {dst}")
    assert not bad, "\n".join(bad)
