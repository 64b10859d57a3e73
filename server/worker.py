"""What an identification or explanation job does, in a worker process (no service state here).

A job's result is delivered whole or not at all: the report is written into a staging folder
(report.partial, wiped first), then the result file (catalog.RESULT_FILES: model.json, the object
`shakeid identify --json` prints; explain.json; joint.json) atomically, then the staging folder is renamed
to report. A job run again (re-queued after a restart) whose result file is there adopts it: it finishes
the rename if it was cut short and returns the same summary, without fitting again.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from identify.errors import ShakeidError

from .catalog import RESULT_FILES
from .schemas import IdentifyIn, ReadOptions


def die_with_parent(parent_pid: int, workers: int = 1) -> None:
    """Pool initializer: the worker exits when the service that started it is gone (even after a
    SIGKILL, which gives the service no chance to stop its pool): a job left behind would hold memory
    and its files for nobody, and the catalog re-queues it on the next start anyway. Also: batch work
    runs at a lower CPU priority (nice +10), so the web server and the rig controller keep the cores.
    And a terminal's Ctrl-C, which reaches the whole process group, is the service's to handle: a worker
    ignores SIGINT (it printed a KeyboardInterrupt traceback per worker; the service stops its pool).
    An explanation's shooting runs take this worker's share of the cores (identify.threads.share_cores:
    `workers` processes side by side)."""
    import signal

    from identify.threads import share_cores

    share_cores(workers)
    import threading
    import time

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(10)

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(0)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def warm_up() -> bool:
    """Import the numerical stack once, so the first real job does not pay for it."""
    import matplotlib  # noqa: F401

    import identify.identifier  # noqa: F401
    import reports.identification  # noqa: F401
    return True


def _write_json(path: Path, obj) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(obj, indent=2))
    os.replace(tmp, path)  # readers see the old file or the whole new one, never half of it


def read(path: str, options: dict):
    """The recording at path with the job's read options (as `shakeid identify`'s)."""
    from daq.formats import open_recording

    return open_recording(path, options.get("layout", "base"), options.get("input"), options.get("output"),
                          options.get("time"), options.get("fs_hz"),
                          tuple(options["samples"]) if options.get("samples") else None)


#: SparseIdentifier parameters a job may set: the identify body's own fields (schemas.IdentifyIn)
IDENTIFY_KEYS = tuple(sorted(set(IdentifyIn.model_fields) - set(ReadOptions.model_fields)))


#: job kinds over several recordings: the job's path is a list (options.recording_ids names them, in order)
SEVERAL_KINDS = ("identify_joint", "explain_campaign")


def run_job(kind: str, path, options: dict, out_dir: str) -> dict:
    """Run one job; returns a short summary for the catalog. ShakeidError -> a message for the user.
    kind "identify_joint": path is a list of recordings' paths, fitted as one model (identify.joint);
    "explain_campaign": a list explained together (identify.explain.several), as "explain" explains one."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if (out / RESULT_FILES.get(kind, "-")).is_file():
        return _adopt(kind, out)
    shutil.rmtree(out / STAGING, ignore_errors=True)  # an interrupted run's half-written report
    if kind == "identify_joint":
        return _run_joint(list(path), options, out)
    paths = list(path) if kind in SEVERAL_KINDS else [path]
    try:
        # data that cannot carry a model is refused, as by the CLI (the job fails, saying why)
        recs, data = _read_checked(paths, options, "identify" if kind == "identify" else "analyse")
        if kind == "identify":
            from identify.frf.side_by_side import identification_document
            from identify.identifier import SparseIdentifier
            from reports.identification import write_report

            rec = recs[0]
            params = {k: options[k] for k in IDENTIFY_KEYS if options.get(k) is not None}
            if options.get("band_hz"):
                params["band_hz"] = tuple(options["band_hz"])
            ident = SparseIdentifier(**params).fit(rec)
            result = identification_document(ident, [rec], data, [_label(path, options)])
            if result["status"] == "failed":  # no model.json: what was fitted is not a model of the rig
                raise ShakeidError(f"{_label(path, options)}: identification failed: {result['reason']}")
            _write_json(out / FRF_FILE, result["frf"])
            write_report(ident, out / STAGING, result)
            _write_json(out / "model.json", result)
            return _adopt(kind, out)
        if kind in ("explain", "explain_campaign"):
            return _explain(kind, recs, data, [_label(p, options) for p in paths], options, out)
        raise ShakeidError(f"unknown job kind {kind!r}")
    except (ShakeidError, ValueError) as exc:  # the user's input: a message, not a traceback
        raise ShakeidError(_public(str(exc), paths, options)) from None


def _read_checked(paths: list, options: dict, verb: str) -> tuple[list, dict]:
    """The recordings at paths, each read with its stored read options under the request's
    (options["read_options_by_recording"], in order; for one recording they are merged when queued) and
    checked as the CLI checks them (check_identifiable: refused unless accept_faulty); several are named
    by _label. Returns them and the first one's quality, as the CLI's document gives it."""
    from identify.data.quality import check_identifiable

    stored = options.get("read_options_by_recording") or [{}] * len(paths)
    recs, data = [], None
    for p, own in zip(paths, stored):
        rec = read(p, {**own, **options})  # as uploaded, the request's read options over that
        if len(paths) > 1:
            rec.source = _label(p, options)
        quality = check_identifiable(rec, _label(p, options), bool(options.get("accept_faulty")),
                                     f"set accept_faulty to {verb} it anyway")
        recs.append(rec)
        data = data or quality
    return recs, data


