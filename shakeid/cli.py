"""The `shakeid` command line: identify, simulate, demo.

Errors an operator can fix (bad file, bad option) print one line `shakeid: error: ...` on stderr and exit
with status 2; nothing is half-written.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from daq.formats import NAMES as FORMAT_NAMES
from identify.errors import IdentificationError, ShakeidError
from reports.text import summary

from .argtypes import file_and_samples, non_negative, positive
from .batch_cmd import add_batch_parser
from .campaign_cmd import add_campaign_parser
from .explain_cmd import add_explain_parser
from .files import add_layout_options, naming, read_recording, write_report
from .export_cmd import add_export_parser
from .frf_cmd import add_frf_parser
from .helpformat import Parser
from .lab_options import add_lab_parsers, add_sweep_shape
from .ooc_cmd import add_out_of_core_options
from .param_options import add_estimator_options, estimator_kwargs
from .plan_cmd import add_plan_parser

EXIT_USAGE = 2


def _add_identify_options(p: argparse.ArgumentParser) -> None:
    add_layout_options(p)
    g = p.add_argument_group("identification")
    add_estimator_options(g)  # identify.params.PARAMS: one declaration for CLI, API, estimator, docs


def _identifier(args):
    from identify.identifier import SparseIdentifier
    from identify.regression.library import Library

    Library(degree=args.degree, extra_terms=args.extra_terms)  # unknown terms are refused here, by name
    return SparseIdentifier(**estimator_kwargs(args), band_hz=tuple(args.band) if args.band else None)


def cmd_identify(args) -> int:
    """Exit 0 with a model; 2 for data that cannot carry one (refused before fitting, unless
    --accept-faulty); 1 when the fitted model fails its validation (identify/simulation/validation.py)."""
    from identify.data.quality import check_identifiable

    if len(args.files) > 1:
        from .joint_cmd import cmd_identify_joint

        return cmd_identify_joint(args, _identifier)
    args.file, args.samples = file_and_samples(args.files[0], getattr(args, "samples", None))
    ident = _identifier(args)  # option errors first, before any file is read
    from .ooc_cmd import identify_out_of_core, wants_out_of_core

    if wants_out_of_core(args):  # a long HDF5 recording: read and identified chunk by chunk
        return identify_out_of_core(args, ident)
    if args.report:
        from reports.html import check_report_folder

        check_report_folder(args.report, "identification")  # before the fit: a mistyped --report costs nothing
    rec = read_recording(args)
    data = check_identifiable(rec, args.file, args.accept_faulty)
    try:
        ident.fit(rec)
    except ValueError as exc:  # library/term specification problems
        raise ShakeidError(str(exc)) from None
    except IdentificationError as exc:  # what the data cannot give (no excited band, too short): name the file
        raise naming(args.file, exc) from None
    from identify.frf.side_by_side import identification_document  # with the predicted jumps (docs/frf.md)

    result = identification_document(ident, [rec], data)
    replaced = write_report("identification", ident, args.report, result)
    if args.json:
        print(json.dumps(result))
    else:
        print(summary(result, rec.source))
        for line in result["frf"]["flags"]:
            print(f"flagged: {line}")
        if args.report:
            print(f"report: {Path(args.report) / 'index.html'}{replaced}")
    if result["status"] == "failed":
        print(f"shakeid: identification failed: {args.file}: {result['reason']} (`shakeid explain {args.file}` "
              "looks for the effect the library misses)", file=sys.stderr)
        return 1
    return 0


def _add_sweep_options(p: argparse.ArgumentParser) -> None:
    """The simulated sweep of `shakeid simulate`: the table's motion, the sensors, the rig."""
    add_sweep_shape(p, required=False)
    p.add_argument("--fs-hz", type=positive, default=2048.0, metavar="HZ",
                   help="sample rate, Hz (2048 Hz is the paper's 0.488 ms step)")
    p.add_argument("--noise", type=non_negative, default=0.005, metavar="F",
                   help="sensor noise std as a fraction of each channel's std (0.005: 0.5 %%)")
    p.add_argument("--bias-ms2", type=float, default=0.0, metavar="M/S²", help="accelerometer bias, m/s² (both sensors)")
    p.add_argument("--lsb-ms2", type=non_negative, default=0.0, metavar="M/S²", help="ADC quantisation step, m/s² (0: none)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the sensor noise")
    p.add_argument("--rig", choices=("paper-table1", "design"), default="paper-table1",
                   help="the rig's parameters: the paper's identified Table 1 model, or its design values")
    p.add_argument("--effect", action="append", default=[], metavar="NAME=COEF",
                   help="add a physical effect (force coefficient, SI units), e.g. coulomb_friction=0.3; repeatable")


