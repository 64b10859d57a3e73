"""Regression inside the measurement band, and the displacement below it.

Accelerometers see no DC, so the chain's displacement q2 is band-limited: it lacks the slow part m(t)
of the true displacement, the static offset an even force (an asymmetric spring, q2^2) produces and
which follows the response amplitude through a sweep (the design rig with 3e4 N/m^2: down to -2.6 mm
at a 12 mm response). Measured on that rig (tests/identify/test_even_terms.py), each of two things
alone biases the fit:

1. An even term of the states has a DC and slow part the band-limited target lacks: least squares on
   raw columns spends a constant, q1^2, q1^2*q2 ... on cancelling it. Through the same band as the
   target (`band_limited_gram`, the mechanism explain's screen uses), Band(q'') = sum theta Band(phi)
   holds exactly and the constant, whose band-limited column is zero, drops out.
2. A polynomial in q2 + m is a polynomial in q2 with shifted coefficients: (q2 + m)^3 carries
   3 m q2^2, so on q2 alone the q2^2 coefficient comes out as ~k2 + 3 k3 m: 77 % of the truth in
   band, 25 % with raw columns, q2^3 at 51-62 % (2e4 N/m^2, true terms only). The terms are written in
   the true displacement q2 + m, with m from the force itself (`slow_displacement`): below the band
   the rig's acceleration is ~0, so the force must balance there, Low(f(q1, q2 + m, u)) = 0 with
   Low = 1 - Band. With the true model m matches the simulated one to 0.01 mm rms (2.5 %); fitting
   the whole library and m together (`carry_offset`) recovers every coefficient to 0.05 %.

The displacement origin is the rest position (q2 = 0 before the sweep), so the model has no constant
force term: a constant force only moves the rest position, which accelerometers cannot see.
"""
from __future__ import annotations

import numpy as np

from dataclasses import replace

from .states import StateSignals
from ..regression.gram import BlockGram
from ..regression.library import evaluate_terms
from ..model import SparseModel
from ..regression.optimizers.base import least_squares
from ..simulation.simulate import equation_rows

#: Newton steps per update of the slow displacement (the stiffness is taken once: 3 right-hand sides and
#: 2 band operations, then 1 and 1 per step);
#: from zero, the design rig with 2e4 N/m^2 converges 0.36 mm -> 0.017 mm -> 0.001 mm of step.
OFFSET_NEWTON_STEPS = 3
#: Fit/offset passes: stop when the offset moved by less than OFFSET_TOLERANCE x the rms displacement.
#: Plain alternation oscillates with period two on the 3e4 N/m^2 rig (change stuck at 2.6e-2); with
#: Anderson mixing of the last ANDERSON_DEPTH + 1 passes it settles in 6 passes (3.7e-4).
MAX_OFFSET_PASSES = 10
OFFSET_TOLERANCE = 1e-3
ANDERSON_DEPTH = 2


def band_limited_gram(library, sig: StateSignals, targets, edges, cache: dict | None = None) -> BlockGram:
    """Per-block Grams of [Band(library(model states, input)) | targets] over the valid rows.

    Columns are evaluated on the whole record and passed through the chain's band operator with the
    same taper as the target was (StateSignals.band_limit), then cut to the valid rows; a column the
    band removes entirely (the constant, when f_lo > 0) is exactly zero and the optimizers leave it out.
    targets : 1-D arrays over the valid rows. cache : a dict kept between calls on the same record;
    a column whose values did not change since (one without q2 when only the offset moved) is reused."""
    v = sig.valid
    m, p = len(library), len(targets)
    AY = np.empty((v.stop - v.start, m + p), order="F")
    cols = library.evaluate((sig.q1, sig.states[:, 1].copy()), sig.input[:, None])
    todo = []
    for j, name in enumerate(library.names):
        col = cols[:, j]
        if name == sig.input_name:
            AY[:, j] = col[v]  # the input is the chain's band-limited channel already
            continue
        hit = cache.get(name) if cache is not None else None
        if hit is not None and np.array_equal(hit[0], col):
            AY[:, j] = hit[1]
        else:
            todo.append(j)
    for j, y in zip(todo, sig.band_limit_many([cols[:, j] for j in todo])):
        AY[:, j] = y[v]
        if cache is not None:
            cache[library.names[j]] = (cols[:, j].copy(), AY[:, j].copy())
    for j, y in enumerate(targets):
        AY[:, m + j] = y
    return BlockGram(AY, p, edges)


def has_even_force(model: SparseModel, sig: StateSignals, equation: str = "q1_dot") -> bool:
    """True when the model's force has an even part, f(q1, q2, u) + f(-q1, -q2, -u) != 0 on the data
    (q2^2 and |q1| are even, q1*|q1| odd): only an even force rectifies into a displacement below
    the band. An odd force implies next to none (Table 1 rig: 8 um rms, from the sweep's start in the
    band's lower roll-off, against 0.4-0.5 mm for 2-3e4 N/m^2), and carrying that invites the
    full-library fit to pair it with a spurious q2^2 (z = 19 on the Table 1 sweep)."""
    e = list(model.equations).index(equation)
    if all(_odd(term) for term, c in zip(model.terms, model.coef_[e]) if c):
        return False  # f(-x) = -f(x) term by term, and exactly so in floating point: no data needed
    rows = slice(sig.valid.start, sig.valid.stop, 7)
    x, u = sig.state_columns(rows), sig.input[rows][:, None]
    f = equation_rows(model, x, u, e)  # compiled: the record's every 7th row, twice
    even = f + equation_rows(model, [-c for c in x], -u, e)
    return bool(np.max(np.abs(even), initial=0.0) > 1e-9 * np.max(np.abs(f), initial=0.0))