def _explain(kind: str, recs: list, data: dict, names: list[str], options: dict, out: Path) -> dict:
    """One discrepancy analysis of one recording or several together (`shakeid explain A [B ...]`):
    explain.json and its report (the one path of the "explain" and "explain_campaign" jobs)."""
    from identify.explain.workflow import DiscrepancyAnalysis
    from identify.frf.side_by_side import for_explanation
    from reports.explain import write_explain_report

    analysis = DiscrepancyAnalysis(band_hz=tuple(options["band_hz"]) if options.get("band_hz") else None)
    result = {**analysis.fit(recs if len(recs) > 1 else recs[0]).result(), **data}
    # before/after the named effect beside the sweep, as `shakeid explain` (never fails the job)
    result["frf"] = for_explanation(result, analysis.baseline_model_, analysis.model_, recs, names)
    write_explain_report(analysis, out / STAGING, result["frf"])
    _write_json(out / "explain.json", result)
    return _adopt(kind, out)


#: where a job writes its report before the result file is there (then renamed to "report")
STAGING = "report.partial"
#: the predicted frequency response beside the measured sweeps, written beside model.json
FRF_FILE = "frf.json"


def frf_beside(out: Path, result: dict, model, recs: list, names: list[str]) -> dict:
    """The side-by-side frequency response of an identification (identify.frf.side_by_side, the one
    `shakeid identify --json` carries), also written to FRF_FILE before the result file. It never fails
    the job: whatever goes wrong is its status and reason. Its cost is one frequency response per table
    amplitude over the band the sweeps cover and one free run of the model per sweep."""
    from identify.frf.side_by_side import for_identification

    doc = for_identification(result, model, recs, names)
    _write_json(out / FRF_FILE, doc)
    return doc


def _adopt(kind: str, out: Path) -> dict:
    """The summary of the result delivered in `out` (its result file is there, whole); a staged report is
    moved into place first. A joint fit that failed fails its job again, with the same reason."""
    result = json.loads((out / RESULT_FILES[kind]).read_text())
    if (out / STAGING).is_dir():
        shutil.rmtree(out / "report", ignore_errors=True)
        os.replace(out / STAGING, out / "report")
    if kind in ("explain", "explain_campaign"):
        summary = {"effect": result["effect"], "gap_before": result["gap_before"], "gap_after": result["gap_after"]}
        return summary if kind == "explain" else {**summary, "recordings": [r["source"] for r in result["recordings"]]}
    terms = {eq: sorted(t) for eq, t in result["model"].items()}
    if kind == "identify_joint":
        if result["status"] == "failed":
            raise ShakeidError(f"joint identification of {len(result['recordings'])} recordings failed: "
                               f"{result['reason']}")
        return {"terms": terms, "recordings": {r["source"]: r["status"] for r in result["recordings"]}}
    val = (result.get("validation") or {}).get("heldout", {}).get("q1_dot", {})
    return {"terms": terms, "fit_percent": val.get("fit_percent"), "accepted_faulty": result.get("accepted_faulty", [])}


def _run_joint(paths: list, options: dict, out: Path) -> dict:
    """One model of several recordings (a campaign's, at its end). joint.json is written whatever the
    verdict (its `recordings` section says which recording one model does not explain); model.json only
    for a model that passed, as for one recording; a failed joint model fails the job with the reason."""
    from identify.identifier import SparseIdentifier

    try:
        recs, _ = _read_checked(paths, options, "identify")
        params = {k: options[k] for k in IDENTIFY_KEYS if options.get(k) is not None}
        if options.get("band_hz"):
            params["band_hz"] = tuple(options["band_hz"])
        ident = SparseIdentifier(**params)
        result = ident.fit(recs).result()
        if result["status"] != "failed":
            result["frf"] = frf_beside(out, result, ident.model_, recs, [r.source for r in recs])
            if result["frf"]["status"] == "ok":  # the campaign's overlay, moved into report/ by _adopt
                _campaign_overlay(out, result["frf"])
            _write_json(out / "model.json", result)
        _write_json(out / "joint.json", result)  # last: the result file (catalog.RESULT_FILES)
        return _adopt("identify_joint", out)
    except (ShakeidError, ValueError) as exc:
        raise ShakeidError(_public(str(exc), paths, options)) from None


def _campaign_overlay(out: Path, frf: dict) -> None:
    """The campaign's overlay figure (reports.frf_overlay) in the staging folder; a figure that cannot be
    drawn is said in frf.json, never a failed job."""
    from reports.frf_overlay import OVERLAY_FIGURE, overlay_figure

    try:
        (out / STAGING).mkdir(exist_ok=True)
        overlay_figure(frf, out / STAGING / OVERLAY_FIGURE)
    except Exception as exc:  # noqa: BLE001 -- the joint model stands without its figure
        frf["figure_error"] = f"{type(exc).__name__}: {exc}"
        _write_json(out / FRF_FILE, frf)


def _label(path, options: dict) -> str:
    """A recording as the operator knows it: the name the queue gave it (options["display_names"],
    {path: name}: an upload as uploaded, "short.csv (recording 470613d7dd6e)"), else its file name in the
    store, never the server's absolute path."""
    return (options.get("display_names") or {}).get(str(path), Path(path).name)


def _public(message: str, paths, options: dict) -> str:
    """A job's error as the operator sees it: each recording's absolute path replaced by its _label."""
    named = False
    for p in paths:
        named = named or str(p) in message or _label(p, options) in message
        message = message.replace(str(p), _label(p, options))
    if not named and len(paths) == 1:  # an option's error ("band ... must satisfy"): which recording's job
        message = f"{_label(paths[0], options)}: {message}"
    return message
