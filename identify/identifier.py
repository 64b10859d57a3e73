"""SparseIdentifier: recording in, validated sparse ODE model out (the paper's Algorithm 1, done right).

    rec = read_recording("sweep.csv")
    ident = SparseIdentifier().fit(rec)
    ident.model_            # SparseModel: {"q1_dot": {"q1": -3.73, ...}, "q2_dot": {"q1": 1.0}}
    ident.result()          # the JSON document `shakeid identify --json` prints

Steps: states from the measurement chain (identify.chain) -> library matrix over the valid samples ->
per-block normal equations -> sparse path on the training blocks (ADMM-LASSO or STLSQ) -> selection and
least-squares refit per equation -> standard errors -> free-run validation on the held-out blocks.

Held-out samples: by default 20 % of the record in 10 blocks spread evenly over it, so a sweep's every
frequency range (the resonance included) contributes to both fit and validation. `holdout_samples=N`
holds out the first N samples instead, as the paper did (30000): that removes the sweep's start, and with
it the resonance of a 1-20 Hz sweep of this rig, from the fit.
"""
from __future__ import annotations

import time

import numpy as np

from .chain import StateSignals, reconstruct_states
from .errors import IdentificationError
from . import uncertainty as unc
from .budget import choose_budget
from .gram import BlockGram
from .inband import band_limited_gram, carry_offset, has_even_force
from .library import Library
from .model import SparseModel
from .optimizers import ADMMLasso, STLSQ
from .optimizers.base import least_squares
from .physical import RigConstants, physical_parameters
from .recording import Recording
from .refine import refine_free_run
from .selection import DEFAULT_TOLERANCE, heldout_supports, select
from .validation import fit_verdict, validate

N_BLOCKS = 50
BUDGETS = ("equation-error", "free-run")
BUDGET_REFITS = ("fit", "all")
BIAS_METHODS = ("auto", "simex")
N_REPORTED = 10  # budget candidates listed in the result


