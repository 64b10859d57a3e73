"""SparseIdentifier: recording in, validated sparse ODE model out (the paper's Algorithm 1, done right).

    rec = read_recording("sweep.csv")
    ident = SparseIdentifier().fit(rec)
    ident.model_            # SparseModel: {"q1_dot": {"q1": -3.73, ...}, "q2_dot": {"q1": 1.0}}
    ident.result()          # the JSON document `shakeid identify --json` prints

Steps: states from the measurement chain (identify.chain.states) -> library matrix over the valid samples ->
per-block normal equations -> sparse path on the training blocks (ADMM-LASSO or STLSQ) -> selection and
least-squares refit per equation -> standard errors -> free-run validation on the held-out blocks. This
class holds the parameters, decides once whether it was given one recording or several, and hands the
recordings to the one fit sequence (identify.fitting) as normal-equations sources (identify.regression.sources);
several recordings add the consistency check across them (identify.joint).

Held-out samples: by default 20 % of the record in 10 blocks spread evenly over it, so a sweep's every
frequency range (the resonance included) contributes to both fit and validation. `holdout_samples=N`
holds out the first N samples instead, as the paper did (30000): that removes the sweep's start, and with
it the resonance of a 1-20 Hz sweep of this rig, from the fit.
"""
from __future__ import annotations

import time

import numpy as np

from . import joint, params
from .trust import uncertainty as unc
from .errors import IdentificationError
from .fitting import (effective_samples, fit_sources, holdout_blocks, make_optimizer, per_record,  # noqa: F401
                      placement_supports, select_supports)
from .explain.effects import expand_terms
from .regression.library import Library
from .physical import RigConstants, physical_parameters
from .data.recording import Recording
from .selection.pareto import DEFAULT_TOLERANCE
from .regression.sources import RecordingEquations, state_gram
from .threads import one_blas_thread

N_REPORTED = 10  # budget candidates listed in the result