def _odd(term) -> bool:
    """Whether a term changes sign with every state and input, f(-x) = -f(x): each feature has a parity
    (q, sign(q), an input and stop(q) odd; |q| and contact(q) even), a power of an odd one is odd when
    the power is, and a product is odd when an odd number of its factors are."""
    odd_factors = sum(power for feature, power in term.factors
                      if not (feature.startswith("|") or feature.startswith("contact(")))
    return odd_factors % 2 == 1


def slow_displacement(model: SparseModel, sig: StateSignals, start: np.ndarray | None = None,
                      steps: int = OFFSET_NEWTON_STEPS) -> np.ndarray | None:
    """The displacement below the band m(t) (m, over all rows) that the model's force balances there.

    Solves Low(f(q1, q2 + m, u)) = 0 by Newton steps m <- m - Low(f) / Low(df/dq2), starting from
    `start` (default 0): a ratio of slow signals stays slow. None when the band reaches DC (nothing
    lies below it) or the model has no restoring stiffness below the band to balance with (then m is
    not determined: the fit stays in the band-limited displacement)."""
    if sig.band_hz[0] <= 0:
        return None
    q1, q2, u = sig.q1, sig.q2, sig.input[:, None]
    m = np.zeros_like(q2) if start is None else np.array(start, dtype=float)
    h = 1e-3 * float(np.std(q2[sig.valid])) or 1e-9

    def low(x):
        return x - sig.band_limit(x)

    e = list(model.equations).index("q1_dot")

    coef = model.coef_[e]

    def force(q):  # model.rhs on contiguous columns (3x faster than on an (n, 2) array), summed column
        theta = evaluate_terms(model.space, model.terms, (q1, q), u)  # by column: BLAS's matrix-vector
        out = np.zeros(q.shape)                                        # product was 4x slower here
        for j in np.flatnonzero(coef):
            out += coef[j] * theta[:, j]
        return out

    # the stiffness below the band, once per call (the offset moves it little), with the first force
    q = q2 + m
    raw = [(force(q + h) - force(q - h)) / (2 * h), force(q)]
    slope, low_force = (x - bx for x, bx in zip(raw, sig.band_limit_many(raw)))
    stiff = -slope[sig.valid]
    if not np.all(np.isfinite(stiff)) or np.min(stiff) <= 0:
        return None
    slope = np.minimum(slope, -np.min(stiff))  # the edges (not fitted) kept stable
    for step in range(steps):
        if step:
            low_force = low(force(q2 + m))
        m = m - low_force / slope
        if not np.all(np.isfinite(m)):
            return None
    return m


def carry_offset(library, sig: StateSignals, edges, train_blocks, targets=("q1_dot", "q1")):
    """The displacement below the band that the library's force balances there, fitted together.

    Each pass fits every term by least squares in the band (band-limited columns, training blocks; a
    sparse model selected before the offset is known carries the spurious terms the offset caused, and
    alternating with it wanders) and asks that force for its offset (slow_displacement); passes are
    mixed (Anderson) until the offset settles; the first target is the force's. Returns (states with
    the offset, their band-limited Gram with all `targets`, a summary for the result: passes, last
    relative change, converged, offset rms/min/max in mm)."""
    v = sig.valid
    ref = float(np.std(sig.q2[v])) or 1.0
    x = np.zeros_like(sig.q2)
    xs, rs = [], []
    current, cache = sig, {}
    gram = band_limited_gram(library, sig, [getattr(sig, t)[v] for t in targets], edges, cache)
    info = {"carried": True, "passes": 0, "last_change": None, "converged": False}
    for passes in range(1, MAX_OFFSET_PASSES + 1):
        train = gram.equations(train_blocks)
        coef = least_squares(train.G, train.B[:, 0], np.diag(train.G) > 0)
        force = SparseModel({"q1_dot": {n: float(c) for n, c in zip(library.names, coef) if c},
                             "q2_dot": {"q1": 1.0}}, ("q1", "q2"), (sig.input_name,))
        new = slow_displacement(force, current, x)
        info["passes"] = passes
        if new is None:
            info["reason"] = "the force fitted on the whole library has no restoring stiffness below the band"
            break
        res = new - x
        info["last_change"] = change = float(np.std(res[v]) / ref)
        if change < OFFSET_TOLERANCE:
            info["converged"] = True
            break
        if passes == MAX_OFFSET_PASSES:
            break
        xs, rs = (xs + [x])[-ANDERSON_DEPTH - 1:], (rs + [res])[-ANDERSON_DEPTH - 1:]
        x = x + res
        if len(xs) > 1:  # Anderson: the combination of recent passes whose residual is least
            dr = np.column_stack([b - a for a, b in zip(rs[:-1], rs[1:])])
            dx = np.column_stack([b - a for a, b in zip(xs[:-1], xs[1:])])
            gamma = np.linalg.lstsq(dr[v], res[v], rcond=None)[0]
            x = x - (dx + dr) @ gamma
        current = replace(sig, q2_offset=x)
        gram = band_limited_gram(library, current, [getattr(current, t)[v] for t in targets], edges, cache)
    return current, gram, {**info, **offset_summary(current)}


def offset_summary(sig: StateSignals) -> dict:
    """The displacement below the band the states carry, in mm over the valid rows."""
    if sig.q2_offset is None:
        return {"carried": False}
    mv = sig.q2_offset[sig.valid] * 1e3
    return {"carried": True, "rms_mm": float(np.sqrt(np.mean(mv**2))), "min_mm": float(mv.min()),
            "max_mm": float(mv.max())}
