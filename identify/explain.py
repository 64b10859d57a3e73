"""Discrepancy workflow: where a model and the rig (or its recording) disagree, which effects are missing,
and how much adding them closes the gap.

    analysis = DiscrepancyAnalysis().fit(recording)        # or DiscrepancyAnalysis(baseline=model)
    analysis.result()["effects"]                           # [{name, kind, terms, coefficients, ...}, ...]

1. Baseline: a given model (digital twin, earlier identification), or the textbook Duffing structure
   {q1, q2, q2^3, input} (plus a constant for force inputs, whose DC is in band) fitted by equation
   error and refit on the multiple-shooting error (identify.shooting), which keeps it on the measured
   branch of the resonance's jump.
2. Gap: the held-out multiple-shooting NRMSE of the measured signal (q'' for the accelerometer rig, y for
   force inputs), against the sensor-noise floor (identify.noise). The first round's totals (the gap,
   the share a candidate closes, the bootstrap) leave out the largest TRIM_SHARE of the held-out
   segments' errors (identify.shooting.trimmed_total): no segment that holds the resonance's jump, a
   bifurcation a model's last digits move, can decide whether anything is missing or what (later
   rounds decide on plain sums, _total). The jump itself is reported
   apart: its time and frequency, measured and as the models' free runs predict it (identify.jumps).
3. Explain until explained (identify.candidates, identify.admissibility): while the gap is above
   `none_factor` x the noise floor, every catalog effect (physics and measurement faults) is fitted on
   top of the current explanation; candidates a rule excludes are dropped; the best by training
   shooting error is added if it removes at least `min_gap_closed` of the held-out squared shooting
   error. Each added effect's confidence: (1 - Wald p) x the block-bootstrap probability that it beats
   both the runner-up and the explanation before it; candidates that come within SURROGATE_SHARE of
   what it closes are reported as its surrogates.
4. Answer: `effect` = the first added effect; `none` when the baseline's gap is within `none_factor`
   x the noise floor; `unexplained` when it is above and no candidate closes enough, with the
   localisation of what remains (also given when effects were added but the gap stays above
   OUTSIDE_FACTOR x the floor: then the named effects are flagged as surrogates for physics outside
   the catalog and their confidence is scaled by the share of the excess error they explain).
5. A drifting sensor bias, which the band-limited chain removes before any gap is measured, is looked
   for in the raw channels below the band (identify.drift) and listed after the effects; it is the
   answer when the gap needs nothing else.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import spearmanr

from . import admissibility
from .candidates import all_candidates
from .chain import reconstruct_states
from .drift import T_REPORT, bias_trends
from .effects import CATALOG, Effect
from .errors import IdentificationError
from .identifier import holdout_blocks
from .jumps import jump_time
from .localise import excitation_hz, localise, remaining
from .model import SparseModel
from .noise import noise_floor
from .recording import Recording
from .shooting import TRIM_SHARE, bootstrap_prob, trimmed_total
from .structure import GAP_SIGNAL, Fitter, Structure

TEXTBOOK = ("q1", "q2", "q2^3")
METRIC = {"base": "held-out multiple-shooting NRMSE of the relative acceleration q''",
          "force": "held-out multiple-shooting NRMSE of the output y"}
#: Candidates refit on the shooting error per round: the best REFINE_TOP - 1 by shooting error at their
#: equation-error start and the best REFINE_TOP - 1 by held-out equation error.
REFINE_TOP = 3
#: Candidates are looked at once the baseline's gap exceeds this multiple of the floor; below
#: none_factor x the floor the first effect must close NEAR_CLOSED of the squared gap and beat the
#: baseline with bootstrap probability NEAR_P_BEATS, else the answer is `none` (the suite's single
#: effects at 2-3 % sensor noise left gaps of 1-2x the floor that were answered `none`).
LOOK_FACTOR = 1.0
NEAR_CLOSED = 0.4
NEAR_P_BEATS = 0.95
#: An effect is added only when the block bootstrap says it beats the explanation before it with at
#: least this probability on the held-out segments (it is chosen on the training segments).
MIN_P_BEATS = 0.9
#: A candidate closing at least this share of what the named one closes is reported as its surrogate.
SURROGATE_SHARE = 0.7
#: Once an effect is added, the next one is looked for while the gap is above the (upper-estimate) noise
#: floor, as the issue asks. Perfect models reach 0.6-0.9x of it (measured: Coulomb friction, gain and
#: delay faults on the design rig at 2048 Hz), a missing second effect left 1.07x at 1000 Hz and 1.7x at
#: 2048 Hz. It was 0.7x: below the floor the rest is mostly the noise plus what an effect's form misses,
#: and the suite's quadratic damping + hysteresis rig (case 57 of benchmarks/explain_robustness.py) then
#: took displacement-dependent damping at 0.95x the floor, confidence 1.0, for what Bouc-Wen n = 1 left.
CONTINUE_FACTOR = 1.0
#: The explanation so far is refit on the shooting error to convergence (this many evaluations; a
#: candidate's refit stops at 12) before the gap decides whether something is still missing: case 88 of
#: benchmarks/explain_robustness.py (quadratic stiffness + Bouc-Wen hysteresis, both named) left 1.79x
#: the floor after 12, 1.10x after 40 (as after 100), and took cubic damping, confidence 1.0, for the
#: difference.
POLISH_NFEV = 40
#: A record is one sweep when the excitation frequency over SWEEP_WINDOWS windows has a rank correlation
#: with time of at least ONE_SWEEP_RHO in size (then a stiffness drift is not separable).
SWEEP_WINDOWS = 20
ONE_SWEEP_RHO = 0.9
#: Above this multiple of the noise floor after the explanation, the rest is outside the catalog.
OUTSIDE_FACTOR = 5.0
OUTSIDE = "physics outside the catalog"


def closed_shares(gap_before: float, gap_after: float) -> dict:
    """The one definition of the gap closed, and the share of the squared gap it derives: gap_closed =
    1 - after/before (on the NRMSE, as the top level's), gap_share_closed = 1 - (after/before)^2 =
    1 - (1 - gap_closed)^2 (what min_gap_closed is compared with)."""
    r = gap_after / gap_before if gap_before > 0 else 1.0
    return {"gap_closed": float(1 - r), "gap_share_closed": float(1 - r * r)}


class DiscrepancyAnalysis:
    """Parameters: baseline (SparseModel or None for the fitted textbook Duffing), catalog of effects
    ({name: Effect}), holdout_fraction, alpha (Wald test level for physics terms), min_gap_closed
    (smallest share of the current held-out squared shooting error an added effect must remove),
    none_factor (gap within this multiple of the noise floor: nothing to explain), max_effects,
    refine (shooting refit of baseline and candidates), band_hz (measurement chain)."""

    def __init__(self, baseline: SparseModel | None = None, catalog: dict[str, Effect] | None = None,
                 holdout_fraction: float = 0.2, alpha: float = 1e-3, min_gap_closed: float = 0.2,
                 none_factor: float = 2.0, max_effects: int = 3, refine: bool = True, band_hz=None):
        self.baseline = baseline
        self.catalog = catalog
        self.holdout_fraction = holdout_fraction
        self.alpha = alpha
        self.min_gap_closed = min_gap_closed
        self.none_factor = none_factor
        self.max_effects = max_effects
        self.refine = refine
        self.band_hz = band_hz

    # -- fitting ----------------------------------------------------------------------------------
    def fit(self, recording: Recording) -> "DiscrepancyAnalysis":
        # a bias drift is looked for in the raw channels (identify.drift, after the rounds): the chain
        # removes it before any gap is measured, so as a candidate it could only fit something else
        catalog = ({k: v for k, v in CATALOG.items() if k != "bias_drift"} if self.catalog is None
                   else self.catalog)
        sig = reconstruct_states(recording, self.band_hz)
        u_name = sig.input_name
        edges, held = holdout_blocks(sig, self.holdout_fraction)
        if not held.any():
            raise IdentificationError("the discrepancy workflow needs held-out samples (holdout fraction > 0)")
        fitter = Fitter(recording, sig, edges, held)
        self.layout_, self.states_, self.fitter_ = recording.layout, sig, fitter
        self.heldout_rows_ = fitter.rows_held
        start = self._baseline_structure(recording, u_name, fitter)
        coef = start.coefficients
        k = -coef.get("q2", 0.0)
        self.f_res_hz_ = np.sqrt(k) / (2 * np.pi) if k > 0 else 0.1 * sig.band_hz[1]
        fitter.set_segments(self.f_res_hz_)
        cur = fitter.refine(start) if (self.baseline is None and self.refine) else start
        self.baseline_structure_ = cur
        base_fit = fitter.equation_fit(cur)
        self.baseline_residual_mse_ = base_fit.mse_heldout

        d0 = fitter.data(cur)
        hs = fitter.seg_held
        meas0 = d0.measured
        self._norm = float(sum(np.sum((meas0[a:b] - meas0[fitter.rows_held].mean()) ** 2)
                               for a, b, h in zip(fitter.starts, fitter.stops, hs) if h))
        err = fitter.errors(cur)
        self.noise_floor_ = noise_floor(recording, sig, fitter.rows_held)
        self.gap_before_ = self._gap(err)
        base_err = err
        cur_se = base_fit.se
        effects, rounds = [], []
        self._plain = False
        while len(effects) < self.max_effects and self._decision_gap(err) > (
                LOOK_FACTOR if not effects else CONTINUE_FACTOR) * self.noise_floor_:
            # within none_factor x the floor the answer is `none` unless a candidate clearly closes the gap
            near = not effects and self._gap(err) <= self.none_factor * self.noise_floor_
            step = self._round(fitter, cur, err, cur_se, base_fit.mse_heldout, catalog, near)
            self._plain = True  # rounds after the first decide on plain sums (see _total)
            rounds.append(step["table"])
            if step["best"] is None:
                break
            best, gap_prev = step["best"], self._gap(err)
            cur, err = best["structure"], best["err"]
            if self.refine:
                cur, err = self._polish(fitter, cur, err)
                best["entry"].update(gap_after=self._gap(err), **closed_shares(gap_prev, self._gap(err)))
            effects.append(best["entry"])
            cur_se = fitter.equation_fit(cur).se
        self.rounds_ = rounds
        self.candidates_ = rounds[0] if rounds else []
        self.effects_ = effects
        self.final_structure_ = cur
        self.gap_after_ = self._gap(err)
        floor = self.noise_floor_
        if effects:
            self.effect_ = effects[0]["name"]
            self.confidence_ = effects[0]["confidence"]
        elif self.gap_before_ <= self.none_factor * floor:
            self.effect_ = "none"
            # the gap sits at the noise floor: as sure as it is below the threshold (0.5 at it)
            ratio = self.gap_before_ / floor if floor > 0 else np.inf
            self.confidence_ = float(np.clip(1 - 0.5 * (ratio - 1) / (self.none_factor - 1), 0.5, 0.99))
        else:
            self.effect_ = "unexplained"
            # how sure that something is missing: 0.5 at none_factor x the floor (the threshold), 0.99
            # from twice that (the mirror of `none`'s); the closest candidate is in `candidates`
            ratio = self.gap_before_ / floor if floor > 0 else np.inf
            self.confidence_ = float(np.clip(0.5 + 0.5 * (ratio / self.none_factor - 1), 0.5, 0.99))
        final = cur.coefficients
        for e in effects:  # the coefficients of the final model, all effects refit together
            e["coefficients"].update({t: final.get(t, 0.0) for t in e["terms"]})
            if e["name"] == "hysteresis" and cur.hyst is not None:
                e["coefficients"].update(beta_per_m=cur.hyst[0], gamma_per_m=cur.hyst[1])
            if e["name"] == "end_stop" and cur.travel:
                e["coefficients"].update(travel_m=cur.travel)
        self._flag_outside(effects)
        self._drift_separable(sig, effects)
        self._add_drifts(recording, sig, effects)
        self.terms_ = effects[0]["terms"] if effects else []
        self.pair_p_value_ = effects[0].get("p_beats_runner_up") if effects else None

        # models, free runs (validation) and localisation
        self.baseline_model_ = self.baseline if self.baseline is not None else fitter.model(cur if not effects
                                                                                             else self.baseline_structure_)
        self.model_ = fitter.model(cur)
        self.gap_measured_ = meas0
        self.sim_before_qdot_ = fitter.free_run(self.baseline_structure_)
        self.sim_after_qdot_ = fitter.free_run(cur) if effects else self.sim_before_qdot_
        self.validation_before_ = self._validation(self.sim_before_qdot_)
        self.validation_after_ = self._validation(self.sim_after_qdot_)
        self.jump_ = self._jump(meas0, self.sim_before_qdot_, self.sim_after_qdot_)
        self.localisation_ = localise(fitter.model(self.baseline_structure_), sig) \
            if self.baseline_structure_.hyst is None and "tau" not in str(self.baseline_structure_.terms) else {}
        self.remaining_ = None
        if self.gap_after_ > self.none_factor * floor and (self.effect_ == "unexplained" or
                                                          any(OUTSIDE in e["surrogate_for"] for e in effects)):
            self.remaining_ = remaining(fitter, cur, err)
        self.baseline_segment_errors_ = base_err  # per shooting segment (held-out: fitter_.seg_held)
        return self

    def _baseline_structure(self, recording, u_name, fitter) -> Structure:
        if self.baseline is not None:
            b = self.baseline
            if tuple(b.inputs) != (u_name,):
                raise IdentificationError(f"baseline model's input {b.inputs} does not match the recording's ({u_name})")
            if tuple(b.states) != ("q1", "q2"):
                raise IdentificationError(f"baseline model's states {b.states}: the discrepancy workflow takes (q1, q2)")
            terms = list(b.equations["q1_dot"]) + ([u_name] if u_name not in b.equations["q1_dot"] else [])
            return Structure(tuple(terms), travel=b.travel.get("q2"), coef=tuple(b.equations["q1_dot"].items()))
        terms = list(TEXTBOOK) + [u_name]
        if recording.layout == "force":
            # DC is inside the band for a force input, so an offset of the force channel (Silverbox:
            # +6 mV) is a constant force the textbook model must carry; for accelerations it is filtered
            terms.insert(0, "1")
        st = Structure(tuple(terms))
        fit = fitter.equation_fit(st)
        return Structure(st.terms, coef=tuple(fit.coef.items()))

    def _drift_separable(self, sig, effects: list) -> None:
        """A stiffness drift on a single sweep is confounded with a stiffness that depends on the
        excitation frequency (time and frequency move together: the issue saw 27-94 % of k against
        truths within +-7 %): its value is withheld and what would separate it is said instead."""
        v = sig.valid
        u = sig.input[v]
        edges = np.linspace(0, u.size, SWEEP_WINDOWS + 1).astype(int)
        f = np.array([excitation_hz(u, a, b, sig.fs_hz, sig.band_hz[0]) for a, b in zip(edges[:-1], edges[1:])])
        rho = float(spearmanr(np.arange(f.size), f)[0]) if np.ptp(f) > 0 else 0.0
        if not abs(rho) >= ONE_SWEEP_RHO:
            return
        for e in effects:
            if e["name"] == "stiffness_drift":
                value = e["coefficients"].get("q2*tau")
                e["separable"] = False
                e["note"] = (f"not separable on this record: one {'up' if rho > 0 else 'down'}-sweep, so time and "
                             f"excitation frequency move together (rank correlation {rho:+.2f}) and a drift of the "
                             f"stiffness cannot be told from a frequency-dependent one (the confounded q2*tau "
                             f"would be {value:.4g}); an up and a down sweep, or the same sweep repeated, "
                             f"separate them")
                e["coefficients"] = {}

    def _jump(self, measured, before, after) -> dict:
        """The jump as its own observable (identify.jumps): measured, and as the baseline's and the
        explanation's free runs predict it; None where there is none."""
        sig = self.fitter_.sig0
        u = sig.input[sig.valid]

        def at(signal):
            j = jump_time(signal, u, sig.fs_hz, self.f_res_hz_)
            if j is None:
                return None
            r = j["row"]
            return {"t_s": (sig.valid.start + r) / sig.fs_hz, "direction": j["direction"], "ratio": j["ratio"],
                    "excitation_hz": excitation_hz(u, max(r - 1, 0), r + 1, sig.fs_hz, sig.band_hz[0])}

        return {"measured": at(measured), "predicted_before": at(before), "predicted_after": at(after)}

    def _polish(self, fitter: Fitter, st: Structure, err: np.ndarray):
        """(structure, per-segment errors) refit to convergence on the training segments' shooting error
        (kept only if the training error falls)."""
        train = ~fitter.seg_held
        out = fitter.refine(st, max_nfev=POLISH_NFEV)
        if out is st:
            return st, err
        e = fitter.errors(out)
        return (out, e) if np.sum(e[train]) < np.sum(err[train]) else (st, err)

    def _total(self, err: np.ndarray):
        """The total that decides: trimmed (shooting.trimmed_total) in the first round, whether anything
        is missing and what; plain sums once an effect is named, as a second effect shows in the
        resonance's few segments, which trimming would drop (Coulomb + quadratic damping named Coulomb
        alone with every round trimmed)."""
        return np.sum(err, axis=-1) if self._plain else trimmed_total(err)

    def _decision_gap(self, err: np.ndarray) -> float:
        h = self.fitter_.seg_held
        return float(np.sqrt(self._total(err[h]) / self._norm)) if self._norm > 0 else 0.0

    def _gap(self, err: np.ndarray) -> float:
        h = self.fitter_.seg_held
        return float(np.sqrt(trimmed_total(err[h]) / self._norm)) if self._norm > 0 else 0.0

    def _round(self, fitter: Fitter, cur: Structure, err, cur_se, mse_cur, catalog, near: bool = False) -> dict:
        """One round: every candidate on top of `cur`; the best admissible one if it closes enough."""
        train, held = ~fitter.seg_held, fitter.seg_held
        cands = all_candidates(fitter, cur, catalog)
        for c in cands:
            self._score(fitter, c, cur, err, cur_se, mse_cur)
        ok = sorted([c for c in cands if c["admissible"]], key=lambda c: np.sum(c["err"]))
        if self.refine:
            # the equation-error start can free-run far from the candidate's own optimum (an asymmetric
            # spring's start was worse than the baseline, refit it closed 80 %): refit the best by the
            # shooting error at the start and the best by held-out equation error
            by_eq = sorted(ok, key=lambda c: -c["score"])
            chosen = list({id(c): c for c in ok[:REFINE_TOP - 1] + by_eq[:REFINE_TOP - 1]}.values())
            for c in chosen:
                refined = dict(c, structure=fitter.refine(c["structure"]))
                self._score(fitter, refined, cur, err, cur_se, mse_cur)
                if refined["admissible"] and np.sum(refined["err"][train]) < np.sum(c["err"][train]):
                    c.update(refined)
            ok = sorted([c for c in cands if c["admissible"]], key=lambda c: np.sum(c["err"]))
        table = [self._public(c) for c in sorted(cands, key=lambda c: -c["gap_share_closed"])]
        # a candidate that fits the training segments best but makes the held-out gap worse has fitted
        # something else there (a gain fault bending to a one-sided end stop's contacts: -85 % on the
        # held-out segments while the stop itself closed 49 %): it is passed over, not taken as the best
        ok = [c for c in ok if c["gap_share_closed"] > 0] or ok
        need, p_need = (NEAR_CLOSED, NEAR_P_BEATS) if near else (self.min_gap_closed, MIN_P_BEATS)
        if not ok or ok[0]["gap_share_closed"] < need or ok[0]["p_beats_current"] < p_need:
            return {"best": None, "table": table}
        best = ok[0]
        others = ok[1:]
        runner = min(others, key=lambda c: self._total(c["err"][held])) if others else None
        p_runner = bootstrap_prob(runner["err"][held], best["err"][held], trim=not self._plain) if runner else 1.0
        conf = (1 - best["p_value"]) * min(p_runner, best["p_beats_current"])
        closed = best["gap_share_closed"]
        sur = best.get("same_as", []) + [c["name"] for c in others if c["gap_share_closed"] >= SURROGATE_SHARE * closed]
        st = best["structure"]
        coefficients = {t: st.coefficients.get(t, 0.0) for t in best["terms"]}
        coefficients.update(best["extra"])
        best["entry"] = {"name": best["name"], "kind": best["kind"], "terms": best["terms"],
                         "coefficients": coefficients, "confidence": float(conf),
                         "gap_after": self._gap(best["err"]), **closed_shares(self._gap(err), self._gap(best["err"])),
                         "surrogate_for": sur, "p_value": best["p_value"], "p_beats_runner_up": float(p_runner),
                         "p_beats_previous": best["p_beats_current"], "runner_up": runner["name"] if runner else None}
        return {"best": best, "table": table}

    def _score(self, fitter, c, cur, err, cur_se, mse_cur) -> None:
        st = c["structure"]
        held = fitter.seg_held
        c["err"] = fitter.errors(st)
        reason = admissibility.check(c["name"], st.coefficients, cur.coefficients, cur_se, c["fit"].se)
        if not reason and c["kind"] == "physics" and not c["p_value"] < self.alpha:
            reason = f"not significant (Wald p = {c['p_value']:.2g} >= {self.alpha:g})"
        c["rejected"] = reason
        c["admissible"] = not reason
        e0, e1 = self._total(err[held]), self._total(c["err"][held])
        c["gap_share_closed"] = float(1 - e1 / e0) if e0 > 0 else 0.0
        c["p_beats_current"] = bootstrap_prob(err[held], c["err"][held], trim=not self._plain)
        c["score"] = float((mse_cur - c["fit"].mse_heldout) / mse_cur) if mse_cur > 0 else 0.0

    def _public(self, c) -> dict:
        st = c["structure"]
        coef = {t: st.coefficients.get(t, 0.0) for t in c["terms"]}
        coef.update(c["extra"])
        if "beta_per_m" in coef:  # refit on the shooting error with the coefficients
            coef.update(beta_per_m=st.hyst[0], gamma_per_m=st.hyst[1])
        if "travel_m" in coef:  # refit on the shooting error with the coefficients
            coef.update(travel_m=st.travel)
        return {"name": c["name"], "kind": c["kind"], "terms": c["terms"], "coefficients": coef,
                "score": c["score"], "p_value": c["p_value"], "gap_share_closed": c["gap_share_closed"],
                "gap_closed": float(1 - np.sqrt(max(1 - c["gap_share_closed"], 0.0))), "gap_after": self._gap(c["err"]), "p_beats_baseline": c["p_beats_current"],
                "admissible": c["admissible"], "rejected": c["rejected"], "description": CATALOG[c["name"]].description
                if c["name"] in CATALOG else ""}

    def _add_drifts(self, recording, sig, effects: list) -> None:
        """A drifting sensor bias, found in the raw channels below the band (identify.drift): the gap
        cannot show it, so it is listed after whatever closed the gap; it is the answer when nothing
        else was (`none` becomes `bias_drift`); an `unexplained` gap stays unexplained."""
        self.bias_trends_ = bias_trends(recording, sig)
        if any(e["name"] == "bias_drift" for e in effects):
            return
        for d in self.bias_trends_:
            if abs(d["t"]) < T_REPORT:
                continue
            effects.append({"name": "bias_drift", "kind": "measurement", "terms": [],
                            "coefficients": {f"bias_drift_{d['channel']}": d["change_ms2"]},
                            "confidence": float(1 - d["p_value"]), "gap_after": self.gap_after_,
                            "gap_closed": 0.0, "gap_share_closed": 0.0, "surrogate_for": [], "p_value": d["p_value"],
                            "evidence": (f"the {d['channel']} accelerometer's mean below the band moves by "
                                         f"{d['change_ms2']:+.4f} +- {d['se_ms2']:.4f} m/s^2 over the record "
                                         f"(t = {d['t']:.1f}); the chain removes it, so the gap does not show it")})
            if self.effect_ == "none":
                self.effect_, self.confidence_ = "bias_drift", effects[-1]["confidence"]

    def _flag_outside(self, effects: list) -> None:
        """Effects added but the gap stays well above the noise floor: what they explain is partly
        something else. Flag them and scale their confidence by the share of the excess explained."""
        floor = self.noise_floor_
        if not effects or self.gap_after_ <= OUTSIDE_FACTOR * floor:
            return
        excess = self.gap_before_ ** 2 - floor ** 2
        share = (self.gap_before_ ** 2 - self.gap_after_ ** 2) / excess if excess > 0 else 0.0
        for e in effects:
            e["surrogate_for"] = e["surrogate_for"] + [OUTSIDE]
            e["confidence"] = float(e["confidence"] * np.clip(share, 0, 1))
        self.confidence_ = effects[0]["confidence"]

    def _validation(self, sim: np.ndarray) -> dict:
        """Full free run (one simulation over the record) against the measured gap signal."""
        from .validation import fit_metrics

        h = self.heldout_rows_
        return {"diverged": bool(not np.all(np.isfinite(sim))),
                "heldout": {GAP_SIGNAL[self.layout_]: fit_metrics(self.gap_measured_[h], sim[h])},
                "all": {GAP_SIGNAL[self.layout_]: fit_metrics(self.gap_measured_, sim)}}

    # -- the JSON document ------------------------------------------------------------------------
    def result(self) -> dict:
        """The `shakeid explain --json` document."""
        gb, ga = self.gap_before_, self.gap_after_
        return {
            "effect": self.effect_, "terms": self.terms_, "confidence": self.confidence_,
            "effects": self.effects_,
            "candidates": self.candidates_, "rounds": self.rounds_,
            "gap_before": gb, "gap_after": ga,
            "gap_closed": (1 - ga / gb) if gb else None,
            "metric": METRIC[self.layout_],
            "noise_floor": self.noise_floor_,
            "model": self.model_.to_dict()["model"],
            **{k: v for k, v in self.model_.to_dict().items() if k in ("states", "inputs", "travel")},
            "measurement": {k: v for k, v in self.final_structure_.meas if v},
            "baseline": {"model": self.baseline_model_.to_dict()["model"],
                         "source": "given" if self.baseline is not None else "textbook Duffing fitted",
                         "equation_error_heldout_mse": self.baseline_residual_mse_},
            "validation": {"before": self.validation_before_, "after": self.validation_after_},
            "localisation": {k: v for k, v in self.localisation_.items() if not k.startswith("_")},
            "remaining": self.remaining_,
            "thresholds": {"alpha": self.alpha, "min_gap_closed": self.min_gap_closed,
                           "none_factor": self.none_factor, "outside_factor": OUTSIDE_FACTOR,
                           "surrogate_share": SURROGATE_SHARE, "trim_share": TRIM_SHARE},
            "p_beats_runner_up": self.pair_p_value_,
            "jump": self.jump_,
            "bias_trends": self.bias_trends_,
        }
