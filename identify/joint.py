"""Joint identification: one model fitted to several recordings of the same rig (a campaign's sweeps
at several amplitudes, repeats over weeks).

    ident = SparseIdentifier().fit([rec_a, rec_b, rec_c])
    ident.result()["recordings"]   # per recording: band, held-out free-run fit, its own status

What is summed, what stays per recording:
- the measurement chain runs per recording (identify.chain: its own excited band, tapers, valid rows);
- each recording gets its own held-out blocks (identifier.holdout_blocks: the same share, spread over
  its own sweep, so every recording's resonance feeds both fit and validation);
- the per-block normal equations of all recordings are stacked into one BlockGram (gram.concatenate):
  path, selection, all-rows refit and inclusion probabilities run unchanged on the summed normal
  equations; the block-robust standard errors pair neighbouring blocks only within a recording
  (uncertainty.refit_all_rows), and the SIMEX chain bias adds fresh noise to every recording and refits
  on their summed Gram (uncertainty.chain_bias with lists);
- the free run is validated per recording, each on its own held-out blocks from its own initial state
  (a recording is a separate experiment), and overall on all held-out rows pooled.

Change between recordings (one model cannot explain all levels): each recording is also identified
alone (same path and selection on its own blocks), and the joint terms are refit on its blocks alone.
A recording is "inconsistent" when both
- statistically: its own refit of a q1_dot term differs from the joint coefficient by more than
  Z_CHANGE of its block-robust standard errors (coefficient_z; sensor noise alone does not do that), and
- practically: the joint model fails its validation there while the recording's own model passes
  (validation.model_verdict), or the joint model's held-out free-run NRMSE of the displacement or
  velocity is above CHANGE_FLOOR and more than CHANGE_RATIO times the recording's own model's;
"failed" when the joint model fails there and the recording's own model fails too. One rig at three
levels and 0.5-5 % noise: |z| <= 4.7, NRMSE ratios up to 2.6 (at errors of 0.01); a stiffness 1 % off
in one recording: |z| 17-36 at 0.5 % noise (benchmarks/joint_change.py, docs/identification.md).
Which recording of a set changed is not told by this: the joint fit is a compromise, and with a large
change every recording disagrees with it; the largest z says which terms moved.

budget="free-run" and refine="free-run" run on the summed normal equations too, their free-run errors
pooled over the recordings, each simulated from its own start on its own fit (or held-out) rows
(identify.refine.PooledFreeRunError): a second recording at other amplitudes is more data for what the
free run extrapolates (Silverbox with its zip's second record, docs/identification.md).

Refused for several recordings (IdentificationError): holdout_samples (the paper's split of one
record) and a force with an even part (its displacement below the band is carried per record,
identify.inband).
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from . import uncertainty as unc
from .chain import reconstruct_states
from .errors import IdentificationError
from .gram import BlockGram
from .inband import has_even_force
from .library import Library
from .model import SparseModel
from .validation import SIGNALS, first_equation, fit_metrics, fit_verdict, model_verdict, validate

#: |own - joint| / own SE of a q1_dot coefficient above which a recording's rig differs (with the practical
#: condition below). One rig, 54 recordings at 0.5-5 % noise: at most 4.7 (benchmarks/joint_change.py).
Z_CHANGE = 6.0
#: Joint model's held-out free-run NRMSE (displacement, velocity) over the recording's own model's above
#: which the difference matters for the motion (with CHANGE_FLOOR). One rig: up to 2.6, at NRMSE ~0.01.
CHANGE_RATIO = 2.0
#: ... and only when the joint model's NRMSE is above this (a ratio of two tiny errors means nothing).
CHANGE_FLOOR = 0.05
COMPARED = ("q2", "q1")


def _refuse_copies(recordings: list) -> None:
    """A recording given twice, under any name (a copied file, an upload made twice), would count its
    evidence twice and shrink every standard error by sqrt(2): refused when two hold the same samples
    (a digest of each one's input and output; ~10 ms for a million samples)."""
    seen: dict[bytes, str] = {}
    for r in recordings:
        digest = hashlib.sha1(np.ascontiguousarray(r.input).tobytes())
        digest.update(np.ascontiguousarray(r.output).tobytes())
        key = digest.digest()
        if key in seen:
            raise IdentificationError(f"{r.source} holds the same samples as {seen[key]} (a copy?): a joint fit takes "
                                      "each recording once (twice would count its evidence twice and shrink the "
                                      "standard errors)")
        seen[key] = r.source


def fit_joint(ident, recordings: list):
    """SparseIdentifier.fit for several recordings (see the module doc); sets the identifier's usual
    fitted attributes (model_, standard_errors_, validation_, verdict_, ...) plus recordings_,
    joint_states_ and joint_ (the per-recording account)."""
    if not recordings:
        raise IdentificationError("no recordings to identify")
    if ident.holdout_samples is not None:
        raise IdentificationError(f"joint identification of {len(recordings)} recordings does not take "
                                  "holdout_samples (the first N samples of one record); identify the recordings "
                                  "one by one for it")
    _refuse_copies(recordings)
    timings = {}
    t0 = time.perf_counter()
    sigs = [reconstruct_states(r, ident.band_hz, ident.harmonics, ident.taper_s) for r in recordings]
    timings["chain"] = time.perf_counter() - t0
    inputs = {s.input_name for s in sigs}
    if len(inputs) != 1 or len({r.layout for r in recordings}) != 1:
        raise IdentificationError("joint identification needs recordings of one layout: got "
                                  + ", ".join(f"{r.source} ({r.layout})" for r in recordings))
    from .identifier import effective_samples, holdout_blocks

    ident.library_ = Library(("q1", "q2"), (sigs[0].input_name,), ident.degree, ident.extra_terms)
    t0 = time.perf_counter()
    parts = [holdout_blocks(s, ident.holdout_fraction) for s in sigs]
    gram = BlockGram.concatenate([ident._gram(s, edges) for s, (edges, _) in zip(sigs, parts)])
    held = np.concatenate([h for _, h in parts])
    timings["library_gram"] = time.perf_counter() - t0
    n_eff = sum(effective_samples(s) for s in sigs)
    train, _, coefs = ident._fit_pass(n_eff, gram, held, timings)
    training = SparseModel(coefs, ("q1", "q2"), (sigs[0].input_name,))
    even = [r.source for r, s in zip(recordings, sigs) if s.band_hz[0] > 0 and has_even_force(training, s)]
    if even:
        raise IdentificationError(
            "the joint fit has a force with an even part (" + ", ".join(training.equations["q1_dot"]) + "): its "
            "displacement below the band is carried per record (identify.inband), which joint identification "
            "does not do; identify the recordings one by one")
    ident.recording_, ident.recordings_, ident.joint_states_ = None, list(recordings), sigs
    ident.states_ = sigs[0]  # names the states and input; bands and rows are per recording (joint_)
    ident.offset_ = {"carried": False, "passes": 0}
    ident.heldout_rows_ = np.concatenate([np.repeat(h, np.diff(e)) for e, h in parts])
    coefs = ident._budget_by_free_run(sigs, train, held, coefs, timings)
    ident.training_model_ = training = SparseModel(coefs, ("q1", "q2"), (sigs[0].input_name,))

    t0 = time.perf_counter()
    bias_of = None
    if ident.bias_replicates != 0:
        def gram_of(noisy, columns):
            return BlockGram.concatenate([ident._gram(s, e, columns) for s, (e, _) in zip(noisy, parts)])

        def bias_of(sups, coefs):
            return unc.estimate_chain_bias(ident.bias_method, list(recordings), sigs, gram, ident.library_, sups,
                                           coefs, gram_of, ident.bias_replicates)
    reported, ident.standard_errors_, ident.uncertainty_ = ident._trust(gram, held, n_eff, bias_of)
    timings["refit_uncertainty"] = time.perf_counter() - t0
    ident.model_ = SparseModel(reported, ("q1", "q2"), (sigs[0].input_name,), ident.standard_errors_)
    validated = ident._free_run_choice(sigs, timings)  # the training fit, or its free-run refit

    t0 = time.perf_counter()
    per = [_recording(ident, gram, validated, i, r, s, e, h)
           for i, (r, s, (e, h)) in enumerate(zip(recordings, sigs, parts))]
    timings["per_recording"] = time.perf_counter() - t0
    runs = [p.pop("_runs") for p in per]
    ident.validation_ = _pooled(validated, runs) if ident.validate else None
    if ident.validation_ is not None and ident.budget_ is not None and ident.budget_refit == "all":
        ident.validation_["heldout_fitted"] = True  # the winner's coefficients saw these rows
        for p in per:
            p["validation"]["heldout_fitted"] = True
    ident.verdict_ = fit_verdict(ident.validation_, validated, ident.model_, sigs[0].input_name)
    flagged = [p for p in per if p["status"] == "inconsistent"]
    failed = [p for p in per if p["status"] == "failed"]
    if flagged or failed:  # the per-recording findings first: they say what is wrong with the set
        pooled = [ident.verdict_["reason"]] if ident.verdict_["status"] == "failed" else []
        ident.verdict_ = {"status": "failed", "reason": "; ".join(
            [f"one model does not explain all recordings: {p['source']}: {p['reason']}" for p in flagged]
            + [f"{p['source']}: {p['reason']}" for p in failed] + pooled)}
    ident.joint_ = {"recordings": per, "rule": {"z_change": Z_CHANGE, "change_ratio": CHANGE_RATIO,
                                                "change_floor_nrmse": CHANGE_FLOOR,
                                                "compared": [SIGNALS[k] for k in COMPARED]}}
    ident.timings_ = timings
    return ident


def _recording(ident, gram: BlockGram, model: SparseModel, i: int, rec, sig, edges, held) -> dict:
    """One recording's account: its chain, the joint model's held-out free run on it (`model`, the one
    validated), the recording identified alone, the consistency of its coefficients with the joint
    ones, and its status."""
    rows = np.repeat(held, np.diff(edges))
    part = gram.part(i)
    out = {"source": rec.source, "samples": int(rec.input.size), "fs_hz": float(rec.fs_hz),
           "band_hz": list(sig.band_hz), "valid_samples": [sig.valid.start, sig.valid.stop],
           "fit_samples": int(np.count_nonzero(~rows)), "heldout_samples": int(np.count_nonzero(rows)),
           "status": "unvalidated", "reason": "the free-run validation was not run", "_runs": None}
    out["coefficient_z"] = _coefficient_z(ident, gram, part)
    # the recording alone: same path and rule on its own blocks
    from .identifier import effective_samples

    train, heldout = part.equations(~held), part.equations(held) if held.any() else None
    sels = ident._select(ident._optimizer().fit_path(train), train, heldout, effective_samples(sig))
    names = ident.library_.names
    alone = SparseModel({eq: {names[j]: float(s.coef[j]) for j in np.flatnonzero(s.coef)} for eq, s in sels.items()},
                        ("q1", "q2"), (sig.input_name,))
    out["alone"] = {"model": alone.to_dict()["model"]}
    if not ident.validate:
        return out
    mask = rows if held.any() else np.ones_like(rows)
    val, sim_states, sim_qdot = validate(model, sig, mask)
    out["validation"] = val
    out["_runs"] = (sig, mask, sim_states, sim_qdot, val)
    alone_val = validate(alone, sig, mask)[0]
    out["alone"]["validation"] = {k: alone_val[k] for k in ("diverged", "heldout")}
    verdict = model_verdict(val, model, sig.input_name)
    out["status"], out["reason"] = verdict["status"], verdict["reason"]
    ratios = {}
    for k in COMPARED:
        joint_e, own_e = val["heldout"][k]["nrmse"], alone_val["heldout"][k]["nrmse"]
        ratios[k] = None if joint_e is None or own_e is None else joint_e / max(own_e, 1e-12)
    out["nrmse_ratio_joint_to_alone"] = {SIGNALS[k]: r for k, r in ratios.items()}
    worse = [k for k, r in ratios.items() if r is not None and r > CHANGE_RATIO
             and val["heldout"][k]["nrmse"] > CHANGE_FLOOR]
    alone_ok = model_verdict(alone_val, alone, sig.input_name)["status"] == "ok"
    z = out["coefficient_z"]["q1_dot"]
    z_max = max((abs(v) for v in z.values()), default=0.0)
    if alone_ok and z_max > Z_CHANGE and (worse or out["status"] == "failed"):
        # the recording has a model of its own, its coefficients differ beyond noise, and the joint
        # model misses its motion: the rig differs here
        moved = ", ".join(f"{t} (z = {z[t]:+.1f})" for t in sorted(z, key=lambda t: -abs(z[t]))[:2])
        k = worse[0] if worse else max(ratios, key=lambda k: ratios[k] or 0.0)
        why = out["reason"] + "; " if out["status"] == "failed" else ""
        out["status"] = "inconsistent"
        out["reason"] = (f"{why}the joint model's held-out free-run {SIGNALS[k]} error is {ratios[k]:.3g}x this "
                         f"recording's own model's (NRMSE {val['heldout'][k]['nrmse']:.3g} against "
                         f"{alone_val['heldout'][k]['nrmse']:.3g}): the rig behaves differently here; terms that "
                         f"moved most: {moved}")
    return out


def _coefficient_z(ident, gram: BlockGram, part: BlockGram) -> dict:
    """{equation: {term: z}}: the joint terms refit on this recording's blocks alone, minus the joint
    all-rows refit, over this recording's block-robust standard error (chain bias not removed from
    either: it is nearly common to both)."""
    out = {}
    names = ident.library_.names
    for e, (eq, sel) in enumerate(ident.selections_.items()):
        joint, _ = unc.refit_all_rows(gram, sel.support, e, covariance=False)
        own, cov = unc.refit_all_rows(part, sel.support, e)
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        out[eq] = {names[j]: (float((own[j] - joint[j]) / s) if s > 0 else 0.0)
                   for j, s in zip(np.flatnonzero(sel.support), se)}
    return out


def _pooled(model: SparseModel, runs: list) -> dict:
    """The joint model's free-run metrics over all recordings' held-out (and all valid) rows pooled, in
    the shape of validation.validate's (so the verdict and the report read it as a single record's);
    runs: per recording (sig, held-out mask, simulated states, simulated q1_dot, its validation)."""
    measured = {k: [] for k in SIGNALS}
    simulated = {k: [] for k in SIGNALS}
    one_step = []
    for sig, mask, sim_states, sim_qdot, _ in runs:
        v = sig.valid
        for k, m, s in (("q1_dot", sig.q1_dot[v], sim_qdot), ("q1", sig.q1[v], sim_states[:, 0]),
                        ("q2", sig.q2[v], sim_states[:, 1])):
            measured[k].append(m)
            simulated[k].append(s)
        x = sig.states[v]
        one_step.append(first_equation(model, x[:, 0], x[:, 1], sig.input[v][:, None]))
    mask = np.concatenate([r[1] for r in runs])
    out = {"diverged": any(r[4]["diverged"] for r in runs), "substeps": max(r[4]["substeps"] for r in runs),
           "samples_per_step": min(r[4]["samples_per_step"] for r in runs), "heldout": {}, "all": {},
           "heldout_samples": int(np.count_nonzero(mask)), "pooled_recordings": len(runs)}
    for k in SIGNALS:
        m, s = np.concatenate(measured[k]), np.concatenate(simulated[k])
        out["heldout"][k] = fit_metrics(m[mask], s[mask])
        out["all"][k] = fit_metrics(m, s)
    acc = np.concatenate(measured["q1_dot"])
    out["equation_error"] = {"q1_dot": fit_metrics(acc[mask], np.concatenate(one_step)[mask])}
    return out


def joint_result(ident, out: dict) -> dict:
    """SparseIdentifier.result() of a joint fit: today's document, its `chain` summed over the
    recordings (bands and rows are per recording), plus `recordings` (one section each) and `joint`."""
    per = ident.joint_["recordings"]
    out["chain"] = {"fit_samples": sum(p["fit_samples"] for p in per),
                    "heldout_samples": sum(p["heldout_samples"] for p in per),
                    "holdout": f"{ident.holdout_fraction:.0%} of each recording in interleaved blocks",
                    "band_hz": [p["band_hz"] for p in per],
                    "displacement_below_band": ident.offset_}
    out["recordings"] = per
    out["joint"] = {"n_recordings": len(per), "change_rule": ident.joint_["rule"],
                    "inconsistent": [p["source"] for p in per if p["status"] == "inconsistent"]}
    return out
