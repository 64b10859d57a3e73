"""The command line's recordings in and reports out, shared by its commands (identify, batch, explain):
the layout options, reading the recording they name, naming the file in an error, writing a report folder."""
from __future__ import annotations

import argparse
import sys

from identify.errors import ShakeidError

from .argtypes import int_in, positive


def add_layout_options(p: argparse.ArgumentParser) -> None:
    """Which columns of the file are the input, the output and the time (identify, batch, explain)."""
    g = p.add_argument_group("recording layout")
    g.add_argument("--layout", choices=("base", "force"), default="base",
                   help="base: table and mass accelerations in m/s²; force: an input u and a displacement-like "
                        "output y (e.g. Silverbox, volts)")
    g.add_argument("--input", metavar="NAME", help="input channel by name, in any format: a column, a variable, a "
                   "TDMS channel (GROUP/NAME when in two groups), a UFF id1, an MDF channel (default: table_acc, or u "
                   "with --layout force)")
    g.add_argument("--output", metavar="NAME", help="output channel by name, as --input (default: mass_acc, or y with "
                   "--layout force)")
    g.add_argument("--time", metavar="NAME", help="time column, s (default: t)")
    g.add_argument("--fs", type=positive, metavar="HZ",
                   help="sample rate in Hz for a file without a clock, or the exact rate of a clock the file stores "
                        "coarsely (UFF's 6-digit increment) (default: from the file)")
    g.add_argument("--samples", type=int_in(0), nargs=2, metavar=("START", "STOP"),
                   help="use samples [START, STOP) only (0-based), e.g. Silverbox's estimation range "
                        "(default: all)")
    g.add_argument("--band", type=float, nargs=2, metavar=("F_LO", "F_HI"),
                   help="integration band in Hz (default: the excited band, found from the table's spectrum)")


def read_recording(args):
    """The recording named on the command line (any format daq.formats reads), cut to --samples if given;
    what the reader noticed (a unit converted, a sample rate stored coarsely) is printed to stderr."""
    from daq.formats import open_recording

    samples = getattr(args, "samples", None)
    rec = open_recording(args.file, args.layout, args.input, args.output, args.time, args.fs,
                         tuple(samples) if samples else None)
    for note in rec.metadata.get("warnings", ()):
        print(f"shakeid: warning: {args.file}: {note}", file=sys.stderr)
    return rec


def naming(path, exc: Exception) -> ShakeidError:
    """The error with the file it is about in front, unless it names it already."""
    text = str(exc)
    return ShakeidError(text if str(path) in text else f"{path}: {text}")


def write_report(kind: str, fitted, out_dir, result: dict | None = None) -> str:
    """Write the identification or explain report of `fitted` into out_dir (nothing when it is None;
    `result`: the identification's document as --json prints it, for model.json); returns what the
    operator is told it replaced: " (replaces the report written there at ...)" or ""."""
    if not out_dir:
        return ""
    from reports.html import earlier_report

    earlier = earlier_report(out_dir)
    if kind == "identification":
        from reports.identification import write_report

        write_report(fitted, out_dir, result)
    else:
        from reports.explain import write_explain_report

        write_explain_report(fitted, out_dir, (result or {}).get("frf"))
    return f" (replaces {earlier})" if earlier else ""
