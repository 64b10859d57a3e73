"""The `shakeid` command line: identify, simulate, demo.

Errors an operator can fix (bad file, bad option) print one line `shakeid: error: ...` on stderr and exit
with status 2; nothing is half-written.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from identify.errors import ShakeidError

from .batch_cmd import add_batch_parser
from .campaign_cmd import add_campaign_parser
from .lab import cmd_controller, cmd_demo, cmd_recordings, cmd_serve, cmd_sim, cmd_sweep
from .rigcmd import cmd_rig

EXIT_USAGE = 2


def _add_identify_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("recording layout")
    g.add_argument("--layout", choices=("base", "force"), default="base",
                   help="base: table/mass accelerations (default); force: input u, displacement-like output y")
    g.add_argument("--input", help="input column/variable (default table_acc, or u for --layout force)")
    g.add_argument("--output", help="output column/variable (default mass_acc, or y)")
    g.add_argument("--time", help="time column (default t)")
    g.add_argument("--fs", type=float, help="sample rate in Hz when the file has no time column")
    g.add_argument("--samples", type=int, nargs=2, metavar=("START", "STOP"),
                   help="use samples [START, STOP) only (0-based), e.g. Silverbox's estimation range")
    g = p.add_argument_group("identification")
    g.add_argument("--degree", type=int, default=4, help="highest monomial degree of the library (4)")
    g.add_argument("--extra-terms", default="", help="comma-separated extra terms, e.g. 'sign(q1),q1*|q1|'")
    g.add_argument("--method", choices=("admm", "stlsq"), default="admm")
    g.add_argument("--lambdas", type=int, default=100, help="points on the path (100)")
    g.add_argument("--threshold", type=float, help="STLSQ: a single threshold instead of a path")
    g.add_argument("--raw-threshold", action="store_true",
                   help="STLSQ: threshold raw coefficients, as the paper's Table 2 (lambda = 0.95)")
    g.add_argument("--selection", choices=("heldout", "paper", "bic"), default="heldout")
    g.add_argument("--tolerance", type=float, help="selection tolerance (paper 0.25, heldout 0.003)")
    g.add_argument("--max-terms", type=int, help="at most this many terms per equation")
    g.add_argument("--budget", choices=("equation-error", "free-run"), default="equation-error",
                   help="how --max-terms chooses q1_dot's terms: by one-step acceleration error (default) or "
                        "by the free-run error of refit candidates on the data (slower; implies the refit)")
    g.add_argument("--budget-refit", choices=("fit", "all"), default="fit",
                   help="--budget free-run: refit the chosen terms on the fit rows (default) or on all rows, "
                        "held-out ones included (validation figures are then not out-of-sample)")
    g.add_argument("--refine", choices=("free-run",),
                   help="refit the kept coefficients on the free-run simulation error")
    g.add_argument("--holdout-samples", type=int, help="hold out the first N samples (the paper: 30000)")
    g.add_argument("--holdout-fraction", type=float, default=0.2,
                   help="share held out in interleaved blocks when --holdout-samples is not given (0.2)")
    g.add_argument("--band", type=float, nargs=2, metavar=("F_LO", "F_HI"), help="integration band in Hz")
    g.add_argument("--bias-replicates", type=int, default=16,
                   help="SIMEX replicates for the measurement chain's bias (16; 0: none, faster)")
    g.add_argument("--placements", type=int, default=24,
                   help="random held-out placements for the inclusion probabilities (24; 0: none, faster)")
    g.add_argument("--mass-kg", type=float, default=0.49, help="moving mass for physical parameters (0.49)")


def _identifier(args):
    from identify.identifier import SparseIdentifier
    from identify.physical import RigConstants

    if args.lambdas < 2:
        raise ShakeidError("--lambdas must be at least 2")
    if not 0 <= args.holdout_fraction < 0.9:
        raise ShakeidError("--holdout-fraction must be in [0, 0.9)")
    if args.bias_replicates < 0 or args.placements < 0:
        raise ShakeidError("--bias-replicates and --placements must be >= 0")
    extra = tuple(t.strip() for t in args.extra_terms.split(",") if t.strip())
    from identify.library import Library

    Library(degree=args.degree, extra_terms=extra)  # unknown terms are refused here, by name
    return SparseIdentifier(degree=args.degree, extra_terms=extra, method=args.method, n_lambdas=args.lambdas,
                            threshold=args.threshold, normalize_threshold=not args.raw_threshold,
                            selection=args.selection, tolerance=args.tolerance, max_terms=args.max_terms,
                            budget=args.budget, budget_refit=args.budget_refit, refine=args.refine,
                            holdout_fraction=args.holdout_fraction, holdout_samples=args.holdout_samples,
                            band_hz=tuple(args.band) if args.band else None,
                            rig=RigConstants(mass_kg=args.mass_kg), bias_replicates=args.bias_replicates,
                            placements=args.placements)


def _read(args):
    """The recording named on the command line, cut to --samples if given."""
    from daq.recorder import open_recording

    samples = getattr(args, "samples", None)
    return open_recording(args.file, args.layout, args.input, args.output, args.time, args.fs,
                          tuple(samples) if samples else None)


def cmd_identify(args) -> int:
    """Exit 0 with a model; 2 for data that cannot carry one (refused before fitting, unless
    --accept-faulty); 1 when the fitted model fails its validation (identify/validation.py)."""
    from identify.quality import check_identifiable

    if len(args.files) > 1:
        from .joint_cmd import cmd_identify_joint

        return cmd_identify_joint(args, _identifier, _read)
    args.file = args.files[0]
    ident = _identifier(args)  # option errors first, before any file is read
    from .ooc_cmd import identify_out_of_core, wants_out_of_core

    if wants_out_of_core(args):  # a long HDF5 recording: read and identified chunk by chunk
        return identify_out_of_core(args, ident)
    rec = _read(args)
    data = check_identifiable(rec, args.file, args.accept_faulty)
    try:
        ident.fit(rec)
    except ValueError as exc:  # library/term specification problems
        raise ShakeidError(str(exc)) from None
    result = {**ident.result(), **data}
    if args.report:
        from .report import write_report

        write_report(ident, args.report)
    if args.json:
        print(json.dumps(result))
    else:
        print(summary(result, rec.source))
        if args.report:
            print(f"report: {Path(args.report) / 'index.html'}")
    if result["status"] == "failed":
        print(f"shakeid: identification failed: {args.file}: {result['reason']}", file=sys.stderr)
        return 1
    return 0


def summary(result: dict, source: str) -> str:
    from .report import coefficient_table

    lines = [f"identified {source}: method {result['method']}, selection {result['selection']['rule']}", ""]
    if result.get("accepted_faulty"):
        lines += ["accepted faulty data (--accept-faulty): " + "; ".join(result["accepted_faulty"]), ""]
    lines.append(coefficient_table(result))
    val = result.get("validation")
    if val:
        h = val["heldout"]
        fmt = lambda m: "diverged" if m["fit_percent"] is None else f"{m['fit_percent']:.2f} %"  # noqa: E731
        lines.append(f"free-run fit on {val['heldout_samples']} held-out samples: acceleration {fmt(h['q1_dot'])},"
                     f" velocity {fmt(h['q1'])}, displacement {fmt(h['q2'])}")
    offset = result.get("chain", {}).get("displacement_below_band") or {}
    if offset.get("carried"):
        lines.append(f"displacement below the band carried (an even force rectifies it; the terms are those of the "
                     f"true displacement): rms {offset['rms_mm']:.3g} mm, {offset['min_mm']:.3g} to {offset['max_mm']:.3g} mm, "
                     f"{offset['passes']} passes{'' if offset['converged'] else ', NOT converged'}")
    phys = result.get("physical")
    if phys:
        def pv(key, unit, scale=1.0):
            v = phys[key]["value"]
            return f"{key} = {v * scale:.5g} {unit}" if v is not None else f"{key}: term not in model"
        lines.append("physical: " + "; ".join([pv("damping_ns_per_m", "N s/m"), pv("stiffness_n_per_m", "N/m"),
                                               pv("cubic_stiffness_n_per_m3", "N/m^3"),
                                               pv("prestress_b_m", "mm", 1e3)]) +
                     f" (design k3 = {phys['design']['cubic_stiffness_n_per_m3']:.4g} N/m^3)")
    if result.get("status") == "failed":
        lines.append(f"MODEL FAILED: {result['reason']}")
    return "\n".join(lines)


def cmd_explain(args) -> int:
    from identify.explain import DiscrepancyAnalysis
    from identify.model import SparseModel

    from identify.quality import check_identifiable

    baseline = SparseModel.load(args.model) if args.model else None
    rec = _read(args)
    data = check_identifiable(rec, args.file, args.accept_faulty,  # as identify: no analysis of unusable data
                              "use --accept-faulty to analyse it anyway")
    analysis = DiscrepancyAnalysis(baseline=baseline, band_hz=tuple(args.band) if args.band else None).fit(rec)
    result = {**analysis.result(), **data}
    if args.report:
        from .explain_report import write_explain_report

        write_explain_report(analysis, args.report)
    if args.json:
        print(json.dumps(result))
        return 0
    f = lambda v: "n/a" if v is None else f"{v:.4f}"  # noqa: E731
    print(f"baseline: {result['baseline']['source']}; {result['metric']}: {f(result['gap_before'])}"
          f" (sensor-noise floor <= {f(result['noise_floor_upper'])})")
    worst = result["localisation"]["time"]["worst_window"]
    print(f"largest misfit: t = {worst['t_start_s']:.1f}-{worst['t_end_s']:.1f} s, excitation "
          f"{worst['excitation_hz']:.1f} Hz")
    for c in result["candidates"]:
        closed = c.get("gap_share_closed")
        p = "-" if c.get("kind") == "measurement" else f"{c['p_value']:.1e}"  # searched, no Wald test
        print(f"  {c['name']:32s} equation-error share {c['score']:+.3f}  p = {p}  "
              f"shooting gap closed {'-' if closed is None else f'{closed:+.2f}'}"
              + (f"  (rejected: {c['rejected']})" if c.get("rejected") else ""))
    if result["effect"] in ("none", "unexplained"):
        print(f"missing effect: {result['effect']} (confidence {result['confidence']:.2f})")
    else:
        for e in result["effects"]:
            sur = f"; stands in for {', '.join(e['surrogate_for'])}" if e["surrogate_for"] else ""
            print(f"missing effect: {e['name']} ({e['kind']}) {json.dumps(e['coefficients'])} (confidence "
                  f"{e['confidence']:.2f}; gap after {f(e['gap_after'])}{sur})")
        print(f"gap {f(result['gap_before'])} -> {f(result['gap_after'])}")
        print("model: " + json.dumps(result["model"]))
    if result.get("remaining"):
        top = result["remaining"]["segments"][0]
        print(f"still missed most at t = {top['t_start_s']:.1f}-{top['t_end_s']:.1f} s "
              f"(excitation {top['excitation_hz']:.1f} Hz, {100 * top['share_of_error']:.0f} % of the error)")
    if args.report:
        print(f"report: {args.report}")
    return 0


def _add_sweep_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--f-start-hz", type=float, default=1.0)
    p.add_argument("--f-end-hz", type=float, default=20.0)
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--amplitude-mm", type=float, default=1.3)
    p.add_argument("--fs-hz", type=float, default=2048.0, help="sample rate (2048 Hz = the paper's 0.488 ms)")
    p.add_argument("--noise", type=float, default=0.005, help="sensor noise as a fraction of each channel's std")
    p.add_argument("--bias-ms2", type=float, default=0.0, help="accelerometer bias, m/s^2 (both sensors)")
    p.add_argument("--lsb-ms2", type=float, default=0.0, help="ADC quantisation step, m/s^2 (0: none)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rig", choices=("paper-table1", "design"), default="paper-table1")
    p.add_argument("--effect", action="append", default=[], metavar="NAME=COEF",
                   help="add a physical effect (force coefficient, SI), e.g. coulomb_friction=0.3")


def _synthesize(args):
    from sim.rig import RigParameters
    from sim.sensors import Accelerometer
    from sim.sweep import SineSweep
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
        if args.noise < 0 or args.lsb_ms2 < 0:
            raise ShakeidError("--noise and --lsb-ms2 must be >= 0")
        sensor = Accelerometer(noise_fraction=args.noise, bias_ms2=args.bias_ms2, lsb_ms2=args.lsb_ms2)
        return run_sweep(rig, sweep, args.fs_hz, table_sensor=sensor, mass_sensor=sensor, seed=args.seed)
    except ValueError as exc:
        raise ShakeidError(str(exc)) from None


def cmd_simulate(args) -> int:
    from identify.recording import write_csv

    run = _synthesize(args)
    out = Path(args.out)
    write_csv(out, run.recording)
    truth = out.with_suffix(".truth.json")
    truth.write_text(json.dumps(run.truth, indent=2))
    stops, n_contact = run.truth["end_stops"], run.truth["contact_samples"]
    if stops is None:
        contact = "no end stops"
    elif n_contact:
        contact = (f"end stops (+-{stops['travel_mm']:g} mm) hit: {n_contact} samples in contact "
                   f"({n_contact / run.recording.fs_hz:.2f} s)")
    else:
        contact = f"end stops (+-{stops['travel_mm']:g} mm) not touched"
    print(f"wrote {out} ({run.recording.n_samples} samples at {run.recording.fs_hz:g} Hz) and {truth}; "
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
    p = argparse.ArgumentParser(prog="shakeid", description="Sparse nonlinear identification of shaker rigs")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True)
    q = sub.add_parser("identify", help="identify a sparse ODE model from a recording (CSV, MAT, HDF5)")
    q.add_argument("files", nargs="+", metavar="FILE",
                   help="a recording; several: one model fitted to all of them (joint identification)")
    _add_identify_options(q)
    from .ooc_cmd import add_out_of_core_options

    add_out_of_core_options(q)
    q.add_argument("--report", metavar="DIR", help="write figures, coefficient table and model JSON here")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    q.add_argument("--accept-faulty", action="store_true",
                   help="identify a recording that is not complete or whose quality flags make it unusable")
    q.set_defaults(func=cmd_identify)
    add_batch_parser(sub, _add_identify_options)
    q = sub.add_parser("explain", help="where a model misses the rig, which effect is missing, and the fix")
    q.add_argument("file")
    q.add_argument("--model", metavar="MODEL.json", help="baseline model (default: textbook Duffing fitted)")
    g = q.add_argument_group("recording layout")
    g.add_argument("--layout", choices=("base", "force"), default="base")
    g.add_argument("--input")
    g.add_argument("--output")
    g.add_argument("--time")
    g.add_argument("--fs", type=float)
    g.add_argument("--samples", type=int, nargs=2, metavar=("START", "STOP"))
    g.add_argument("--band", type=float, nargs=2, metavar=("F_LO", "F_HI"))
    q.add_argument("--accept-faulty", action="store_true",
                   help="analyse a recording that is not complete or whose quality flags make it unusable")
    q.add_argument("--report", metavar="DIR")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    q.set_defaults(func=cmd_explain)
    q = sub.add_parser("sweep", help="run a sweep on the rig of --config and record it to HDF5, or through a "
                                     "running shakeid serve (--server)")
    where = q.add_mutually_exclusive_group(required=True)
    where.add_argument("--config", metavar="RIG.toml", help="drive the rig directly")
    where.add_argument("--server", metavar="URL", help="through the HTTP service, e.g. http://127.0.0.1:8000")
    q.add_argument("--token", help="with --server: an operator token (default: $SHAKEID_TOKEN)")
    q.add_argument("--wait-model", action="store_true", help="with --server: wait for the model and print it")
    q.add_argument("--f-start-hz", type=float, required=True)
    q.add_argument("--f-end-hz", type=float, required=True)
    q.add_argument("--duration-s", type=float, required=True)
    q.add_argument("--amplitude-mm", type=float, required=True)
    q.add_argument("--settle-s", type=float, default=2.0)
    q.add_argument("--operator", default="")
    q.add_argument("--note", default="")
    q.add_argument("--out", metavar="FILE.h5", help="the recording (with --server: a copy, downloaded)")
    q.set_defaults(func=cmd_sweep)
    add_campaign_parser(sub)
    q = sub.add_parser("recordings", help="inspect HDF5 recordings (metadata, status, gaps)")
    q.add_argument("files", nargs="+")
    q.add_argument("--recover", action="store_true", help="mark recordings left running by a crash as aborted")
    q.add_argument("--process", action="store_true",
                   help="add processed signals: relative acceleration, velocity, displacement (/entry/processed)")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_recordings)
    q = sub.add_parser("rig", help="the PLC of --config directly (works while the service is wedged): status, "
                                   "reset, estop")
    q.add_argument("action", choices=("status", "reset", "estop"))
    q.add_argument("--config", metavar="RIG.toml", required=True, help="rig configuration: its [plc] section")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=cmd_rig)
    q = sub.add_parser("sim", help="run the simulated rig: PLC over Modbus TCP, accelerometer stream over TCP")
    q.add_argument("--config", metavar="RIG.toml", help="rig configuration (examples/sim-rig.toml)")
    q.add_argument("--host", help="listen address (default: the config's, else 127.0.0.1)")
    q.add_argument("--modbus-port", type=int, help="default: the config's [plc] port, else 5020")
    q.add_argument("--stream-port", type=int, help="default: the config's [stream] url port, else 5021")
    q.add_argument("--speed", type=float, help="rig seconds per wall second (PLC and streams; default 1)")
    q.set_defaults(func=cmd_sim)
    q = sub.add_parser("serve", help="the HTTP service: sweeps, recordings, models (FastAPI + uvicorn)")
    q.add_argument("--config", metavar="RIG.toml", help="rig + [server] configuration; none: embedded simulated rig")
    q.add_argument("--host", default="127.0.0.1")
    q.add_argument("--port", type=int, default=8000)
    q.add_argument("--data-dir", help="recordings, models, catalog (default: [server] data_dir, SHAKEID_DATA_DIR, "
                                      "./shakeid-data)")
    q.add_argument("--sim-speed", type=float, help="embedded simulated rig: rig seconds per wall second")
    q.add_argument("--log-level", default="warning", choices=("debug", "info", "warning", "error"))
    q.add_argument("--controller", metavar="ADDRESS",
                   help="attach to a rig controller that runs on its own (`shakeid controller`), e.g. "
                        "unix:/run/shakeid/controller.sock or tcp:127.0.0.1:8765 (default: start one as a child)")
    q.set_defaults(func=cmd_serve)
    q = sub.add_parser("controller", help="the rig controller process: sweeps, heartbeat, emergency stop (the "
                                          "service starts one itself; run it alone for a separate deployment)")
    q.add_argument("--config", metavar="RIG.toml", help="rig configuration; none: embedded simulated rig")
    q.add_argument("--data-dir", help="shared with the web server: catalog, recordings (default as serve)")
    q.add_argument("--address", help="where to listen (default unix:DATA_DIR/controller.sock)")
    q.add_argument("--sim-speed", type=float, help="embedded simulated rig: rig seconds per wall second")
    q.add_argument("--parent-pid", type=int, help=argparse.SUPPRESS)  # set by `shakeid serve` for its child
    q.set_defaults(func=cmd_controller)
    q = sub.add_parser("simulate", help="write a synthetic recording of the simulated rig (CSV + truth JSON)")
    q.add_argument("--out", required=True, metavar="FILE.csv")
    _add_sweep_options(q)
    q.set_defaults(func=cmd_simulate)
    q = sub.add_parser("demo", help="sweep the simulated rig over Modbus, record HDF5, identify, report")
    q.add_argument("--out", default="demo-output")
    q.add_argument("--f-start-hz", type=float, default=1.0)
    q.add_argument("--f-end-hz", type=float, default=20.0)
    q.add_argument("--duration-s", type=float, default=60.0)
    q.add_argument("--amplitude-mm", type=float, default=1.3)
    q.set_defaults(func=cmd_demo)
    return p




def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ShakeidError as exc:
        print(f"shakeid: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("shakeid: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
