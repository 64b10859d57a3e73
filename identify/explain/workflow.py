"""Discrepancy workflow: where a model and the rig (or its recording) disagree, which effects are missing,
and how much adding them closes the gap.

    analysis = DiscrepancyAnalysis().fit(recording)        # or DiscrepancyAnalysis(baseline=model)
    analysis.result()["effects"]                           # [{name, kind, terms, coefficients, ...}, ...]

1. Baseline: a given model (digital twin, earlier identification), or the textbook Duffing structure
   {q1, q2, q2^3, input} (plus a constant for force inputs, whose DC is in band) fitted by equation
   error and refit on the multiple-shooting error (identify.simulation.shooting), which keeps it on the measured
   branch of the resonance's jump.
2. Gap: the held-out multiple-shooting NRMSE of the measured signal (q'' for the accelerometer rig, y for
   force inputs), against the sensor-noise floor (identify.noise.floor). The first round's totals (the gap,
   the share a candidate closes, the bootstrap) leave out the largest TRIM_SHARE of the held-out
   segments' errors (identify.simulation.shooting.trimmed_total): no segment that holds the resonance's jump, a
   bifurcation a model's last digits move, can decide whether anything is missing or what (later
   rounds decide on plain sums, _total). The jump itself is reported
   apart: its time and frequency, measured and as the models' free runs predict it (identify.explain.jumps).
3. Explain until explained (identify.explain.rounds, candidates from identify.explain.effects): while the gap is above
   `none_factor` x the noise floor, every catalog effect (physics and measurement faults) is fitted on
   top of the current explanation; candidates a rule excludes are dropped (the best a sign rule excluded
   is judged again on its shooting refit when it fits best); the best by training shooting error is
   added if it removes at least `min_gap_closed` of the held-out squared shooting error. Each added
   effect's confidence: (1 - p) x the block-bootstrap probability that it beats
   both the runner-up and the explanation before it; candidates that come within SURROGATE_SHARE of
   what it closes are reported as its surrogates.
4. Answer: `effect` = the first added effect; `none` when the baseline's gap is within `none_factor`
   x the noise floor; `unexplained` when it is above and no candidate closes enough, with the
   localisation of what remains (also given when effects were added but the gap stays above
   OUTSIDE_FACTOR x the floor: then the named effects are flagged as surrogates for physics outside
   the catalog and their confidence is scaled by the share of the excess error they explain).
5. A drifting sensor bias, which the band-limited chain removes before any gap is measured, is looked
   for in the raw channels below the band (identify.explain.drift) and listed after the effects; it is the
   answer when the gap needs nothing else.
"""
from __future__ import annotations

import numpy as np

from ..chain.states import reconstruct_states
from .effects import CATALOG, Effect
from .effects.stiffness_drift import sweep_direction
from ..errors import IdentificationError
from .rounds import SURROGATE_SHARE, Rounds, closed_shares
from ..identifier import holdout_blocks
from .localise import localise, remaining
from .masking import masked_admissibility
from ..model import SparseModel
from ..noise.floor import noise_floor
from ..data.recording import Recording
from ..simulation.shooting import TRIM_SHARE
from .several import as_recordings, jump_of, pooled_floor, recording_entries
from .structure import GAP_SIGNAL, Fitter, Structure
from ..threads import one_blas_thread

__all__ = ["DiscrepancyAnalysis", "closed_shares"]

TEXTBOOK = ("q1", "q2", "q2^3")
METRIC = {"base": "held-out multiple-shooting NRMSE of the relative acceleration q''",
          "force": "held-out multiple-shooting NRMSE of the output y"}
