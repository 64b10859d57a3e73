"""The import rule of the product card: identify stands alone (numpy/scipy only); sim may use identify
and the protocol libraries it serves (pymodbus, pyads, python-can, pyserial); daq uses identify and sim
(and h5py); reports (what a person reads: report folders, text) use identify and matplotlib; server
composes them (and the web stack) but never imports the command-line package shakeid, which sits on top of
everything. Within shakeid/ no modules import each other in a circle (function-level imports count: a
circle there is a circle in the design). Checked on the source, so a stray import fails here."""
import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ALLOWED = {
    "identify": {"numpy", "scipy", "identify"},
    "sim": {"numpy", "scipy", "identify", "sim", "pymodbus", "pyads", "can", "serial"},
    # daq is the acquisition and file layer: the readers of the lab's file formats (daq/formats/) use npTDMS
    # (TDMS), pyuff (UFF 58) and asammdf (MDF4)
    "daq": {"numpy", "scipy", "h5py", "identify", "sim", "daq", "pymodbus", "pyads", "can", "serial",
            "nptdms", "pyuff", "asammdf"},
    "reports": {"numpy", "matplotlib", "identify", "reports"},
    # the service composes the layers; nothing below it may import it (checked by the sets above), and it
    # does not import the CLI (shakeid/): both use reports/
    "server": {"numpy", "h5py", "matplotlib", "identify", "sim", "daq", "reports", "server", "fastapi", "pydantic",
               "uvicorn", "distributed"},  # distributed: jobs on an existing Dask cluster ([compute] scheduler)
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


def _module_graph(package: str) -> dict[str, set[str]]:
    """{module: modules of the same package it imports}, anywhere in the file (top level or in a function),
    absolute (`from shakeid.lab import x`) or relative (`from .lab import x`, `from . import lab`)."""
    root = REPO / package
    names = {f.stem for f in root.glob("*.py")}
    graph: dict[str, set[str]] = {}
    for f in sorted(root.glob("*.py")):
        deps = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 1:
                mods = [node.module] if node.module else [a.name for a in node.names]
                mods = [f"{package}.{m}" for m in mods]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            deps |= {m.split(".")[1] for m in mods if m.startswith(package + ".") and m.split(".")[1] in names}
        graph[f.stem] = deps - {f.stem}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle as [a, b, ..., a], or None (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node, path):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt, path + [nxt])):
                return found
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start, [start])):
            return found
    return None


@pytest.mark.parametrize("package", ["shakeid", "reports"])
def test_no_import_circle_in_the_package(package):
    graph = _module_graph(package)
    assert {"cli", "lab", "remote"} <= set(graph) or package != "shakeid"
    circle = _cycle(graph)
    assert circle is None, f"{package}/ modules import each other in a circle: {' -> '.join(circle)}"


def test_the_circle_finder_finds_circles():
    """The check above can fail: the finder sees a circle of three and a relative import of a sibling."""
    assert _cycle({"cli": {"lab"}, "lab": {"remote"}, "remote": {"cli"}}) == ["cli", "lab", "remote", "cli"]
    assert _cycle({"cli": {"lab", "remote"}, "lab": {"remote"}, "remote": set()}) is None


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_its_layer(package):
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    files = sorted((REPO / package).rglob("*.py"))
    assert files
    for f in files:
        extra = _imports(f) - stdlib - ALLOWED[package]
        assert not extra, f"{f.relative_to(REPO)} imports {sorted(extra)}"


def test_no_module_much_over_400_lines():
    for f in REPO.glob("*/**/*.py"):
        if ".venv" in f.parts or f.relative_to(REPO).parts[0] == "build":  # the environment; pip's build copies
            continue
        assert len(f.read_text().splitlines()) <= 450, f
