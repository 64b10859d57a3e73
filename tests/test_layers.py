"""The import rule of the product card: identify stands alone (numpy/scipy only); protocol (the rig on the
wire: PLC states, limits, register map, ADS symbols, frame formats, sweep profile) stands alone too (numpy);
sim may use identify, protocol and the protocol libraries it serves (pymodbus, pyads, python-can,
pyserial); daq uses identify and protocol (and h5py), never sim: a DAQ client does not load the
simulator; reports (what a person reads: report folders, text) use identify and matplotlib; server
composes them (and the web stack) but never imports the command-line package shakeid, which sits on top of
everything. Within shakeid/ no modules import each other in a circle (function-level imports count: a
circle there is a circle in the design). Checked on the source, so a stray import fails here."""
import ast
import re
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


def _imported(base: str, aliases, package: str, names: set[str]) -> list[str]:
    """What `from base import a, b` imports: the modules a, b where they are modules of the package
    (`from . import render` is render, not the folder's __init__), else base itself."""
    subs = [f"{base}.{a.name}" for a in aliases if f"{base}.{a.name}"[len(package) + 1:] in names]
    return subs or [base]


def _module_graph(package: str) -> dict[str, set[str]]:
    """{module: modules of the same package it imports}, anywhere in the file (top level or in a function),
    absolute (`from shakeid.lab import x`) or relative (`from .lab import x`, `from . import lab`,
    `from ..regression.gram import x` in a stage folder). Every file is a node, named by its dotted path in
    the package (`chain.states`; a folder's `__init__.py` is the folder: `explain.effects`)."""
    root = REPO / package
    node_of = {}
    for f in root.rglob("*.py"):
        if "__pycache__" in f.parts:
            continue
        parts = list(f.relative_to(root).with_suffix("").parts)
        node_of[f] = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
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
                mods = _imported(f"{base}.{node.module}" if node.module else base, node.names, package, names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = _imported(node.module, node.names, package, names)
            else:
                continue
            deps |= {m[len(package) + 1:] for m in mods if m.startswith(package + ".")} & names
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
    assert {"identifier", "fitting", "joint", "out_of_core", "regression.optimizers.base"} <= set(graph) \
        or package != "identify"
    circle = _cycle(graph)
    assert circle is None, f"{package}/ modules import each other in a circle: {' -> '.join(circle)}"


def test_the_circle_finder_finds_circles():
    """The check above can fail: the finder sees a circle of three and a relative import of a sibling."""
    assert _cycle({"cli": {"lab"}, "lab": {"remote"}, "remote": {"cli"}}) == ["cli", "lab", "remote", "cli"]
    assert _cycle({"cli": {"lab", "remote"}, "lab": {"remote"}, "remote": set()}) is None


def test_the_graph_sees_stage_folder_imports():
    """identify's graph: a file in a stage folder reaches another folder's module by `from ..x.y import`
    (regression/optimizers/base.py imports regression/gram.py; simulation/simulate.py the C kernel by
    `from .. import _simkernel`, which is no module file); the fit sequence sits below the identifier."""
    graph = _module_graph("identify")
    assert "regression.gram" in graph["regression.optimizers.base"]
    assert "regression.gram" in graph["regression.optimizers.stlsq"] or \
        "regression.optimizers.base" in graph["regression.optimizers.stlsq"]
    assert {"fitting", "joint", "regression.sources"} <= graph["identifier"]
    assert "regression.optimizers" in graph["fitting"] or "regression.optimizers.base" in graph["fitting"]
    assert "explain.effects.base" in graph["explain.effects.end_stop"]


def test_the_engine_is_grouped_by_stage():
    """identify/ shows the pipeline: a handful of modules at the top (the estimator, its parameters, its one
    fit sequence, the model, errors), every stage a folder; the public names load from the facade."""
    import identify

    top = sorted(f.stem for f in (REPO / "identify").glob("*.py") if f.stem != "__init__")
    assert len(top) <= 10, f"identify/ has {len(top)} modules at the top: {top}"
    stages = {d.name for d in (REPO / "identify").iterdir() if (d / "__init__.py").exists()}
    assert {"data", "chain", "noise", "regression", "selection", "trust", "simulation", "explain"} <= stages
    for name in identify.__all__:
        assert getattr(identify, name).__name__ == name


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


#: how the README names a distribution whose import name differs
_README_NAMES = {"python-can": "can", "pyserial": "serial", "npTDMS": "nptdms"}


def test_the_readme_layout_states_the_rule():
    """README.md's Layout table ("may import") says what ALLOWED enforces, package by package, and its
    server row names every router module (the table had drifted: threadpoolctl, scipy, pydantic, uvicorn,
    distributed and the frf router missing)."""
    rows = {}
    for line in (REPO / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0].startswith("`") and cells[0].endswith("/`"):
            rows[cells[0].strip("`/")] = cells
    for package, allowed in ALLOWED.items():
        said = {_README_NAMES.get(w, w) for w in re.findall(r"[A-Za-z][\w-]*", rows[package][2].split("(")[0])}
        assert said == allowed - {package}, f"README's {package}/ row: says {sorted(said)}, the rule is " \
                                            f"{sorted(allowed - {package})}"
    routers = {f.stem for f in (REPO / "server" / "routers").glob("*.py")} - {"__init__"}
    listed = set(re.search(r"`routers/`: ([^)]*)\)", rows["server"][1]).group(1).replace(" ", "").split(","))
    assert listed == routers, f"README's server/ row lists routers {sorted(listed)}, server/routers has {sorted(routers)}"