def holdout_blocks(sig: StateSignals, fraction: float = 0.2, first_samples: int | None = None):
    """Block edges over the valid rows, and which blocks are held out.

    Default: N_BLOCKS equal blocks, `fraction` of them held out, spread evenly over the record.
    `first_samples`: hold out the record's first N samples instead (the paper's split)."""
    n = sig.valid.stop - sig.valid.start
    if first_samples is not None:
        n1 = int(np.clip(first_samples - sig.valid.start, 0, n))
        if n - n1 < 64:
            raise IdentificationError(f"holding out {first_samples} samples leaves {n - n1} to fit")
        nb1 = max(int(round(N_BLOCKS * n1 / n)), 1) if n1 else 0
        e1 = np.linspace(0, n1, nb1 + 1).round().astype(int) if n1 else np.array([0])
        e2 = np.linspace(n1, n, N_BLOCKS - nb1 + 1).round().astype(int)
        edges = np.concatenate([e1, e2[1:]])
        return edges, np.arange(edges.size - 1) < nb1
    nb = int(min(N_BLOCKS, max(n // 64, 2)))
    edges = np.linspace(0, n, nb + 1).round().astype(int)
    n_ho = int(round(fraction * nb))
    held = np.zeros(nb, dtype=bool)
    if n_ho:
        held[((np.arange(n_ho) + 0.5) * nb / n_ho).astype(int)] = True
    return edges, held


def effective_samples(sig: StateSignals) -> float:
    """Independent samples a band-limited record carries, 2 B T (the bic rule's n_eff)."""
    return 2 * (sig.band_hz[1] - sig.band_hz[0]) * (sig.valid.stop - sig.valid.start) / sig.fs_hz


def per_record(rows: np.ndarray, sig):
    """f -> f(rows) for one recording (sig a StateSignals); for several (sig a list, rows a mask over
    all their valid rows, one after the other), f -> [f(part) for each recording's part of rows]."""
    if not isinstance(sig, (list, tuple)):
        return lambda f: f(rows)
    parts = np.split(rows, np.cumsum([s.valid.stop - s.valid.start for s in sig])[:-1])
    return lambda f: [f(p) for p in parts]


class SparseIdentifier:
    """Parameters (stored as given, sklearn-style; fitted attributes end in `_`):

    degree : highest monomial degree of the library (4 as in the paper).
    extra_terms : further library terms, e.g. ("sign(q1)", "q1*|q1|").
    method : "admm" (LASSO path) or "stlsq".
    n_lambdas, lambda_eps : path length and lambda_min / lambda_max (ADMM).
    threshold, normalize_threshold : STLSQ threshold (None: a path) and whether it applies to
        unit-RMS columns (True) or raw coefficients as in the paper's Table 2 (False).
    selection, tolerance : rule ("heldout", "paper", "bic") and its tolerance (None: the rule's default).
    max_terms : optional budget of terms per equation (least costly terms eliminated beyond it).
    budget : how the budget's terms are chosen: "equation-error" (default; backward elimination by the
        one-step acceleration error, identify.selection) or "free-run" (q1_dot's terms by the free-run
        error of candidates refit on it, estimation data only, identify.budget; the kept terms come
        with their free-run refit coefficients, as with refine="free-run"; slower: minutes on Silverbox).
    budget_refit : rows of the free-run budget winner's final refit: "fit" (default; the validation's
        held-out rows stay unseen) or "all" (fit and held-out rows, once the terms are chosen on the
        fit rows and ranked on the held-out ones; more data for the coefficients, but the validation
        figures are then no longer out-of-sample: result()["validation"]["heldout_fitted"] says so).
    refine : None, or "free-run" to refit the kept coefficients on the free-run simulation error of the
        fit samples (identify.refine); standard errors are then those of the equation-error fit.
    holdout_fraction : share of samples held out in interleaved blocks; holdout_samples : hold out
        the first N samples instead (paper).
    band_hz, harmonics, taper_s : measurement-chain settings (identify.chain.reconstruct_states).
    rig : RigConstants for physical parameters (base-excited layout only).
    validate : run the free-run validation.
    bias_method : how the measurement chain's bias is estimated: "auto" (default; in closed form by the
        corrected score when every kept term is a monomial of the states and input and no offset is
        carried, identify.corrected; SIMEX otherwise) or "simex" (always SIMEX, the Monte Carlo).
    bias_replicates : SIMEX replicates, when SIMEX runs (None: by the record's length, 64 up to 250 000
        samples down to 16 from 1e6, uncertainty.replicates_for); 0: no chain-bias correction at all,
        coefficients then ignore it; placements : random held-out placements for the inclusion
        probabilities (0: none). identify.uncertainty.
    """

    def __init__(self, degree: int = 4, extra_terms=(), method: str = "admm", n_lambdas: int = 100,
                 lambda_eps: float = 1e-5, threshold: float | None = None, normalize_threshold: bool = True,
                 selection: str = "heldout", tolerance: float | None = None, max_terms: int | None = None,
                 budget: str = "equation-error", budget_refit: str = "fit", refine: str | None = None,
                 holdout_fraction: float = 0.2, holdout_samples: int | None = None, band_hz=None,
                 harmonics: float = 5.0, taper_s: float | None = None, rig: RigConstants | None = None,
                 validate: bool = True, bias_replicates: int | None = unc.N_REPLICATES,
                 placements: int = unc.N_PLACEMENTS, bias_method: str = "auto"):
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

    # ------------------------------------------------------------------------------------------------
    def _optimizer(self):
        if self.method == "admm":
            return ADMMLasso(n_lambdas=self.n_lambdas, eps=self.lambda_eps)
        if self.method == "stlsq":
            return STLSQ(threshold=self.threshold, n_thresholds=self.n_lambdas, eps=self.lambda_eps,
                         normalize=self.normalize_threshold)
        raise IdentificationError(f"unknown method {self.method!r} (admm or stlsq)")

    def _rig_constants(self) -> tuple[RigConstants, str]:
        """The rig's constants for the physical parameters and where its mass came from: given (rig=), the
        recording's (a sweep records its rig configuration's moving mass), or the default, assumed."""
        if self.rig is not None:
            return self.rig, "given"
        mass = (getattr(getattr(self, "recording_", None), "metadata", None) or {}).get("moving_mass_kg")
        if mass:
            return RigConstants(mass_kg=float(mass)), "recording"
        return RigConstants(), "assumed"

    def fit(self, recording: "Recording | list[Recording]") -> "SparseIdentifier":
        """Fit to one Recording, or to a list of them: one model for several recordings of the same
        rig (identify.joint: chain and held-out blocks per recording, normal equations summed)."""
        if isinstance(recording, (list, tuple)):
            if len(recording) != 1:
                from .joint import fit_joint

                self._check_options()
                return fit_joint(self, list(recording))
            recording = recording[0]
        self._check_options()
        timings = {}
        t0 = time.perf_counter()
        sig = reconstruct_states(recording, self.band_hz, self.harmonics, self.taper_s)
        timings["chain"] = time.perf_counter() - t0
        self.recording_ = recording
        self.states_ = sig
        self.joint_ = None
        self.library_ = Library(("q1", "q2"), (sig.input_name,), self.degree, self.extra_terms)
        return self._fit_signals(sig, timings)

    def _check_options(self) -> None:
        """Options refused before any work (an unknown method, refine, budget)."""
        if self.refine not in (None, "free-run"):  # refused before any work, like an unknown method
            raise IdentificationError(f"unknown refine {self.refine!r} (free-run)")
        if self.budget not in BUDGETS:
            raise IdentificationError(f"unknown budget {self.budget!r} ({', '.join(BUDGETS)})")
        if self.bias_method not in BIAS_METHODS:
            raise IdentificationError(f"unknown bias_method {self.bias_method!r} ({', '.join(BIAS_METHODS)})")
        if self.budget_refit not in BUDGET_REFITS:
            raise IdentificationError(f"unknown budget_refit {self.budget_refit!r} ({', '.join(BUDGET_REFITS)})")
        self._optimizer()

    def _fit_signals(self, sig: StateSignals, timings: dict) -> "SparseIdentifier":
        lib = self.library_
        edges, held = holdout_blocks(sig, self.holdout_fraction, self.holdout_samples)
        t0 = time.perf_counter()
        gram = self._gram(sig, edges)
        timings["library_gram"] = time.perf_counter() - t0
        train, heldout, coefs = self._fit_pass(effective_samples(sig), gram, held, timings)
        # The terms are those of the true displacement: when the selected force has an even part (an
        # asymmetric spring) it rectifies into a displacement below the band the chain cannot see; find
        # it (identify.inband) and fit again on q2 + offset. An odd force (the textbook rig) needs none.
        t0 = time.perf_counter()
        self.offset_ = {"carried": False, "passes": 0}
        if sig.band_hz[0] > 0 and has_even_force(SparseModel(coefs, ("q1", "q2"), (sig.input_name,)), sig):
            sig, gram, self.offset_ = carry_offset(lib, sig, edges, ~held)
            train, heldout, coefs = self._fit_pass(effective_samples(sig), gram, held, timings)
        timings["offset"] = time.perf_counter() - t0
        self.states_ = sig
        self.heldout_rows_ = np.repeat(held, np.diff(edges))
        coefs = self._budget_by_free_run(sig, train, held, coefs, timings)
        t0 = time.perf_counter()
        # the selection-time fit (training blocks only) is what the held-out validation scores; the
        # reported coefficients are the kept terms refit on all rows, less the chain's bias
        # (identify.uncertainty, docs/identification.md section 5)
        self.training_model_ = SparseModel(coefs, ("q1", "q2"), (sig.input_name,))
        bias_of = None
        if self.bias_replicates != 0 and getattr(self, "recording_", None) is not None:
            def bias_of(sups, coefs):
                return unc.estimate_chain_bias(self.bias_method, self.recording_, sig, gram, self.library_, sups,
                                               coefs, lambda s2, cols: self._gram(s2, gram.edges, cols),
                                               self.bias_replicates)
        reported, self.standard_errors_, self.uncertainty_ = self._trust(gram, held, effective_samples(sig), bias_of)
        timings["refit_uncertainty"] = time.perf_counter() - t0
        self.model_ = SparseModel(reported, ("q1", "q2"), (sig.input_name,), self.standard_errors_)
        validated = self._free_run_choice(sig, timings)
        self.validation_ = None
        if self.validate:
            t0 = time.perf_counter()
            self.validation_, self.simulated_states_, self.simulated_q1_dot_ = validate(
                validated, sig, self.heldout_rows_ if held.any() else np.ones_like(self.heldout_rows_))
            timings["validation"] = time.perf_counter() - t0
            if self.budget_ is not None and self.budget_refit == "all":
                self.validation_["heldout_fitted"] = True  # the winner's coefficients saw these rows
        # a fitted model that does not reproduce the motion is kept (a library user may inspect it) but
        # reported as failed: verdict_ = {"status": "ok" | "failed" | "unvalidated", "reason": ...}
        # judged on the validated fit (the training-only one, unless a budget or refine replaced both) and,
        # when the reported all-rows fit differs, on its physics too: failed if either cannot be the rig
        self.verdict_ = fit_verdict(self.validation_, validated, self.model_, sig.input_name)
        self.timings_ = timings
        return self

    def _free_run_choice(self, sig, timings: dict) -> SparseModel:
        """The model the free run validates: the training fit; or, with the free-run budget, its winner
        (chosen after its free-run refit), or, with refine="free-run", the training fit refit on the fit
        rows' free-run error; both are then reported too (with the equation-error standard errors).
        sig: the StateSignals, or a list of them for several recordings (identify.joint)."""
        self.refinement_ = None
        if self.budget_ is not None:
            self.model_ = SparseModel(self.budget_.model.equations, ("q1", "q2"), (self.states_.input_name,),
                                      self.standard_errors_)
            self.refinement_ = self.budget_.refinement
            return self.model_
        if self.refine is None:
            return self.training_model_
        t0 = time.perf_counter()
        refined, self.refinement_ = refine_free_run(self.training_model_, sig,
                                                    per_record(self.heldout_rows_, sig)(np.logical_not))
        self.model_ = SparseModel(refined.equations, refined.states, refined.inputs, self.standard_errors_)
        timings["refine"] = time.perf_counter() - t0
        return self.model_

    def _gram(self, sig: StateSignals, edges, columns=None) -> BlockGram:
        """Per-block normal equations of the library on the model's states. With an offset carried
        (an even force) every column goes through the chain's band (identify.inband, as explain's
        screen does): an even term's DC and slow part are not in the measured acceleration, and on
        raw columns an offset a few % off shows as a spurious constant, q1^4, q2^4 (3e4 N/m^2 rig).
        Without one (odd forces) the columns stay as they are and are streamed in chunks: through the
        band, the degree-4 even terms fit the chain's low-frequency error on short sweeps (exact
        supports 9 of 24 instead of 21 of 24, docs/identification.md), while raw, their DC costs.
        `columns`: those library columns only (indices)."""
        lib = self.library_ if columns is None else self.library_.subset(columns)
        v = sig.valid
        # q2_dot = q1 by construction of the chain, so the second target is q1 itself
        targets = (sig.q1_dot[v], sig.q1[v])
        if sig.q2_offset is not None:
            return band_limited_gram(lib, sig, targets, edges)
        return BlockGram.from_library(lib, (sig.q1[v], sig.q2[v]), sig.input[v][:, None], targets, edges)

    def _fit_pass(self, n_eff: float, gram: BlockGram, held, timings: dict):
        """Path, selection and refit per equation on the Grams of the states (n_eff: effective_samples).
        Returns (training and held-out normal equations, coefficients by equation)."""
        lib = self.library_
        train, heldout = gram.equations(~held), gram.equations(held) if held.any() else None
        t0 = time.perf_counter()
        self.path_ = self._optimizer().fit_path(train)
        timings["path"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.selections_ = self._select(self.path_, train, heldout, n_eff)
        coefs = {eq: {lib.names[j]: float(s.coef[j]) for j in np.flatnonzero(s.coef)}
                 for eq, s in self.selections_.items()}
        timings["selection_refit"] = time.perf_counter() - t0
        return train, heldout, coefs

    def _select(self, path, train, heldout, n_eff: float) -> dict:
        """The rule's choice per equation on a path (no side effects: the inclusion probabilities rerun it)."""
        by_free_run = self.budget == "free-run" and self.max_terms is not None  # then chosen after the offset
        return {eq: select(path, e, train, heldout, self.selection, self.tolerance, n_eff,
                           None if by_free_run and e == 0 else self.max_terms)
                for e, eq in enumerate(("q1_dot", "q2_dot"))}

    def _budget_by_free_run(self, sig, train, held, coefs: dict, timings: dict) -> dict:
        """With budget="free-run", the first equation's max_terms terms chosen by free-run error
        (identify.budget); sets budget_ (None otherwise) and returns the coefficients by equation.
        sig: the StateSignals, or a list of them for several recordings (heldout_rows_ then spans them all)."""
        self.budget_ = None
        sel = self.selections_["q1_dot"]
        if self.budget != "free-run" or self.max_terms is None or sel.support.sum() <= self.max_terms:
            return coefs
        lib = self.library_
        start = SparseModel(coefs, ("q1", "q2"), (self.states_.input_name,))
        each = per_record(self.heldout_rows_, sig)  # f -> f(mask), or [f(mask) per recording] for several
        self.budget_ = choose_budget(start, lib.names, sel.support, self.max_terms, train, sig,
                                     each(np.logical_not), each(np.asarray) if held.any() else None,
                                     final_rows=each(np.ones_like) if self.budget_refit == "all" else None)
        timings["budget"] = self.budget_.seconds
        sel.support = self.budget_.support.copy()
        sel.coef = least_squares(train.G, train.B[:, 0], sel.support)
        return {eq: {lib.names[j]: float(s.coef[j]) for j in np.flatnonzero(s.coef)}
                for eq, s in self.selections_.items()}

    def _placement_supports(self, trains, heldouts, n_eff: float) -> list:
        """Per held-out placement, the supports (one per equation) this identifier's path and rule
        choose on its training and held-out normal equations; the paths run as one batch, started from
        the fit's own path (a placement moves a few blocks: its solutions are near the fit's)."""
        paths = self._optimizer().fit_paths(trains, start=self.path_)
        if self.selection == "heldout" and self.max_terms is None:  # the default: all placements at once
            by_eq = [heldout_supports(paths, e, trains, heldouts, self.tolerance) for e in range(2)]
            return [list(supports) for supports in zip(*by_eq)]
        return [[s.support for s in self._select(path, train, heldout, n_eff).values()]
                for path, train, heldout in zip(paths, trains, heldouts)]

    def _trust(self, gram: BlockGram, held, n_eff: float, bias_of) -> tuple[dict, dict, dict]:
        """Reported coefficients, standard errors and inclusion probabilities (identify.uncertainty);
        bias_of(supports, coefs) -> unc.chain_bias(...) or None."""
        names, eqs = self.library_.names, list(self.selections_)
        sups = {e: s.support for e, s in enumerate(self.selections_.values())}

        def fit_and_select(trains, heldouts):
            return self._placement_supports(trains, heldouts, n_eff)

        coefs, var, info = unc.assess(gram, held, sups, bias_of, fit_and_select, self.placements)
        named = {eqs[e]: {names[j]: j for j in np.flatnonzero(sups[e])} for e in sups}
        info = unc.name_info(info, eqs, names, sups)
        info["exact"] = {}
        if "q2_dot" in eqs and list(named["q2_dot"]) == ["q1"]:
            # the second target is the chain's q1, the derivative of its q2 on the band's bins: q2_dot = q1
            # holds by construction, and its least-squares coefficient is 1 and its standard error 0 to
            # rounding (0.9999999999999999 +- 6e-17 on a Table 1 sweep), which would read as a measurement
            e = eqs.index("q2_dot")
            coefs[e][named["q2_dot"]["q1"]], var[e][named["q2_dot"]["q1"]] = 1.0, 0.0
            info["exact"]["q2_dot"] = "q2_dot = q1 by construction: the chain's velocity is the derivative of its displacement"
        return ({eq: {n: float(coefs[e][j]) for n, j in named[eq].items()} for e, eq in enumerate(eqs)},
                {eq: {n: float(np.sqrt(var[e][j])) for n, j in named[eq].items()} for e, eq in enumerate(eqs)},
                info)

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
            "uncertainty": {k: v for k, v in self.uncertainty_.items() if k != "inclusion_probability"},
            "states": {"q1": "relative velocity" if sig.input_name == "zdd" else "output derivative",
                       "q2": "relative displacement" if sig.input_name == "zdd" else "output"},
            "inputs": [sig.input_name],
            "method": self.method,
            "library": {"degree": self.degree, "terms": lib.names},
            "selection": sel,
            "chain": {"band_hz": list(sig.band_hz), "valid_samples": [sig.valid.start, sig.valid.stop],
                      "fit_samples": int(np.count_nonzero(~self.heldout_rows_)),
                      "heldout_samples": int(np.count_nonzero(self.heldout_rows_)),
                      "holdout": ("first %d samples" % self.holdout_samples if self.holdout_samples is not None
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
            from .joint import joint_result

            out = joint_result(self, out)
        return out
