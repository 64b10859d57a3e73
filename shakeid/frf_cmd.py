"""`shakeid frf MODEL.json --amplitude-mm A [A ...] [--band F_LO F_HI] [--json] [--report DIR]`: the
model's predicted nonlinear frequency response per table amplitude (identify.frf, docs/frf.md).

MODEL.json is what `shakeid identify --json` prints, a report's or the service's model.json, or a bare
model file. Human output: one line per amplitude (jumps, largest response, harmonics) and the notes;
--json prints one document {"jumps": [...], "responses": [...], "backbone": {...}}.
"""
from __future__ import annotations

import json
from pathlib import Path

from identify.errors import ShakeidError

from .argtypes import positive
from .model_arg import add_model_arguments, read_model

#: The backbone reaches this much beyond the largest predicted response.
BACKBONE_MARGIN = 1.1


def add_frf_parser(sub) -> None:
    q = sub.add_parser("frf", help="predicted nonlinear frequency response of a model: branches, stability, jumps, backbone")
    add_model_arguments(q, "use")
    q.add_argument("--amplitude-mm", type=positive, nargs="+", required=True, metavar="A",
                   help="table displacement amplitude(s), mm peak (z = A sin 2 pi f t)")
    q.add_argument("--band", type=positive, nargs=2, metavar=("F_LO", "F_HI"),
                   help="frequency band, Hz (default: 0.25-4 x the model's linear natural frequency)")
    q.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    q.add_argument("--report", metavar="DIR", help="write frf.png, frf.json and index.html to DIR")
    q.set_defaults(func=cmd_frf)


def frf_document(model, amplitudes_mm, band_hz=None) -> dict:
    """The JSON document: jumps per amplitude, each response (identify.frf.FrequencyResponse.to_dict), the
    backbone up to BACKBONE_MARGIN x the largest response."""
    from identify.frf import backbone, frequency_response

    responses = [frequency_response(model, a, band_hz) for a in amplitudes_mm]
    peak = max(max(max(b["amplitude_mm"]) for b in r.branches) for r in responses)
    return {"band_hz": list(responses[0].band_hz),
            "jumps": [{"amplitude_mm": r.amplitude_mm, "jump_down_hz": r.jump_down_hz, "jump_up_hz": r.jump_up_hz}
                      for r in responses],
            "responses": [r.to_dict() for r in responses],
            "backbone": backbone(model, BACKBONE_MARGIN * peak, max(r.harmonics for r in responses))}


def cmd_frf(args) -> int:
    from reports.html import check_report_folder

    if args.band and not args.band[0] < args.band[1]:
        raise ShakeidError(f"--band {args.band[0]:g} {args.band[1]:g}: F_LO must be below F_HI")
    if args.report:
        check_report_folder(args.report, "frf")  # before the work
    from identify.frf.balance import check_model

    model = read_model(args, "use", check_model)
    doc = frf_document(model, args.amplitude_mm, tuple(args.band) if args.band else None)
    doc["model_file"] = str(args.model)
    if args.report:
        from reports.frf import write_frf_report
        out = write_frf_report(doc, args.report, Path(args.model).name)
        doc["report"] = str(out / "index.html")
    if args.json:
        print(json.dumps(doc))
        return 0
    print(f"frequency response of {args.model}, band {doc['band_hz'][0]:.3g}-{doc['band_hz'][1]:.3g} Hz "
          "(steady state; a sweep jumps later by its sweep-rate bias; harmonics: how many the balance\n"
          "needed to converge, docs/frf.md)")
    print(f"{'table mm':>9} {'jump down Hz':>13} {'jump up Hz':>11} {'peak mm':>9} {'harmonics':>9}")
    for r in doc["responses"]:
        peak = max(max(b["amplitude_mm"]) for b in r["branches"])
        down = "-" if r["jump_down_hz"] is None else f"{r['jump_down_hz']:.4f}"
        up = "-" if r["jump_up_hz"] is None else f"{r['jump_up_hz']:.4f}"
        print(f"{r['amplitude_mm']:>9g} {down:>13} {up:>11} {peak:>9.3f} {r['harmonics']:>9}")
        for note in r["notes"]:
            print(f"  {r['amplitude_mm']:g} mm: {note}")
    if args.report:
        print(f"report: {doc['report']}")
    return 0
