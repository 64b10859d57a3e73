"""The one fit sequence: recordings' normal equations in, a validated sparse model with its trust out.

    path -> selection -> (displacement below the band) -> (free-run budget) -> all-rows refit, chain
    bias, standard errors, inclusion probabilities -> (free-run refinement) -> validation -> verdict

Internally there is always a list of recordings, each a *normal-equations source*
(identify.regression.sources.NormalEquationsSource): its chain's states (or, out of core, their summary), its
per-block normal equations on given block edges, what the chain bias and the noise's share of the
variance need of it, and its free-run validation. In core (sources.RecordingEquations) and out of core
(out_of_core.ChunkedEquations) differ only in how they produce those; the decisions made from them are
the same code. Joint identification (identify.joint) is this sequence on several sources plus the
consistency check across them.

The identifier (identify.identifier.SparseIdentifier) holds the parameters and receives the fitted
attributes; this module reads its parameters and sets them (model_, standard_errors_, validation_, ...).
"""
from __future__ import annotations

import time

import numpy as np

from .trust import uncertainty as unc
from .selection.budget import choose_budget
from .chain.states import StateSignals
from .errors import IdentificationError
from .regression.gram import BlockGram
from .model import SparseModel
from .regression.optimizers import ADMMLasso, STLSQ
from .regression.optimizers.base import least_squares
from .simulation.refine import refine_free_run
from .selection.pareto import heldout_supports, select
from .regression.sources import state_gram
from .simulation.validation import fit_verdict, pooled_validation

N_BLOCKS = 50
STATES = ("q1", "q2")
EQUATIONS = ("q1_dot", "q2_dot")


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


def make_optimizer(params):
    """The path's optimizer from the identifier's method, n_lambdas, lambda_eps, threshold."""
    if params.method == "admm":
        return ADMMLasso(n_lambdas=params.n_lambdas, eps=params.lambda_eps)
    if params.method == "stlsq":
        return STLSQ(threshold=params.threshold, n_thresholds=params.n_lambdas, eps=params.lambda_eps,
                     normalize=params.normalize_threshold)
    raise IdentificationError(f"unknown method {params.method!r} (admm or stlsq)")


def select_supports(params, path, train, heldout, n_eff: float) -> dict:
    """The rule's choice per equation on a path (no side effects: the inclusion probabilities rerun it)."""
    by_free_run = params.budget == "free-run" and params.max_terms is not None  # then chosen after the offset
    return {eq: select(path, e, train, heldout, params.selection, params.tolerance, n_eff,
                       None if by_free_run and e == 0 else params.max_terms)
            for e, eq in enumerate(EQUATIONS)}


def placement_supports(params, path, trains, heldouts, n_eff: float) -> list:
    """Per held-out placement, the supports (one per equation) the path and rule choose on its training
    and held-out normal equations; the paths run as one batch, started from the fit's own `path` (a
    placement moves a few blocks: its solutions are near the fit's)."""
    paths = make_optimizer(params).fit_paths(trains, start=path)
    if params.selection == "heldout" and params.max_terms is None:  # the default: all placements at once
        by_eq = [heldout_supports(paths, e, trains, heldouts, params.tolerance) for e in range(2)]
        return [list(supports) for supports in zip(*by_eq)]
    return [[s.support for s in select_supports(params, p, train, heldout, n_eff).values()]
            for p, train, heldout in zip(paths, trains, heldouts)]


def _named(selections: dict, names) -> dict:
    return {eq: {names[j]: float(s.coef[j]) for j in np.flatnonzero(s.coef)} for eq, s in selections.items()}


