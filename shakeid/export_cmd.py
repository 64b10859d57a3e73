"""`shakeid export MODEL.json --format fmu|c|python|latex --out PATH`: a model out of shakeid.

MODEL.json is what `shakeid identify --json` prints or a report's / the service's model.json (the
result document), or a bare model file (SparseModel.save). The file at --out is written whole or not at
all, and an existing one is replaced only with --overwrite. docs/export.md says what each format holds.
"""
from __future__ import annotations

from pathlib import Path

from identify.errors import ShakeidError

from .model_arg import add_model_arguments, read_model


def add_export_parser(sub) -> None:
    from identify.export import FORMATS

    q = sub.add_parser("export", help="write a model as an FMU (FMI 2.0 co-simulation), C, Python or LaTeX")
    add_model_arguments(q, "export")
    q.add_argument("--format", required=True, choices=tuple(FORMATS),
                   help="fmu: FMI 2.0 co-simulation FMU built by the C compiler ($CC, cc, gcc or clang); c: one "
                        "dependency-free C file (right-hand side and an RK4 step); python: a numpy module (rhs, "
                        "simulate); latex: the equations in the paper's notation")
    q.add_argument("--out", required=True, metavar="PATH",
                   help="the file to write: " + ", ".join(f"{s} for {f}" for f, (s, _) in FORMATS.items()))
    q.add_argument("--overwrite", action="store_true", help="replace PATH if it exists (default: refuse)")
    q.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    from identify.export import FORMATS, export_model
    suffix = FORMATS[args.format][0]
    out = Path(args.out)
    if out.suffix.lower() != suffix:  # checked before reading anything: a mistyped --out costs nothing
        raise ShakeidError(f"--out {out}: a {args.format} export is a {suffix} file (e.g. --out "
                           f"{out.with_suffix(suffix).name})")
    if out.exists() and not args.overwrite:
        raise ShakeidError(f"{out} exists already; --overwrite replaces it")
    if not out.parent.is_dir():
        raise ShakeidError(f"{out}: no folder {out.parent} to write it in")
    model = read_model(args, "export")
    export_model(model, args.format, out, title=f"shakeid model from {Path(args.model).name}")
    print(f"wrote {out} ({args.format}: {model.n_terms} terms of {', '.join(model.equations)})")
    return 0
