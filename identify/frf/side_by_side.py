"""Predicted against measured frequency response, side by side, per table amplitude: what the
identification and explain reports, `shakeid identify --json` and the service's frf.json carry.

    doc = side_by_side({"model": model}, [rec_up, rec_down], fit_percent=99.1)
    doc["amplitudes"][0]["predicted"]["model"]      # FrequencyResponse.to_dict() at the recorded amplitude
    doc["amplitudes"][0]["measured"][0]             # the sweep's per-cycle envelope and its measured jump
    doc["jumps"], doc["flagged"], doc["flags"]      # measured vs predicted jump per sweep; the misses

Recordings are sweeps (sweep_envelope); those at table amplitudes within AMPLITUDE_GROUP of each other
share one predicted response (a campaign's up and down sweeps at one level), over the band their
envelopes cover. Each sweep's jump is judged by measured.compare_jump (the fold, the model's own
sweep-rate bias, the measured jump's uncertainty). A model that fits in the time domain but misses a
measured jump by more than that is flagged. Never raises for what a recording or model cannot give:
`status` "not_applicable" or "failed" with the reason (the identification it rides on must not fail).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ShakeidError
from .balance import check_model
from .measured import compare_jump, sweep_envelope
from .response import frequency_response

#: sweeps whose table amplitudes differ by less than this share of theirs share one predicted response
AMPLITUDE_GROUP = 0.05
#: a recording is read as a sweep when its cycles' frequency follows time at least this closely (|r|)
SWEEP_CORRELATION = 0.95
#: significant digits kept of the per-cycle envelope in the JSON
ENVELOPE_DIGITS = 6


def side_by_side(models: dict, recordings: list, fit_percent: float | None = None, judged: str | None = None,
                 names: list[str] | None = None, signals: list | None = None) -> dict:
    """`models`: {label: SparseModel} (the identified model; the explain report's baseline and fixed
    model); `recordings`: base-layout sweep recordings; `fit_percent`: the judged model's held-out
    time-domain fit (None: it failed its validation, so there is nothing to flag); `judged`: the label
    whose misses are flagged (default: the first); `names`: what to call each recording (default: its
    source); `signals`: each recording's chain states when already reconstructed (None: run the chain)."""
    judged = judged or next(iter(models))
    doc = {"status": "ok", "reason": None, "models": list(models), "judged": judged, "amplitudes": [],
           "jumps": [], "flagged": False, "flags": [], "skipped": []}
    try:
        for m in models.values():
            check_model(m)
    except ShakeidError as exc:
        return {**doc, "status": "not_applicable", "reason": str(exc)}
    envs = []
    for rec, name, sig in zip(recordings, names or [str(r.source) for r in recordings],
                              signals or [None] * len(recordings)):
        env, why = _sweep(rec, name, sig)
        if env is None:
            doc["skipped"].append({"source": name, "reason": why})
        else:
            envs.append(env)
    if not envs:
        reasons = "; ".join(s["reason"] for s in doc["skipped"]) or "no recording given"
        return {**doc, "status": "not_applicable", "reason": f"no sweep to compare with: {reasons}"}
    try:
        for group in _groups(envs):
            doc["amplitudes"].append(_amplitude(models, group, doc))
    except (ShakeidError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return _finite({**doc, "status": "failed", "reason": f"the frequency response failed: {exc}"})
    _flag(doc, fit_percent)
    return _finite(doc)


def _sweep(rec, name: str, sig=None):
    """(the recording's envelope, None) or (None, why it is not a sweep to compare with)."""
    try:
        env = sweep_envelope(rec, sig)
    except ShakeidError as exc:
        return None, str(exc).replace(str(rec.source), name)
    f, t = env["frequency_hz"], env["t_s"]
    r = float(np.corrcoef(t, f)[0, 1]) if f.size > 3 and np.ptp(f) > 0 else 0.0
    if not abs(r) >= SWEEP_CORRELATION:
        return None, (f"{name}: not a sine sweep (its cycles' frequency follows time with r = {r:.2f} < "
                      f"{SWEEP_CORRELATION}): no frequency response to read from it")
    env["source"] = name
    return env, None


def _groups(envs: list) -> list[list]:
    """Sweeps grouped by table amplitude (ascending), neighbours within AMPLITUDE_GROUP of each other."""
    envs = sorted(envs, key=lambda e: e["amplitude_mm"])
    groups = [[envs[0]]]
    for e in envs[1:]:
        if e["amplitude_mm"] - groups[-1][-1]["amplitude_mm"] <= AMPLITUDE_GROUP * e["amplitude_mm"]:
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def _amplitude(models: dict, group: list, doc: dict) -> dict:
    """One table amplitude: each model's response over the band the group's sweeps cover, each sweep's
    envelope and its jump against each model's fold (also appended to doc["jumps"])."""
    amp = float(np.mean([e["amplitude_mm"] for e in group]))
    band = (float(min(e["frequency_hz"].min() for e in group)), float(max(e["frequency_hz"].max() for e in group)))
    responses = {label: frequency_response(m, amp, band) for label, m in models.items()}
    entry = {"amplitude_mm": amp, "band_hz": list(band),
             "predicted": {label: r.to_dict() for label, r in responses.items()}, "measured": []}
    for env in group:
        cmps = {label: compare_jump(models[label], env, r) for label, r in responses.items()}
        measured = next(iter(cmps.values()))["measured"]
        entry["measured"].append({"source": env["source"], "direction": env["direction"],
                                  "rate_hz_per_s": env["rate_hz_per_s"], "amplitude_mm": env["amplitude_mm"],
                                  "frequency_hz": _digits(env["frequency_hz"]),
                                  "response_mm": _digits(env["response_mm"]), "jump": measured})
        doc["jumps"].append({
            "amplitude_mm": env["amplitude_mm"], "source": env["source"], "direction": env["direction"],
            "measured_hz": None if measured is None else measured["frequency_hz"],
            "uncertainty_hz": None if measured is None else measured["uncertainty_hz"],
            "predicted": {label: {"fold_hz": c["fold_hz"], "bias_hz": c["bias_hz"], "miss_hz": c.get("miss_hz"),
                                  "model_sweep_jump_hz": (c["model_sweep_jump"] or {}).get("frequency_hz"),
                                  "agrees": c["agrees"]} for label, c in cmps.items()}})
    return entry


def _flag(doc: dict, fit_percent: float | None) -> None:
    """Flag the judged model's misses when it fits in the time domain (fit_percent given)."""
    if fit_percent is None:
        return
    for j in doc["jumps"]:
        p = j["predicted"][doc["judged"]]
        if p["agrees"] is not False:
            continue
        what = "jump-down (up-sweep)" if j["direction"] == "up" else "jump-up (down-sweep)"
        if j["measured_hz"] is None:
            text = (f"the sweep shows no jump, the model predicts its {what} at {_hz(p['fold_hz'] or p['model_sweep_jump_hz'])} Hz")
        elif p["fold_hz"] is None and p["model_sweep_jump_hz"] is None:
            text = f"the sweep jumps at {j['measured_hz']:.3f} ± {j['uncertainty_hz']:.3f} Hz, the model predicts no {what}"
        else:
            bias = "" if p["bias_hz"] is None else f", sweep-rate bias {p['bias_hz']:+.3f} Hz"
            ref = (f"fold {_hz(p['fold_hz'])} Hz{bias}" if p["fold_hz"] is not None
                   else f"its own sweep jumps at {_hz(p['model_sweep_jump_hz'])} Hz")
            text = (f"measured {what} at {j['measured_hz']:.3f} ± {j['uncertainty_hz']:.3f} Hz, predicted {ref}: "
                    f"missed by {p['miss_hz']:.3f} Hz, more than the measurement's uncertainty")
        doc["flags"].append(f"{j['source']} ({j['amplitude_mm']:.3g} mm, {j['direction']}): the model fits in the "
                            f"time domain (held-out fit {fit_percent:.1f} %) but misses the jump: {text}")
    doc["flagged"] = bool(doc["flags"])


def _hz(f) -> str:
    return "-" if f is None else f"{f:.3f}"


def _digits(x) -> list:
    return [float(f"{v:.{ENVELOPE_DIGITS}g}") for v in np.asarray(x, float)]


def _finite(obj):
    """JSON-safe: numpy scalars to Python, non-finite floats to None (strict JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def for_identification(result: dict, model, recordings: list, names: list[str] | None = None,
                       signals: list | None = None) -> dict:
    """The side-by-side an identification's document carries (its "frf"): the model is judged (flagged)
    only when it passed its time-domain validation. Whatever goes wrong is recorded, never raised: the
    identification it rides on stands without it."""
    heldout = ((result.get("validation") or {}).get("heldout") or {}).get("q1_dot") or {}
    fit = heldout.get("fit_percent") if result.get("status") != "failed" else None
    return _guarded(lambda: side_by_side({"model": model}, recordings, fit, names=names, signals=signals))


def identification_document(ident, recordings: list, quality: dict | None = None,
                            names: list[str] | None = None) -> dict:
    """What an identification delivers (model.json, `shakeid identify --json`, the demo's report): the fitted
    SparseIdentifier's result, the data's quality verdict (identify.data.quality.check_identifiable's), and the
    predicted frequency response beside the measured sweeps. One sequence for the CLI, the demo and the
    service's jobs, for one recording or a joint fit's several. The sweeps are read from the
    identification's own chain states when it fitted exactly `recordings` in memory (the chain is the CLI's
    largest cost beside the fit: not run twice)."""
    result = {**ident.result(), **(quality or {})}
    fitted = getattr(ident, "recordings_", [])
    own = (len(fitted) == len(recordings) and all(a is b for a, b in zip(fitted, recordings))
           and all(s.in_core for s in ident.sources_))
    result["frf"] = for_identification(result, ident.model_, recordings, names,
                                       [s.sig for s in ident.sources_] if own else None)
    return result


def for_explanation(result: dict, baseline, fixed, recordings: list, names: list[str] | None = None) -> dict:
    """The explain report's side-by-side: the baseline and, when an effect was added, the baseline with
    it (judged, by its held-out free-run fit)."""
    models = {"baseline": baseline}
    if result.get("effects"):
        models["+ " + ", ".join(e["name"] for e in result["effects"])] = fixed
    which = "after" if len(models) > 1 else "before"
    heldout = (((result.get("validation") or {}).get(which) or {}).get("heldout") or {}).get("q1_dot") or {}
    return _guarded(lambda: side_by_side(models, recordings, heldout.get("fit_percent"), judged=list(models)[-1],
                                         names=names))


def _guarded(make) -> dict:
    try:
        return make()
    except Exception as exc:  # noqa: BLE001 -- the identification must not fail for its frequency response
        return {"status": "failed", "reason": f"the frequency response failed: {type(exc).__name__}: {exc}",
                "amplitudes": [], "jumps": [], "flagged": False, "flags": []}
