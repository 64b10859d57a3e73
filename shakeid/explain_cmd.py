"""`shakeid explain`: where a model misses the rig, which effect is missing, and the fix; of recordings on
disk (one or several: one explanation over all), or of a campaign a running service recorded (--server
URL --campaign ID: the service's explanation, asked for and awaited where it has none yet). Both print the
same summary (print_explanation) or the same JSON (--json)."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from daq.formats import NAMES as FORMAT_NAMES
from identify.errors import IdentificationError, ShakeidError
from reports.text import gap_closed_text, model_text, p_value_text

from .argtypes import file_and_samples
from .files import add_layout_options, naming, read_recording, write_report

#: how often the state of the service's explanation job is asked for, s
POLL_S = 1.0


def add_explain_parser(sub) -> None:
    q = sub.add_parser("explain", help="where a model misses the rig, which effect is missing, and the fix")
    q.add_argument("files", nargs="*", metavar="FILE",
                   help=f"the recording ({FORMAT_NAMES}); FILE[START:STOP]: its samples [START, STOP) only; several "
                        "recordings of one rig (an up and a down sweep, several amplitudes): one explanation over all")
    q.add_argument("--model", metavar="MODEL.json",
                   help="baseline model, e.g. model.json of an identify --report (default: the textbook Duffing, "
                        "fitted to the data)")
    add_layout_options(q)
    q.add_argument("--accept-faulty", action="store_true",
                   help="analyse a recording that is not complete or whose quality flags make it unusable")
    q.add_argument("--report", metavar="DIR", help="write index.html, figures and explain.json here (default: none)")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    remote = q.add_argument_group("a campaign recorded by a running service")
    remote.add_argument("--server", metavar="URL", help="the service, e.g. http://127.0.0.1:8000")
    remote.add_argument("--campaign", metavar="ID", help="with --server: the campaign whose recordings are explained "
                        "together (the service's latest explanation; asked for and awaited if it has none)")
    remote.add_argument("--token", help="with --server: an operator token, to ask for an explanation (default: "
                        "$SHAKEID_TOKEN)")
    q.set_defaults(func=cmd_explain)


def cmd_explain(args) -> int:
    if args.server or args.campaign:
        return _explain_campaign_remote(args)
    if not args.files:
        raise ShakeidError("explain needs recordings (FILE ...), or --server URL --campaign ID for a service's campaign")
    from identify.explain.workflow import DiscrepancyAnalysis
    from identify.data.quality import check_identifiable

    names, samples = list(args.files), getattr(args, "samples", None)
    cuts = [file_and_samples(name, samples) for name in names]
    baseline = _baseline(args.model) if args.model else None
    if args.report:
        from reports.html import check_report_folder

        check_report_folder(args.report, "explain")  # before the analysis
    if len(names) > 1:  # one file twice (by any path, overlapping ranges) would count its evidence twice
        from .joint_cmd import _refuse_twice

        _refuse_twice(names, cuts)
    recs, data = [], None
    for name, (args.file, args.samples) in zip(names, cuts):  # several: one explanation (identify.explain.several)
        rec = read_recording(args)
        if len(names) > 1:
            rec.source = name  # as the operator named it (FILE[START:STOP] included)
        quality = check_identifiable(rec, args.file, args.accept_faulty,  # as identify: no analysis of unusable data
                                     "use --accept-faulty to analyse it anyway")
        recs.append(rec)
        data = data or quality  # the first recording's, as the document has always said (each is checked)
    try:
        analysis = DiscrepancyAnalysis(baseline=baseline, band_hz=tuple(args.band) if args.band else None).fit(recs)
    except IdentificationError as exc:
        raise (naming(args.file, exc) if len(recs) == 1 else ShakeidError(str(exc))) from None
    result = {**analysis.result(), **data}
    from identify.frf.side_by_side import for_explanation  # the jumps before/after beside the sweep's

    result["frf"] = for_explanation(result, analysis.baseline_model_, analysis.model_, recs)
    replaced = write_report("explain", analysis, args.report, result)
    if args.json:
        print(json.dumps(result))
        return 0
    print_explanation(result)
    if args.report:
        print(f"report: {Path(args.report) / 'index.html'}{replaced}")
    return 0


def _explain_campaign_remote(args) -> int:
    """--server URL --campaign ID: the service's latest explanation of the campaign; where it has none (or its
    last attempt failed), one is asked for (POST /api/campaigns/{id}/explain, an operator's token); one
    queued or running is followed until it ends, its state printed as it changes (on stderr with --json)."""
    from .remote import ServiceClient

    if not (args.server and args.campaign):
        raise ShakeidError("a service's campaign is explained with both --server URL and --campaign ID")
    if args.files or args.model or args.report:
        raise ShakeidError("--server --campaign explains the campaign's own recordings with the service's baseline; "
                           "FILE, --model and --report are for recordings on disk")
    client = ServiceClient.for_args(args, "an operator's, to ask for an explanation")
    where = f"/api/campaigns/{args.campaign}"
    say = (lambda text: print(text, file=sys.stderr, flush=True)) if args.json else \
        (lambda text: print(text, flush=True))  # noqa: E731
    job = client.request("GET", where)["explanation"]  # its newest explanation job, or None
    if job is None or job["state"] == "failed":
        job = client.request("POST", f"{where}/explain")
        say(f"explanation of campaign {args.campaign} asked for: job {job['id']}, "
            f"{len(job['options']['recording_ids'])} recordings")
    job = _follow(client, job, say)
    if job["state"] != "completed":
        raise ShakeidError(f"the explanation of campaign {args.campaign} (job {job['id']}) {job['state']}: "
                           f"{job.get('error')}")
    result = client.request("GET", f"{where}/explanation")
    if args.json:
        print(json.dumps(result))
        return 0
    print_explanation(result)
    return 0


def _follow(client, job: dict, say) -> dict:
    """The job once it has left queued/running, its state said as it changes (a job waits behind every
    recording's own identification; the service runs them one after another)."""
    seen = None
    while job["state"] in ("queued", "running"):
        if job["state"] != seen:
            seen = job["state"]
            say(f"job {job['id']}: {seen}")
        time.sleep(POLL_S)
        job = client.request("GET", f"/api/jobs/{job['id']}")
    return job


def print_explanation(result: dict) -> None:
    """The explanation's summary for a person: the gap, where it is largest, the candidates, the effects
    named and the model after; several recordings each with their own gap first."""
    f = lambda v: "n/a" if v is None else f"{v:.4f}"  # noqa: E731
    recordings = result.get("recordings") or []
    if len(recordings) > 1:
        print(f"{len(recordings)} recordings explained together:")
        for r in result["recordings"]:
            print(f"  {r['source']}: {r['duration_s']:.1f} s, sweep rank correlation with time {r['sweep_rho']:+.2f}, "
                  f"gap {f(r['gap_before'])} -> {f(r['gap_after'])} (its floor {f(r['noise_floor'])})")
    print(f"baseline: {result['baseline']['source']}; {result['metric']}: {f(result['gap_before'])}"
          f" (sensor-noise floor <= {f(result['noise_floor'])})")
    worst = result["localisation"]["time"]["worst_window"]
    where = result["localisation"].get("recording", "the recording")
    print(f"largest misfit: {_span(worst)} into {where}, excitation {worst['excitation_hz']:.1f} Hz")
    print("candidates (equation-error share: of the held-out equation error it explains; shooting gap closed: "
          "1 - gap after² / gap before²):")
    for c in result["candidates"]:
        closed = c.get("gap_share_closed")
        p = p_value_text(c["p_value"])  # physics: Wald; a measurement fault: its own test
        print(f"  {c['name']:32s} equation-error share {c['score']:+.3f}  p {p if p[0] == '<' else '= ' + p}  "
              f"shooting gap closed {gap_closed_text(closed)}"
              + (f"  (rejected: {c['rejected']})" if c.get("rejected") else ""))
    if result["effect"] in ("none", "unexplained"):
        print(f"missing effect: {result['effect']} (confidence {result['confidence']:.2f})")
        for e in result["effects"]:  # a drifting sensor bias does not explain a gap, but is still there
            print(f"also: {e['name']} ({e['kind']}): {e.get('evidence', '')}")
    else:
        for e in result["effects"]:
            sur = f"; stands in for {', '.join(e['surrogate_for'])}" if e["surrogate_for"] else ""
            coefs = ", ".join(f"{t} {c:.4g}" for t, c in e["coefficients"].items())
            print(f"missing effect: {e['name']} ({e['kind']}{'; ' + coefs if coefs else ''}) (confidence "
                  f"{e['confidence']:.2f}; gap after {f(e['gap_after'])}{sur})")
            if e.get("evidence"):
                print(f"  {e['evidence']}")
        print(f"gap {f(result['gap_before'])} -> {f(result['gap_after'])}")
        print("model: " + model_text(result["model"]) + " (in full: --json)")
    if result.get("remaining"):
        top = result["remaining"]["segments"][0]
        print(f"still missed most at {_span(top)} "
              f"(excitation {top['excitation_hz']:.1f} Hz, {100 * top['share_of_error']:.0f} % of the error)")


def _span(window: dict) -> str:
    """"t = 16.4-17.9 s" of a window (t_start_s, t_end_s), to 0.01 s when it is shorter than a second (a
    short record's windows read "2.2-2.2 s" to 0.1 s)."""
    a, b = window["t_start_s"], window["t_end_s"]
    digits = 1 if b - a >= 1 else 2
    return f"t = {a:.{digits}f}-{b:.{digits}f} s"


def _baseline(model_path):
    """The baseline model of `explain --model`, read once. One whose own identification failed (its
    `status` in an identify --json / model.json) is analysed as asked, with a warning first: its misfit is
    as much the fit's failure as missing physics."""
    from identify.model import SparseModel, read_document

    doc = read_document(model_path)
    model = SparseModel.from_dict(doc)
    if doc.get("status") == "failed":
        print(f"shakeid: warning: {model_path} is a model whose identification failed ({doc.get('reason', '')}); "
              "its misfit is as much that failure as any missing effect", file=sys.stderr)
    return model