#: Candidates are looked at once the baseline's gap exceeds this multiple of the floor; below
#: none_factor x the floor the first effect must clear explain_rounds.NEAR_CLOSED / NEAR_P_BEATS.
LOOK_FACTOR = 1.0
#: Once an effect is added, the next one is looked for while the gap is above the (upper-estimate) noise
#: floor, as the issue asks. Perfect models reach 0.6-0.9x of it (measured: Coulomb friction, gain and
#: delay faults on the design rig at 2048 Hz), a missing second effect left 1.07x at 1000 Hz and 1.7x at
#: 2048 Hz. It was 0.7x: below the floor the rest is mostly the noise plus what an effect's form misses,
#: and the suite's quadratic damping + hysteresis rig (case 57 of benchmarks/explain_robustness.py) then
#: took displacement-dependent damping at 0.95x the floor, confidence 1.0, for what Bouc-Wen n = 1 left.
CONTINUE_FACTOR = 1.0
#: The explanation so far is refit on the shooting error to convergence (this many evaluations; a
#: candidate's refit stops at 12 or at structure.CANDIDATE_REFIT_FTOL) before the gap decides whether
#: something is still missing: case 88 of benchmarks/explain_robustness.py (quadratic stiffness +
#: Bouc-Wen hysteresis, both named) left 1.79x the floor after 12, 1.10x after 40 (as after 100), and
#: took cubic damping, confidence 1.0, for the difference.
POLISH_NFEV = 40
#: Above this multiple of the noise floor after the explanation, the rest is outside the catalog: the named
#: effects are flagged as surrogates for it, their confidence scaled by the share of the excess they explain.
#: In runs 24-27 of benchmarks/explain_robustness.py (the current decisions, 4 fresh seeds), right in-catalog
#: explanations leave the gap at a median 0.92x the floor (90 % within 1.17x, 96 % within 1.31x; single
#: effects at most 1.96x). Over all 29 stored runs (4023 cases), of the 39 explanations that left 3-5x, 38 had
#: named something else (24 out-of-catalog rigs, 14 pairs with one effect missed) and one was right (a
#: channel delay beside mains hum, 3.2x, which stays named, now flagged; right answers above 3x are rare
#: otherwise: a channel delay at 5.4x, older runs' Coulomb friction at 8.9x, flagged at 5x already). At 5x,
#: free play of the spring, whose stiffness changes with the amplitude along a sweep, was named a stiffness
#: drift at confidence 0.95-1.0 leaving 3.3-4.4x (run 24 case 92, run 27 cases 44 and 92); at 3x, 8 of the 22
#: wrong physical names at confidence >= 0.5 over all stored runs go (re-scored from the stored results: the
#: flag is applied to the final effects only), and no right answer is lost.
OUTSIDE_FACTOR = 3.0
OUTSIDE = "physics outside the catalog"


def default_catalog() -> dict[str, Effect]:
    """The effects offered in the rounds: every registered one that is looked for there (a bias drift is
    looked for in the raw channels after the rounds: the chain removes it before any gap is measured)."""
    return {k: v for k, v in CATALOG.items() if v.in_rounds}


