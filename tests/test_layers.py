"""The import rule of the product card: identify stands alone (numpy/scipy only); protocol (the rig on the
wire: PLC states, limits, register map, ADS symbols, frame formats, sweep profile) stands alone too (numpy);
sim may use identify, protocol and the protocol libraries it serves (pymodbus, pyads, python-can,
pyserial); daq uses identify and protocol (and h5py), never sim: a DAQ client does not load the
simulator; reports (what a person reads: report folders, text) use identify and matplotlib; server
composes them (and the web stack) but never imports the command-line package shakeid, which sits on top of
everything. Within shakeid/ no modules import each other in a circle (function-level imports count: a
circle there is a circle in the design). Checked on the source, so a stray import fails here."""
import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ALLOWED = {
    "identify": {"numpy", "scipy", "identify", "threadpoolctl"},  # threadpoolctl: identify.threads, BLAS limit
    # the rig protocol, declared once for the simulated rig that serves it and the DAQ that speaks it
    "protocol": {"numpy", "protocol"},
    "sim": {"numpy", "scipy", "identify", "protocol", "sim", "pymodbus", "pyads", "can", "serial"},
    # daq is the acquisition and file layer: the readers of the lab's file formats (daq/formats/) use npTDMS
    # (TDMS), pyuff (UFF 58) and asammdf (MDF4)
    "daq": {"numpy", "scipy", "h5py", "identify", "protocol", "daq", "pymodbus", "pyads", "can", "serial",
            "nptdms", "pyuff", "asammdf"},
    "reports": {"numpy", "matplotlib", "identify", "reports"},
    # the service composes the layers; nothing below it may import it (checked by the sets above), and it
    # does not import the CLI (shakeid/): both use reports/
    "server": {"numpy", "h5py", "matplotlib", "identify", "protocol", "sim", "daq", "reports", "server", "fastapi",
               "pydantic", "uvicorn", "distributed"},  # distributed: jobs on an existing Dask cluster ([compute] scheduler)
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
    absolute (`from shakeid.lab import x`) or relative (`from .lab import x`, `from . import lab`,
    `from ..gram import x` in a subpackage). A subpackage (identify/optimizers/) is one node: its files'
    imports of the package's modules are its edges (its files importing each other are its own affair)."""
    root = REPO / package
    node_of = {f: f.stem for f in root.glob("*.py")}
    node_of |= {f: f.relative_to(root).parts[0] for f in root.glob("*/**/*.py") if "__pycache__" not in f.parts}
    names = set(node_of.values())
    graph: dict[str, set[str]] = {n: set() for n in names}
    for f, me in sorted(node_of.items()):
        here = [package, *f.relative_to(root).parts[:-1]]  # the package the file is in
        deps = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level >= 1:
                base = ".".join(here[:len(here) - node.level + 1])
                mods = [f"{base}.{node.module}"] if node.module else [f"{base}.{a.name}" for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            deps |= {m.split(".")[1] for m in mods if m.startswith(package + ".") and m.split(".")[1] in names}
        graph[me] |= deps - {me}
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


# identify: the fit sequence (fitting) is below the identifier, joint and out_of_core, which use it; none of
# them reaches back (the identifier and joint had imported each other inside functions)
@pytest.mark.parametrize("package", ["shakeid", "reports", "identify"])
def test_no_import_circle_in_the_package(package):
    graph = _module_graph(package)
    assert {"cli", "lab", "remote"} <= set(graph) or package != "shakeid"
    assert {"identifier", "fitting", "joint", "out_of_core", "optimizers"} <= set(graph) or package != "identify"
    circle = _cycle(graph)
    assert circle is None, f"{package}/ modules import each other in a circle: {' -> '.join(circle)}"


def test_the_circle_finder_finds_circles():
    """The check above can fail: the finder sees a circle of three and a relative import of a sibling."""
    assert _cycle({"cli": {"lab"}, "lab": {"remote"}, "remote": {"cli"}}) == ["cli", "lab", "remote", "cli"]
    assert _cycle({"cli": {"lab", "remote"}, "lab": {"remote"}, "remote": set()}) is None


def test_the_graph_sees_subpackage_imports():
    """identify's graph: a subpackage is one node, and its files' `from ..gram import` are its edges
    (optimizers/base.py imports identify.gram); the fit sequence sits below the identifier."""
    graph = _module_graph("identify")
    assert "base" not in graph and "gram" in graph["optimizers"]
    assert {"fitting", "joint", "sources"} <= graph["identifier"] and "optimizers" in graph["fitting"]


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