def _synthesize(args):
    from sim.rig import RigParameters
    from sim.sensors import Accelerometer
    from protocol.sweep import SineSweep
    from sim.synth import run_sweep

    rig = RigParameters.paper_table1() if args.rig == "paper-table1" else RigParameters.design()
    for spec in args.effect:
        name, _, value = spec.partition("=")
        try:
            rig.effects[name.strip()] = float(value)
        except ValueError:
            raise ShakeidError(f"--effect {spec!r}: expected NAME=NUMBER") from None
    try:
        rig.__post_init__()
        sweep = SineSweep(args.f_start_hz, args.f_end_hz, args.duration_s, args.amplitude_mm)
        sensor = Accelerometer(noise_fraction=args.noise, bias_ms2=args.bias_ms2, lsb_ms2=args.lsb_ms2)
        return run_sweep(rig, sweep, args.fs_hz, table_sensor=sensor, mass_sensor=sensor, seed=args.seed)
    except ValueError as exc:
        raise ShakeidError(str(exc)) from None


def cmd_simulate(args) -> int:
    from identify.data.recording import write_csv

    out = Path(args.out)
    truth = out.with_suffix(".truth.json")
    existing = [str(p) for p in (out, truth) if p.exists()]
    if existing and not args.overwrite:  # checked before the run: a mistyped --out costs nothing
        raise ShakeidError(f"{' and '.join(existing)} {'exists' if len(existing) == 1 else 'exist'} already; a "
                           "recording is never overwritten (another --out, or --overwrite to replace a synthetic one)")
    if not out.parent.is_dir():
        raise ShakeidError(f"{out}: no folder {out.parent} to write it in")
    run = _synthesize(args)
    write_csv(out, run.recording)
    truth.write_text(json.dumps(run.truth, indent=2))
    stops, n_contact = run.truth["end_stops"], run.truth["contact_samples"]
    if stops is None:
        contact = "no end stops"
    elif n_contact:
        contact = (f"end stops (+-{stops['travel_mm']:g} mm) hit: {n_contact} samples in contact "
                   f"({n_contact / run.recording.fs_hz:.2f} s)")
    else:
        contact = f"end stops (+-{stops['travel_mm']:g} mm) not touched"
    print(f"wrote {out} ({run.recording.n_samples} samples at {run.recording.fs_hz:g} Hz: the {args.duration_s:g} s "
          f"sweep and {run.truth['settle_s']:g} s at rest after it) and {truth}; "
          f"max |q| = {run.truth['max_abs_q_m'] * 1e3:.2f} mm, {contact}")
    return 0


def _version() -> str:
    """The installed package's version (pyproject.toml), or 'unknown' when run from a bare source tree."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("shakeid")
    except PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="shakeid", description="Sparse nonlinear identification of shaker rigs")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    q = sub.add_parser("identify", help=f"identify a sparse ODE model from a recording ({FORMAT_NAMES})")
    q.add_argument("files", nargs="+", metavar="FILE",
                   help=f"a recording ({FORMAT_NAMES}: docs/recordings.md); several: one model fitted to all of them (joint "
                        "identification); FILE[START:STOP]: that file's samples [START, STOP) only")
    _add_identify_options(q)
    add_out_of_core_options(q)
    q.add_argument("--report", metavar="DIR",
                   help="write index.html, figures, coefficient table and model JSON here (default: none)")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    q.add_argument("--accept-faulty", action="store_true",
                   help="identify a recording that is not complete or whose quality flags make it unusable")
    q.set_defaults(func=cmd_identify)
    add_batch_parser(sub, _add_identify_options, _identifier)
    add_explain_parser(sub)
    add_lab_parsers(sub)
    add_campaign_parser(sub)
    add_export_parser(sub)
    add_frf_parser(sub)
    add_plan_parser(sub)
    q = sub.add_parser("simulate", help="write a synthetic recording of the simulated rig (CSV + truth JSON)")
    q.add_argument("--out", required=True, metavar="FILE.csv",
                   help="the recording (t, table_acc, mass_acc); the truth goes to FILE.truth.json")
    q.add_argument("--overwrite", action="store_true",
                   help="replace FILE.csv and FILE.truth.json if they exist (default: refuse, as a recording is "
                        "never overwritten)")
    _add_sweep_options(q)
    q.set_defaults(func=cmd_simulate)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a usage error (its line printed), --help, --version: the code, as any command's
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    from .progress import survive_closed_readers

    survive_closed_readers()  # a reader that goes away (| head) never stops a sweep or a campaign
    try:
        return args.func(args)
    except ShakeidError as exc:
        print(f"shakeid: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # a file or folder the command was given (a missing folder, no permission): one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"shakeid: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("shakeid: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
