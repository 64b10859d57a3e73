"""A model out of shakeid: an FMI 2.0 Co-Simulation FMU, a C file, a numpy module, LaTeX equations.

Generation is stdlib only (string templates, zipfile, the C compiler by subprocess); every term's
expression in every language comes from identify.export.render, driven by the term's structure.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..model import SparseModel
from .ccode import c_source
from .fmu import CompilerError, build_fmu
from .latex import latex_equations, latex_source
from .pycode import python_source

__all__ = ["FORMATS", "CompilerError", "export_model", "latex_equations"]


def _text(render):
    def write(model: SparseModel, out: Path, title: str) -> Path:
        part = out.with_name(out.name + ".part")
        part.write_text(render(model, title))
        os.replace(part, out)
        return out
    return write


#: format -> (file suffix, writer(model, out, title)); a new format is one entry here
FORMATS = {
    "fmu": (".fmu", build_fmu),
    "c": (".c", _text(c_source)),
    "python": (".py", _text(python_source)),
    "latex": (".tex", _text(latex_source)),
}


def export_model(model: SparseModel, fmt: str, out, title: str = "shakeid model") -> Path:
    """Write `model` as `fmt` (a FORMATS key) at `out` (written whole, or not at all)."""
    suffix, write = FORMATS[fmt]
    out = Path(out)
    if out.suffix.lower() != suffix:
        raise ValueError(f"{out}: a {fmt} export is a {suffix} file")
    return write(model, out, title)
