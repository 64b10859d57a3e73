"""The import rule of the product card: identify stands alone (numpy/scipy only); sim may use identify
and the protocol libraries it serves (pymodbus, pyads, python-can, pyserial); daq uses identify and sim
(and h5py); server composes them (and the web stack). Checked on the source, so a stray import fails here."""
import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ALLOWED = {
    "identify": {"numpy", "scipy", "identify"},
    "sim": {"numpy", "scipy", "identify", "sim", "pymodbus", "pyads", "can", "serial"},
    "daq": {"numpy", "scipy", "h5py", "identify", "sim", "daq", "pymodbus", "pyads", "can", "serial"},
    # the service composes the layers; nothing below it may import it (checked by the sets above)
    "server": {"numpy", "h5py", "matplotlib", "identify", "sim", "daq", "server", "shakeid", "fastapi", "pydantic",
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
        if ".venv" in f.parts:
            continue
        assert len(f.read_text().splitlines()) <= 450, f