def fit_pass(ident, n_eff: float, gram: BlockGram, held, timings: dict):
    """Path, selection and refit per equation on the normal equations (sets path_, selections_).
    Returns (training normal equations, coefficients by equation)."""
    train, heldout = gram.equations(~held), gram.equations(held) if held.any() else None
    t0 = time.perf_counter()
    ident.path_ = make_optimizer(ident).fit_path(train)
    timings["path"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ident.selections_ = select_supports(ident, ident.path_, train, heldout, n_eff)
    timings["selection_refit"] = time.perf_counter() - t0
    return train, _named(ident.selections_, ident.library_.names)


def fit_sources(ident, sources: list, timings: dict) -> list:
    """The sequence (module doc) on one or several sources; sets the identifier's fitted attributes and
    returns the per-recording validation runs (source.validate's second value; None unvalidated)."""
    input_name, lib = sources[0].sig.input_name, ident.library_
    t0 = time.perf_counter()
    blocks = [holdout_blocks(s.sig, ident.holdout_fraction, ident.holdout_samples) for s in sources]
    grams = [s.gram(lib, edges) for s, (edges, _) in zip(sources, blocks)]
    gram = grams[0] if len(grams) == 1 else BlockGram.concatenate(grams)
    held = np.concatenate([h for _, h in blocks])
    timings["library_gram"] = timings.get("library_gram", 0.0) + time.perf_counter() - t0
    n_eff = sum(effective_samples(s.sig) for s in sources)
    train, coefs = fit_pass(ident, n_eff, gram, held, timings)
    # The terms are those of the true displacement: when the selected force has an even part (an
    # asymmetric spring) it rectifies into a displacement below the band the chain cannot see; the
    # source finds it (identify.chain.inband) and the pass runs again on q2 + offset. An odd force needs none.
    t0 = time.perf_counter()
    ident.offset_ = {"carried": False, "passes": 0}
    even, trusted = _established_even_force(ident, sources, blocks, gram, held, n_eff, coefs)
    if even and len(sources) > 1:
        raise IdentificationError(
            "the joint fit has a force with an even part (" + ", ".join(_named(ident.selections_, lib.names)["q1_dot"])
            + "): its displacement below the band is carried per record (identify.chain.inband), which joint "
            "identification does not do; identify the recordings one by one")
    if even:
        sources[0], gram, ident.offset_ = sources[0].carry_offset(lib, blocks[0][0], ~held)
        train, coefs = fit_pass(ident, n_eff, gram, held, timings)
        trusted = None  # a new selection on the carried displacement: trusted afresh below
    elif trusted is not None:
        coefs = _named(ident.selections_, lib.names)
    timings["offset"] = time.perf_counter() - t0 - (trusted[3] if trusted is not None else 0.0)
    sigs = [s.sig for s in sources]
    each = sigs[0] if len(sigs) == 1 else sigs  # what per_record, budget and refine take
    ident.heldout_rows_ = np.concatenate([np.repeat(h, np.diff(e)) for e, h in blocks]) if sources[0].in_core else None
    ident.blocks_ = blocks
    coefs = _budget_by_free_run(ident, each, train, held, coefs, timings)
    t0 = time.perf_counter()
    # the reported coefficients are the kept terms refit on all rows, less the chain's bias; a kept term
    # within SIGNIFICANT_Z standard errors of zero is reported apart (identify.trust.uncertainty,
    # docs/identification.md section 5). The selection-time fit (training blocks only) of the terms left is
    # what the held-out validation scores. An even selection not carried was trusted already, on this path.
    if trusted is None:
        reported, ident.standard_errors_, ident.uncertainty_ = trust(ident, sources, blocks, gram, held, n_eff)
    else:
        reported, ident.standard_errors_, ident.uncertainty_, seconds = trusted
        t0 -= seconds
    ident.training_model_ = SparseModel(_named(ident.selections_, lib.names), STATES, (input_name,))
    timings["refit_uncertainty"] = time.perf_counter() - t0
    ident.model_ = SparseModel(reported, STATES, (input_name,), ident.standard_errors_)
    validated = _free_run_choice(ident, each, timings)
    ident.validation_, runs = None, [None] * len(sources)
    if ident.validate:
        t0 = time.perf_counter()
        docs_runs = [s.validate(validated, e, h) for s, (e, h) in zip(sources, blocks)]
        runs = [r for _, r in docs_runs]
        ident.validation_ = docs_runs[0][0] if len(sources) == 1 else pooled_validation(validated, runs)
        if len(sources) == 1 and runs[0] is not None:  # one record in core: the free run itself (reports draw it)
            ident.simulated_states_, ident.simulated_q1_dot_ = runs[0][2], runs[0][3]
        timings["validation"] = time.perf_counter() - t0
        if ident.budget_ is not None and ident.budget_refit == "all":
            ident.validation_["heldout_fitted"] = True  # the winner's coefficients saw these rows
    # a fitted model that does not reproduce the motion is kept (a library user may inspect it) but
    # reported as failed, judged on the validated fit and, when the reported all-rows fit differs, on its
    # physics too (validation.fit_verdict)
    ident.verdict_ = fit_verdict(ident.validation_, validated, ident.model_, input_name)
    ident.sources_, ident.gram_, ident.validated_model_ = sources, gram, validated
    return runs


def _established_even_force(ident, sources, blocks, gram, held, n_eff, coefs) -> tuple[list, tuple | None]:
    """(sources whose selected force has an even part the data establish, trust's (reported, standard
    errors, info, seconds) when it ran on the way, else None).

    Carrying the displacement below the band for an even force the data do not establish hurts: the
    band-limited columns it brings invite other even terms. A sweep streamed from the simulated Table 1 rig
    (2 of 52 power-ons) selected q2^2 and q2^4 (within 2.3 and 0.2 standard errors of zero); carried, the
    second pass added q1^4 at -4.4 standard errors, which stayed in the reported model; decided on the
    trusted terms it is the true five. So before the offset is carried, an even selection goes through
    trust (its uncertain terms leave the selection, as they would after). If what stays is odd, that trust
    is the fit's (the same path and selection); if it is even, the offset is carried and the new selection
    is trusted afresh. Where a free-run budget will choose the terms (_budget_binds: trust's rule does not
    run on the budget's choice), the selection's own even part decides."""
    def even_sources(coefs):
        training = SparseModel(coefs, STATES, (sources[0].sig.input_name,))
        return [s for s in sources if s.sig.band_hz[0] > 0 and s.even_force(training)]

    even = even_sources(coefs)
    if not even or _budget_binds(ident):
        return even, None
    ident.budget_ = None  # set for good by _budget_by_free_run; trust reads it
    t0 = time.perf_counter()
    reported, se, info = trust(ident, sources, blocks, gram, held, n_eff)
    return even_sources(_named(ident.selections_, ident.library_.names)), (reported, se, info,
                                                                            time.perf_counter() - t0)


def _budget_binds(ident) -> bool:
    """Whether the free-run budget chooses the first equation's terms (budget="free-run" and the selection
    holds more than max_terms)."""
    return (ident.budget == "free-run" and ident.max_terms is not None
            and ident.selections_["q1_dot"].support.sum() > ident.max_terms)


def _budget_by_free_run(ident, sig, train, held, coefs: dict, timings: dict) -> dict:
    """With budget="free-run", the first equation's max_terms terms chosen by free-run error
    (identify.selection.budget); sets budget_ (None otherwise) and returns the coefficients by equation.
    sig: the StateSignals, or a list of them for several recordings (heldout_rows_ then spans them all)."""
    ident.budget_ = None
    sel = ident.selections_["q1_dot"]
    if not _budget_binds(ident):
        return coefs
    lib = ident.library_
    start = SparseModel(coefs, STATES, ((sig[0] if isinstance(sig, list) else sig).input_name,))
    each = per_record(ident.heldout_rows_, sig)  # f -> f(mask), or [f(mask) per recording] for several
    ident.budget_ = choose_budget(start, lib.names, sel.support, ident.max_terms, train, sig,
                                  each(np.logical_not), each(np.asarray) if held.any() else None,
                                  final_rows=each(np.ones_like) if ident.budget_refit == "all" else None)
    timings["budget"] = ident.budget_.seconds
    sel.support = ident.budget_.support.copy()
    sel.coef = least_squares(train.G, train.B[:, 0], sel.support)
    return _named(ident.selections_, lib.names)


def _free_run_choice(ident, sig, timings: dict) -> SparseModel:
    """The model the free run validates: the training fit; or, with the free-run budget, its winner
    (chosen after its free-run refit), or, with refine="free-run", the training fit refit on the fit
    rows' free-run error; both are then reported too (with the equation-error standard errors)."""
    ident.refinement_ = None
    inputs = ident.model_.inputs
    if ident.budget_ is not None:
        ident.model_ = SparseModel(ident.budget_.model.equations, STATES, inputs, ident.standard_errors_)
        ident.refinement_ = ident.budget_.refinement
        return ident.model_
    if ident.refine is None:
        return ident.training_model_
    t0 = time.perf_counter()
    refined, ident.refinement_ = refine_free_run(ident.training_model_, sig,
                                                 per_record(ident.heldout_rows_, sig)(np.logical_not))
    ident.model_ = SparseModel(refined.equations, refined.states, refined.inputs, ident.standard_errors_)
    timings["refine"] = time.perf_counter() - t0
    return ident.model_


def trust(ident, sources: list, blocks: list, gram: BlockGram, held, n_eff: float) -> tuple[dict, dict, dict]:
    """Reported coefficients, standard errors and inclusion probabilities (identify.trust.uncertainty), the
    chain bias from the sources (closed form where every source can give it, SIMEX in core otherwise).
    Kept terms within unc.SIGNIFICANT_Z standard errors of zero leave the selection (its support and
    training fit) and the reported model one at a time (_leave_out_uncertain); ident.uncertain_terms_ lists
    them with the all-rows coefficient, standard error and probability they had. Not with a free-run budget:
    its placements rerun the rule, not the budget's choice (reports.text.budget_dropped)."""
    names, eqs = ident.library_.names, list(ident.selections_)
    sups = {e: s.support for e, s in enumerate(ident.selections_.values())}
    bias_of = None
    if ident.bias_replicates != 0:
        def gram_of(noisy, columns):
            noisy = noisy if isinstance(noisy, list) else [noisy]
            parts = [state_gram(ident.library_, s, e, columns) for s, (e, _) in zip(noisy, blocks)]
            return parts[0] if len(parts) == 1 else BlockGram.concatenate(parts)

        def bias_of(sups, coefs):
            return unc.estimate_chain_bias(ident.bias_method, sources, gram, ident.library_, sups, coefs, gram_of,
                                           ident.bias_replicates)

    def fit_and_select(trains, heldouts):
        return placement_supports(ident, ident.path_, trains, heldouts, n_eff)

    coefs, var, info = unc.assess(gram, held, sups, bias_of, fit_and_select, ident.placements)
    coefs, var, info = _leave_out_uncertain(ident, gram, held, sups, (coefs, var, info), bias_of)
    named = {eqs[e]: {names[j]: j for j in np.flatnonzero(sups[e])} for e in sups}
    info = unc.name_info(info, eqs, names, sups)
    if bias_of is not None and info["chain_bias"] is None:
        why = [w for w in (s.bias_unavailable(ident.bias_method) for s in sources) if w]
        if why:
            info["chain_bias_skipped"] = why[0]
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


def _leave_out_uncertain(ident, gram: BlockGram, held, sups: dict, assessed: tuple, bias_of) -> tuple:
    """Backward elimination on trust's kept terms: while a kept term is within unc.SIGNIFICANT_Z standard
    errors of zero, the least significant one per equation (unc.least_significant) leaves `sups` and the
    selections (support and training fit), listed in ident.uncertain_terms_ with the coefficient and
    standard error of the last refit that held it and its inclusion probability (None when none were
    computed); the rest are refit and assessed again, so two terms significant only together stay. The
    probabilities stay those of the decision made. Returns assess's (coefs, var, info) for the terms left."""
    coefs, var, info = assessed
    names, eqs = ident.library_.names, list(ident.selections_)
    ident.uncertain_terms_ = {eq: {} for eq in eqs}
    if ident.budget_ is not None:
        return coefs, var, info
    p_in, train = info["inclusion"], None
    while drop := unc.least_significant(sups, coefs, var):
        train = gram.equations(~held) if train is None else train  # summed only when a term leaves
        for e, j in drop.items():
            ident.uncertain_terms_[eqs[e]][names[j]] = {
                "coefficient": float(coefs[e][j]), "standard_error": float(np.sqrt(var[e][j])),
                "inclusion_probability": None if p_in is None else float(p_in[e, j])}
            sel = ident.selections_[eqs[e]]
            sel.support = sups[e] = sups[e] & (np.arange(sups[e].size) != j)
            sel.coef = least_squares(train.G, train.B[:, e], sel.support)
        coefs, var, again = unc.assess(gram, held, sups, bias_of)
        info = {**again, "inclusion": p_in, "placements": info["placements"]}
    return coefs, var, info
