"""`shakeid identify A.h5 B.h5 C.csv`: one model fitted to several recordings of the rig (identify.joint).

Every file is read and checked as a single `shakeid identify` would (same options, --accept-faulty
included), then fitted jointly. The table is the joint model's; below it one line per recording: its
band, the joint model's held-out free-run fit there, and its status ("inconsistent": the rig behaves
differently in that recording than one model of all of them allows); the model's predicted frequency
response beside every sweep's measured one (identify.frf.side_by_side), and --report writes the joint
report (reports.identification: the recordings' table, a panel per recording). Exit codes as for one
file: 0 a model, 2 data refused, 1 the joint model failed (its validation, or a recording is inconsistent).
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from identify.errors import ShakeidError

from .argtypes import file_and_samples
from .files import read_recording, write_report


def _refuse_twice(names: list, cuts: list) -> None:
    """A recording counted twice would shrink every standard error by sqrt(2): one file named twice (by any
    path to it) is refused, unless both name disjoint sample ranges of it (FILE[START:STOP]).
    cuts: (path, (start, stop) or None) per name."""
    seen: dict = {}
    for name, (path, rows) in zip(names, cuts):
        for other, other_rows in seen.get(os.path.realpath(path), []):
            overlap = rows is None or other_rows is None or (rows[0] < other_rows[1] and other_rows[0] < rows[1])
            if overlap:
                what = " (overlapping samples)" if rows and other_rows else ""
                raise ShakeidError(f"{name}: the same recording as {other}{what}; a joint fit takes each recording "
                                   "once (twice would count its evidence twice and shrink the standard errors)")
        seen.setdefault(os.path.realpath(path), []).append((name, rows))


def cmd_identify_joint(args, make_identifier) -> int:
    """`args.files` (two or more); make_identifier(args) as the single-file command's, each file read as it
    reads one (shakeid.files.read_recording)."""
    from identify.data.quality import check_identifiable

    if getattr(args, "chunked", False) or getattr(args, "chunk_samples", None):
        raise ShakeidError("--chunked identifies one recording out of core; a joint fit of several reads them "
                           "into memory (drop --chunked, or identify the files one by one)")
    cuts = [file_and_samples(name, getattr(args, "samples", None)) for name in args.files]
    _refuse_twice(args.files, cuts)
    ident = make_identifier(args)  # option errors first, before any file is read
    if args.report:
        from reports.html import check_report_folder

        check_report_folder(args.report, "identification")  # before the fit: a mistyped --report costs nothing
    recs, quality = [], []
    for path, (file, samples) in zip(args.files, cuts):
        args.file, args.samples = file, samples  # what read_recording reads: FILE[START:STOP] gives each its rows
        rec = read_recording(args)
        quality.append(check_identifiable(rec, path, args.accept_faulty))
        rec.source = path
        recs.append(rec)
    try:
        ident.fit(recs)
    except ValueError as exc:  # library/term specification problems
        raise ShakeidError(str(exc)) from None
    from identify.frf.side_by_side import identification_document  # all the sweeps beside the model's response

    result = identification_document(ident, recs, names=list(args.files))
    for section, q in zip(result["recordings"], quality):
        section.update(q)
    faulty = [f"{p}: {r}" for p, q in zip(args.files, quality) for r in q.get("accepted_faulty", [])]
    result["data_quality"] = {"usable_for_identification": not faulty, "reasons": faulty,
                              "assessed": "per recording (recordings[i].data_quality)"}
    if faulty:
        result["accepted_faulty"] = faulty
    replaced = write_report("identification", ident, args.report, result)
    if args.json:
        print(json.dumps(result))
    else:
        print(summary(result))
        for line in result["frf"]["flags"]:
            print(f"flagged: {line}")
        if args.report:
            print(f"report: {Path(args.report) / 'index.html'}{replaced}")
    if result["status"] == "failed":
        print(f"shakeid: identification failed: {len(args.files)} recordings: {result['reason']}", file=sys.stderr)
        return 1
    return 0


def summary(result: dict) -> str:
    """The joint model's table, its pooled held-out fit, and one line per recording."""
    from reports.text import coefficient_table, fit_text, unsettled_lines

    per = result["recordings"]
    lines = [f"identified {len(per)} recordings jointly: method {result['method']}, selection "
             f"{result['selection']['rule']}", ""]
    if result.get("accepted_faulty"):
        lines += ["accepted faulty data (--accept-faulty): " + "; ".join(result["accepted_faulty"]), ""]
    lines.append(coefficient_table(result))
    lines += unsettled_lines(result)
    val = result.get("validation")
    if val:
        h = val["heldout"]
        lines.append(f"free-run fit on {val['heldout_samples']} held-out samples of all recordings: acceleration "
                     f"{fit_text(h['q1_dot'])}, velocity {fit_text(h['q1'])}, displacement {fit_text(h['q2'])}")
    lines += ["", "| recording | samples | band Hz | held-out fit acc / vel / disp | NRMSE joint/alone disp, vel | status |",
              "|---|---:|---|---|---|---|"]
    for p in per:
        v = p.get("validation")
        fits = " / ".join(fit_text(v["heldout"][k]) for k in ("q1_dot", "q1", "q2")) if v else "-"
        ratio = p.get("nrmse_ratio_joint_to_alone") or {}
        rs = ", ".join("-" if ratio.get(k) is None else f"{ratio[k]:.2f}" for k in ("displacement", "velocity"))
        lines.append(f"| {p['source']} | {p['samples']} | {p['band_hz'][0]:.3g}-{p['band_hz'][1]:.3g} | {fits} | "
                     f"{rs or '-'} | {p['status']} |")
    for p in per:
        if p["reason"] and p["status"] != "ok":
            lines.append(f"{p['source']}: {p['status']}: {p['reason']}")
    return "\n".join(lines)