class DiscrepancyAnalysis(Rounds):
    """Parameters: baseline (SparseModel or None for the fitted textbook Duffing), catalog of effects
    ({name: Effect}; default: identify.explain.effects' registry), holdout_fraction, alpha (test level: the Wald
    test of physics terms, a measurement fault's own test), min_gap_closed (smallest share of the current
    held-out squared shooting error an added effect must remove), none_factor (gap within this multiple of
    the noise floor: nothing to explain), max_effects, refine (shooting refit of baseline and candidates), band_hz (measurement chain)."""

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
    @one_blas_thread  # as SparseIdentifier.fit: small BLAS products, oversubscribed under load (identify.threads)
    def fit(self, recordings: Recording | list[Recording]) -> "DiscrepancyAnalysis":
        """One explanation of a recording, or of several recordings of the same rig together (an up and
        a down sweep, sweeps at several amplitudes: identify.explain.several), through the same rounds: each
        recording its own chain, states, held-out blocks and shooting segments, the errors pooled, one
        set of coefficients (identify.explain.structure.Fitter; drift time per recording)."""
        catalog = default_catalog() if self.catalog is None else self.catalog
        fitter = self._fitter(recordings)
        cur, err = self._baseline(fitter)
        cur, err, effects = self._explain(fitter, cur, err, catalog)
        self._answer(cur, err, effects)
        self.final_segment_errors_ = err
        for e in effects:  # the coefficients of the final model, all effects refit together
            e["coefficients"].update({t: cur.coefficients.get(t, 0.0) for t in e["terms"]})
            if e["name"] in CATALOG:
                e["coefficients"].update(CATALOG[e["name"]].refit_fields(cur))
        self._flag_outside(effects)
        self.sweep_rhos_ = [sweep_direction(p.sig) for p in fitter.parts]
        for e in effects:
            if e["name"] in CATALOG:
                CATALOG[e["name"]].annotate(e, self)
        self._after_rounds(fitter, effects)
        self.terms_ = effects[0]["terms"] if effects else []
        self.pair_p_value_ = effects[0].get("p_beats_runner_up") if effects else None
        self._validate(fitter, cur, err, effects)
        return self

    @one_blas_thread
    def baseline_gap(self, recordings: Recording | list[Recording]) -> dict:
        """The baseline's held-out gap and the noise floor, nothing explained: where the rounds would start.
        sim.detectability measures with it how much of an effect a plain model leaves visible."""
        self._baseline(self._fitter(recordings))
        return {"gap": self.gap_before_, "noise_floor": self.noise_floor_}

    def _fitter(self, recordings) -> Fitter:
        """Each recording's chain, states and held-out blocks, in one Fitter."""
        recs = as_recordings(recordings)
        parts = []
        for rec in recs:
            sig = reconstruct_states(rec, self.band_hz)
            edges, held = holdout_blocks(sig, self.holdout_fraction)
            if not held.any():
                raise IdentificationError("the discrepancy workflow needs held-out samples (holdout fraction > 0)")
            parts.append((rec, sig, edges, held))
        fitter = Fitter(parts)
        self.layout_, self.states_, self.fitter_ = fitter.layout, fitter.parts[0].sig, fitter
        self.recordings_ = recs
        self.heldout_rows_ = fitter.rows_held
        return fitter

    def _baseline(self, fitter):
        """The baseline structure (refit on the shooting error when it is the textbook one), its segments,
        per-segment errors, the gap before and the noise floor (pooled over the recordings)."""
        start = self._baseline_structure(fitter)
        k = -start.coefficients.get("q2", 0.0)
        self.f_res_hz_ = np.sqrt(k) / (2 * np.pi) if k > 0 else 0.1 * fitter.parts[0].sig.band_hz[1]
        fitter.set_segments(self.f_res_hz_)
        cur = fitter.refine(start) if (self.baseline is None and self.refine) else start
        self.baseline_structure_ = cur
        self._base_fit = fitter.equation_fit(cur)
        self.baseline_residual_mse_ = self._base_fit.mse_heldout
        meas0 = fitter.data(cur).measured
        self.gap_measured_ = meas0
        self._norm = float(sum(np.sum((meas0[a:b] - meas0[fitter.rows_held].mean()) ** 2)
                               for a, b, h in zip(fitter.starts, fitter.stops, fitter.seg_held) if h))
        err = fitter.errors(cur)
        rows = fitter.rows_held
        self.noise_floors_ = [noise_floor(p.rec, p.sig, rows[p.offset:p.offset + p.n]) for p in fitter.parts]
        self.noise_floor_ = self.noise_floor_before_ = pooled_floor(self.noise_floors_, meas0, rows, fitter)
        self.gap_before_ = self._gap(err)
        self.baseline_segment_errors_ = err  # per shooting segment (held-out: fitter_.seg_held)
        return cur, err

    def _explain(self, fitter, cur, err, catalog):
        """Explain until explained: rounds while the gap is above the floor (LOOK_FACTOR, then
        CONTINUE_FACTOR), each adding the best candidate that closes enough, the whole refit after (and a
        fault named before it judged again: Rounds._recheck); once
        the gap is down at the floor, the group of each named effect is checked once for an effect it masks
        (identify.explain.masking)."""
        effects, rounds, checked = [], [], set()
        cur_se, mse0 = self._base_fit.se, self._base_fit.mse_heldout
        self._plain = False
        while len(effects) < self.max_effects:
            step = None
            if self._decision_gap(err) > (LOOK_FACTOR if not effects else CONTINUE_FACTOR) * self.noise_floor_:
                # within none_factor x the floor the answer is `none` unless a candidate clearly closes the gap
                near = not effects and self._gap(err) <= self.none_factor * self.noise_floor_
                step = self._round(fitter, cur, err, cur_se, mse0, catalog, near)
                self._plain = True  # rounds after the first decide on plain sums (see _total)
                rounds.append(step["table"])
            # what a round does not name (or what is left at the floor) may be masked by a named effect
            unchecked = self._unchecked(effects, checked) if self.refine else []
            while unchecked and (step is None or step["best"] is None):
                named = unchecked.pop(0)
                checked.add(CATALOG[named].group)
                unchecked = [n for n in unchecked if CATALOG[n].group not in checked]
                step = self._mask_round(fitter, cur, err, cur_se, mse0, catalog, named)
                rounds.append(step["table"])
            if step is None or step["best"] is None:
                break
            best, entry, gap_prev = step["best"], step["entry"], self._gap(err)
            cur, err = best.structure, best.err
            if self.refine:
                polished, perr = self._polish(fitter, cur, err)
                # a masked term is weakly determined: a polish that takes it across zero is not kept
                if not ("masked_by" in entry and masked_admissibility(CATALOG[best.name], polished.coefficients, best.fit.se)):
                    cur, err = polished, perr
                entry.update(gap_after=self._gap(err), **closed_shares(gap_prev, self._gap(err)))
            effects.append(entry)
            if self.refine and len(effects) > 1:  # a fault named before it may no longer be needed
                cur, err, table = self._recheck(fitter, cur, err, effects)
                rounds += [table] if table else []
            cur_se = fitter.equation_fit(cur).se
            self.noise_floor_ = min(self.noise_floor_, self._floor_after(fitter, cur))
        self.rounds_ = rounds
        self.candidates_ = rounds[0] if rounds else []
        return cur, err, effects

    def _floor_after(self, fitter: Fitter, st: Structure) -> float:
        """The noise floor once the structure's effects are named (base layout; a force layout keeps the
        record's): read, as the record's is (identify.noise.floor.noise_floor), above the band of the raw q''
        less the structure's unfiltered shooting runs. A friction's or a contact's force steps fill the
        spectrum above the band with their 1/f^2 tail, which the record's floor counts as noise (1.4-3.8x the
        sensors' on the wide scenarios' Coulomb rigs, so a second effect at 4x the sensors' floor stayed
        below it); once a model holds the effect, its runs hold the steps too. Outside the segments (and
        where a run diverged) nothing is taken off: the raw q'' stands."""
        if fitter.layout != "base":
            return self.noise_floor_
        runs, rows = np.nan_to_num(fitter.unfiltered_runs(st), nan=0.0), fitter.rows_held
        floors = [noise_floor(p.rec, p.sig, rows[p.offset:p.offset + p.n], runs[p.offset:p.offset + p.n])
                  for p in fitter.parts]
        return pooled_floor(floors, self.gap_measured_, rows, fitter)

    @staticmethod
    def _unchecked(effects: list, checked: set) -> list[str]:
        """Named physics effects whose group (Effect.group) has not been checked for masking yet."""
        return [e["name"] for e in effects if e["name"] in CATALOG and CATALOG[e["name"]].kind == "physics"
                and CATALOG[e["name"]].group and CATALOG[e["name"]].group not in checked]

    def _answer(self, cur, err, effects) -> None:
        """The answer: the first effect added, `none` or `unexplained`, and its confidence."""
        self.effects_ = effects
        self.final_structure_ = cur
        self.gap_after_ = self._gap(err)
        floor = self.noise_floor_
        ratio = self.gap_before_ / floor if floor > 0 else np.inf
        if effects:
            self.effect_ = effects[0]["name"]
            self.confidence_ = effects[0]["confidence"]
        elif self.gap_before_ <= self.none_factor * floor:
            self.effect_ = "none"
            # the gap sits at the noise floor: as sure as it is below the threshold (0.5 at it)
            self.confidence_ = float(np.clip(1 - 0.5 * (ratio - 1) / (self.none_factor - 1), 0.5, 0.99))
        else:
            self.effect_ = "unexplained"
            # how sure that something is missing: 0.5 at none_factor x the floor (the threshold), 0.99
            # from twice that (the mirror of `none`'s); the closest candidate is in `candidates`
            self.confidence_ = float(np.clip(0.5 + 0.5 * (ratio / self.none_factor - 1), 0.5, 0.99))

    def _validate(self, fitter, cur, err, effects) -> None:
        """Models, free runs (validation), the jumps, localisation and what remains."""
        self.baseline_model_ = self.baseline if self.baseline is not None else fitter.model(
            cur if not effects else self.baseline_structure_)
        self.model_ = fitter.model(cur)
        self.sim_before_qdot_ = fitter.free_run(self.baseline_structure_)
        self.sim_after_qdot_ = fitter.free_run(cur) if effects else self.sim_before_qdot_
        self.validation_before_ = self._validation(self.sim_before_qdot_)
        self.validation_after_ = self._validation(self.sim_after_qdot_)
        self.jumps_ = [jump_of(fitter, p, self.gap_measured_, self.sim_before_qdot_, self.sim_after_qdot_,
                               self.f_res_hz_) for p in fitter.parts]
        self.jump_ = self.jumps_[0]
        # localisation reads the model on the measured (q1, q2) and the input alone, of the recording where
        # the baseline misses most (its share of the held-out shooting error)
        states, inputs = fitter.names(self.baseline_structure_)
        worst = max(fitter.parts, key=lambda p: float(np.sum(self.baseline_segment_errors_[
            fitter.seg_held & (fitter.starts >= p.offset) & (fitter.starts < p.offset + p.n)])))
        self.localised_part_ = worst
        self.localisation_ = localise(fitter.model(self.baseline_structure_), worst.sig) \
            if states == ("q1", "q2") and inputs == (fitter.u_name,) else {}
        if self.localisation_ and len(fitter.parts) > 1:
            self.localisation_["recording"] = worst.rec.source
        self.remaining_ = None
        if self.gap_after_ > self.none_factor * self.noise_floor_ and (
                self.effect_ == "unexplained" or any(OUTSIDE in e["surrogate_for"] for e in effects)):
            self.remaining_ = remaining(fitter, cur, err)

    def _after_rounds(self, fitter, effects: list) -> None:
        """What effects show outside the gap, looked for after the rounds in each recording (a drifting
        sensor bias in the raw channels: identify.explain.effects.bias_drift), listed after whatever closed
        the gap (with the recording they were seen in, when there are several); such an effect is the
        answer when nothing else was (`none` becomes it); an `unexplained` gap stays unexplained."""
        trends, found = [], []
        for p in fitter.parts:
            self.bias_trends_ = []
            for effect in CATALOG.values():
                for entry in effect.after_rounds(self, p.rec, p.sig):
                    found.append(dict(entry, recording=p.rec.source) if len(fitter.parts) > 1 else entry)
                    if self.effect_ == "none":
                        self.effect_, self.confidence_ = entry["name"], entry["confidence"]
            trends += [dict(d, recording=p.rec.source) if len(fitter.parts) > 1 else d for d in self.bias_trends_]
        effects.extend(found)
        self.bias_trends_ = trends

    def _baseline_structure(self, fitter) -> Structure:
        u_name = fitter.u_name
        if self.baseline is not None:
            b = self.baseline
            if tuple(b.inputs) != (u_name,):
                raise IdentificationError(f"baseline model's input {b.inputs} does not match the recording's ({u_name})")
            if tuple(b.states) != ("q1", "q2"):
                raise IdentificationError(f"baseline model's states {b.states}: the discrepancy workflow takes (q1, q2)")
            terms = list(b.equations["q1_dot"]) + ([u_name] if u_name not in b.equations["q1_dot"] else [])
            return Structure(tuple(terms), travel=b.travel.get("q2"), coef=tuple(b.equations["q1_dot"].items()))
        terms = list(TEXTBOOK) + [u_name]
        if fitter.layout == "force":
            # DC is inside the band for a force input, so an offset of the force channel (Silverbox:
            # +6 mV) is a constant force the textbook model must carry; for accelerations it is filtered
            terms.insert(0, "1")
        st = Structure(tuple(terms))
        fit = fitter.equation_fit(st)
        return Structure(st.terms, coef=tuple(fit.coef.items()))
    def _polish(self, fitter: Fitter, st: Structure, err: np.ndarray):
        """(structure, per-segment errors) refit to convergence on the training segments' shooting error
        (kept only if the training error falls)."""
        train = ~fitter.seg_held
        out = fitter.refine(st, max_nfev=POLISH_NFEV)  # to convergence (structure.CONVERGED_FTOL)
        if out is st:
            return st, err
        e = fitter.errors(out)
        return (out, e) if np.sum(e[train]) < np.sum(err[train]) else (st, err)
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
        from ..simulation.validation import fit_metrics

        h = self.heldout_rows_
        return {"diverged": bool(not np.all(np.isfinite(sim))),
                "heldout": {GAP_SIGNAL[self.layout_]: fit_metrics(self.gap_measured_[h], sim[h])},
                "all": {GAP_SIGNAL[self.layout_]: fit_metrics(self.gap_measured_, sim)}}

    # -- the JSON document ------------------------------------------------------------------------

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
            "noise_floor_before": self.noise_floor_before_,
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
            "recordings": recording_entries(self),
        }