class SparseIdentifier:
    """Parameters (stored as given, sklearn-style; fitted attributes end in `_`):

    degree : highest monomial degree of the library (4 as in the paper).
    extra_terms : further library terms, e.g. ("sign(q1)", "q1*|q1|"), or a plain effect by its name
        (identify.explain.effects: "coulomb_friction" stands for sign(q1)).
    method : "admm" (LASSO path) or "stlsq".
    n_lambdas, lambda_eps : path length and lambda_min / lambda_max (ADMM).
    threshold, normalize_threshold : STLSQ threshold (None: a path) and whether it applies to
        unit-RMS columns (True) or raw coefficients as in the paper's Table 2 (False).
    selection, tolerance : rule ("heldout", "paper", "bic") and its tolerance (None: the rule's default).
    max_terms : optional budget of terms per equation (least costly terms eliminated beyond it).
    budget : how the budget's terms are chosen: "equation-error" (default; backward elimination by the
        one-step acceleration error, identify.selection.pareto) or "free-run" (q1_dot's terms by the free-run
        error of candidates refit on it, estimation data only, identify.selection.budget; the kept terms come
        with their free-run refit coefficients, as with refine="free-run"; slower: minutes on Silverbox).
    budget_refit : rows of the free-run budget winner's final refit: "fit" (default; the validation's
        held-out rows stay unseen) or "all" (fit and held-out rows, once the terms are chosen on the
        fit rows and ranked on the held-out ones; more data for the coefficients, but the validation
        figures are then no longer out-of-sample: result()["validation"]["heldout_fitted"] says so).
    refine : None, or "free-run" to refit the kept coefficients on the free-run simulation error of the
        fit samples (identify.simulation.refine); standard errors are then those of the equation-error fit.
    holdout_fraction : share of samples held out in interleaved blocks; holdout_samples : hold out
        the first N samples instead (paper).
    band_hz, harmonics, taper_s : measurement-chain settings (identify.chain.states.reconstruct_states).
    rig : RigConstants for physical parameters (base-excited layout only).
    validate : run the free-run validation.
    bias_method : how the measurement chain's bias is estimated: "auto" (default; in closed form by the
        corrected score when every kept term is a monomial of the states and input and no offset is
        carried, identify.chain.bias_correction; SIMEX otherwise) or "simex" (always SIMEX, the Monte Carlo).
    bias_replicates : SIMEX replicates, when SIMEX runs (None: by the record's length, 64 up to 250 000
        samples down to 16 from 1e6, uncertainty.replicates_for); 0: no chain-bias correction at all,
        coefficients then ignore it; placements : random held-out placements for the inclusion
        probabilities (0: none). identify.trust.uncertainty.
    mass_kg : moving mass for the physical parameters (rig= overrides it; None: the recording's, else
        the paper's rig, said to be assumed).
    Ranges and choices of the user-settable ones: identify.params.PARAMS (checked at fit).
    """

    def __init__(self, degree: int = 4, extra_terms=(), method: str = "admm", n_lambdas: int = 100,
                 lambda_eps: float = 1e-5, threshold: float | None = None, normalize_threshold: bool = True,
                 selection: str = "heldout", tolerance: float | None = None, max_terms: int | None = None,
                 budget: str = "equation-error", budget_refit: str = "fit", refine: str | None = None,
                 holdout_fraction: float = 0.2, holdout_samples: int | None = None, band_hz=None,
                 harmonics: float = 5.0, taper_s: float | None = None, rig: RigConstants | None = None,
                 validate: bool = True, bias_replicates: int | None = unc.N_REPLICATES,
                 placements: int = unc.N_PLACEMENTS, bias_method: str = "auto", mass_kg: float | None = None):
        self.degree = degree
        self.extra_terms = tuple(extra_terms)
        self.method = method
        self.n_lambdas = n_lambdas
        self.lambda_eps = lambda_eps
        self.threshold = threshold
        self.normalize_threshold = normalize_threshold
        self.selection = selection
        self.tolerance = tolerance
        self.max_terms = max_terms
        self.budget = budget
        self.budget_refit = budget_refit
        self.refine = refine
        self.holdout_fraction = holdout_fraction
        self.holdout_samples = holdout_samples
        self.band_hz = band_hz
        self.harmonics = harmonics
        self.taper_s = taper_s
        self.rig = rig
        self.validate = validate
        self.bias_replicates = bias_replicates
        self.placements = placements
        self.bias_method = bias_method
        self.mass_kg = mass_kg

    # ------------------------------------------------------------------------------------------------
    def _optimizer(self):
        return make_optimizer(self)

    def _rig_constants(self) -> tuple[RigConstants, str]:
        """The rig's constants for the physical parameters and where its mass came from: given (rig=), the
        recordings' (a sweep records its rig configuration's moving mass; a joint fit's recordings must all
        record the same one, else none is taken), or the default, assumed."""
        if self.rig is not None:
            return self.rig, "given"
        if self.mass_kg is not None:
            return RigConstants(mass_kg=float(self.mass_kg)), "given"
        masses = {(getattr(r, "metadata", None) or {}).get("moving_mass_kg") for r in getattr(self, "recordings_", [])}
        if len(masses) == 1 and (mass := masses.pop()):
            return RigConstants(mass_kg=float(mass)), "recording"
        return RigConstants(), "assumed"

    @one_blas_thread  # the whole fit: small BLAS products, oversubscribed under load (identify.threads)
    def fit(self, recording: "Recording | list[Recording]") -> "SparseIdentifier":
        """Fit to one Recording, or to a list of them: one model for several recordings of the same
        rig (identify.joint: chain and held-out blocks per recording, normal equations summed)."""
        recordings = list(recording) if isinstance(recording, (list, tuple)) else [recording]
        several = len(recordings) != 1  # decided here, once
        if several:
            joint.refuse(self, recordings)
        self._check_options()
        timings = {}
        t0 = time.perf_counter()
        sources = [RecordingEquations.read(r, self) for r in recordings]
        timings["chain"] = time.perf_counter() - t0
        if several:
            joint.refuse_mixed_layouts(sources)
        self.library_ = Library(("q1", "q2"), (sources[0].sig.input_name,), self.degree, expand_terms(self.extra_terms))
        # recordings_: what was fitted, one or several (the one list callers read); recording_ only for one
        self.recordings_, self.recording_, self.joint_ = recordings, (None if several else recordings[0]), None
        runs = fit_sources(self, sources, timings)
        # states_ names the states and input; a joint fit's bands and rows are per recording (joint_)
        self.states_ = self.sources_[0].sig
        if several:
            self.joint_states_ = [s.sig for s in self.sources_]
            joint.check_consistency(self, runs, timings)
        self.timings_ = timings
        return self

    def _check_options(self) -> None:
        """Every user-settable parameter refused out of its range or choices before any work, as the CLI
        and the HTTP schema refuse it (all three from identify.params.PARAMS)."""
        params.check({p.name: getattr(self, p.name) for p in params.PARAMS})
        self._optimizer()

    # the fit sequence's steps as the tests and benchmarks call them on a fitted identifier
    def _gram(self, sig, edges, columns=None):
        return state_gram(self.library_, sig, edges, columns)

    def _select(self, path, train, heldout, n_eff: float) -> dict:
        return select_supports(self, path, train, heldout, n_eff)

    def _placement_supports(self, trains, heldouts, n_eff: float) -> list:
        return placement_supports(self, self.path_, trains, heldouts, n_eff)

    # ------------------------------------------------------------------------------------------------
    def result(self) -> dict:
        """The identification result as one JSON-ready dict (the CLI's --json document)."""
        lib = self.library_
        sig = self.states_
        sel = {"rule": self.selection, "max_terms": self.max_terms, "budget": self.budget,
               "budget_refit": self.budget_refit,
               "tolerance": DEFAULT_TOLERANCE[self.selection] if self.tolerance is None else self.tolerance}
        for eq, s in self.selections_.items():
            e = 0 if eq == "q1_dot" else 1
            sel[eq] = {"index": s.index, "n_terms": int(s.support.sum()),
                       self.path_.param_name: float(self.path_.params[s.index, e]),
                       "score": float(s.score[s.index]),
                       # the rule's tolerance line on the score (an STLSQ path's own parameter is
                       # also named "threshold": this key must not overwrite it)
                       "score_tolerance": None if np.isnan(s.threshold) else float(s.threshold)}
        out = {
            "status": self.verdict_["status"],
            "reason": self.verdict_["reason"],
            "model": self.model_.to_dict()["model"],
            "standard_errors": self.standard_errors_,
            "inclusion_probability": self.uncertainty_["inclusion_probability"],
            # kept terms within SIGNIFICANT_Z standard errors of zero: not in the model (identify.fitting.trust)
            "uncertain_terms": self.uncertain_terms_,
            "uncertainty": {k: v for k, v in self.uncertainty_.items() if k != "inclusion_probability"},
            "states": {"q1": "relative velocity" if sig.input_name == "zdd" else "output derivative",
                       "q2": "relative displacement" if sig.input_name == "zdd" else "output"},
            "inputs": [sig.input_name],
            "method": self.method,
            "library": {"degree": self.degree, "terms": lib.names},
            "selection": sel,
            "chain": {"band_hz": list(sig.band_hz), "valid_samples": [sig.valid.start, sig.valid.stop],
                      "fit_samples": int(sum(np.diff(e)[~h].sum() for e, h in self.blocks_)),
                      "heldout_samples": int(sum(np.diff(e)[h].sum() for e, h in self.blocks_)),
                      "holdout": (f"the first {self.holdout_samples} samples; those from sample {sig.valid.start} on, "
                                  "past the integration filter's cut edge" if self.holdout_samples is not None
                                  else f"{self.holdout_fraction:.0%} in interleaved blocks"),
                      "displacement_below_band": self.offset_},
            "refinement": self.refinement_,
            "budget": None if self.budget_ is None else {"seconds": self.budget_.seconds, "pool": self.budget_.pool,
                                                         "candidates": self.budget_.candidates[:N_REPORTED]},
            "validation": self.validation_,
            "timings_s": self.timings_,
        }
        if sig.input_name == "zdd":
            out["physical"] = physical_parameters(self.model_, *self._rig_constants())
        if getattr(self, "joint_", None) is not None:
            out = joint.joint_result(self, out)
        return out
