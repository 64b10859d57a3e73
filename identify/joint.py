"""Joint identification: one model fitted to several recordings of the same rig (a campaign's sweeps
at several amplitudes, repeats over weeks).

    ident = SparseIdentifier().fit([rec_a, rec_b, rec_c])
    ident.result()["recordings"]   # per recording: band, held-out free-run fit, its own status

What is summed, what stays per recording:
- the measurement chain runs per recording (identify.chain.states: its own excited band, tapers, valid rows);
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
(identify.simulation.refine.PooledFreeRunError): a second recording at other amplitudes is more data for what the
free run extrapolates (Silverbox with its zip's second record, docs/identification.md).

Refused for several recordings (IdentificationError): holdout_samples (the paper's split of one
record) and a force with an even part (its displacement below the band is carried per record,
identify.chain.inband).
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from .trust import uncertainty as unc
from .errors import IdentificationError
from .fitting import effective_samples, make_optimizer, select_supports
from .regression.gram import BlockGram
from .model import SparseModel
from .simulation.validation import SIGNALS, model_verdict

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


def refuse(ident, recordings: list) -> None:
    """What a joint fit refuses before any work: no recordings, the paper's split of one record
    (holdout_samples), a recording given twice."""
    if not recordings:
        raise IdentificationError("no recordings to identify")
    if ident.holdout_samples is not None:
        raise IdentificationError(f"joint identification of {len(recordings)} recordings does not take "
                                  "holdout_samples (the first N samples of one record); identify the recordings "
                                  "one by one for it")
    _refuse_copies(recordings)


def refuse_mixed_layouts(sources: list) -> None:
    """One model needs one layout (the same input) in every recording: refused after the chains ran."""
    if len({s.sig.input_name for s in sources}) != 1 or len({s.recording.layout for s in sources}) != 1:
        raise IdentificationError("joint identification needs recordings of one layout: got "
                                  + ", ".join(f"{s.name} ({s.recording.layout})" for s in sources))


def check_consistency(ident, runs: list, timings: dict) -> None:
    """After the fit sequence (identify.fitting) on several recordings: each recording's account
    (module doc) in joint_, and the verdict failed when one model does not explain them all."""
    t0 = time.perf_counter()
    per = [_recording(ident, i, src, run) for i, (src, run) in enumerate(zip(ident.sources_, runs))]
    timings["per_recording"] = time.perf_counter() - t0
    if ident.validation_ is not None and ident.budget_ is not None and ident.budget_refit == "all":
        for p in per:
            p["validation"]["heldout_fitted"] = True  # the winner's coefficients saw these rows
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


def _recording(ident, i: int, source, run) -> dict:
    """One recording's account: its chain, the joint model's held-out free run on it (the one
    validated), the recording identified alone, the consistency of its coefficients with the joint
    ones, and its status."""
    rec, sig, (edges, held) = source.recording, source.sig, ident.blocks_[i]
    model, gram = ident.validated_model_, ident.gram_
    rows = np.repeat(held, np.diff(edges))
    part = gram.part(i)
    out = {"source": rec.source, "samples": int(rec.input.size), "fs_hz": float(rec.fs_hz),
           "band_hz": list(sig.band_hz), "valid_samples": [sig.valid.start, sig.valid.stop],
           "fit_samples": int(np.count_nonzero(~rows)), "heldout_samples": int(np.count_nonzero(rows)),
           "status": "unvalidated", "reason": "the free-run validation was not run"}
    out["coefficient_z"] = _coefficient_z(ident, gram, part)
    # the recording alone: same path and rule on its own blocks
    train, heldout = part.equations(~held), part.equations(held) if held.any() else None
    sels = select_supports(ident, make_optimizer(ident).fit_path(train), train, heldout, effective_samples(sig))
    names = ident.library_.names
    alone = SparseModel({eq: {names[j]: float(s.coef[j]) for j in np.flatnonzero(s.coef)} for eq, s in sels.items()},
                        ("q1", "q2"), (sig.input_name,))
    out["alone"] = {"model": alone.to_dict()["model"]}
    if run is None:
        return out
    val = run[4]
    out["validation"] = val
    alone_val = source.validate(alone, edges, held)[0]
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
