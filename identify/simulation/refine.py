"""Output-error refit: coefficients that minimise the free-run simulation error.

Equation-error least squares (the paper's refit) is fast and unbiased when the states are measured
well, but it weighs every sample's derivative equally and is biased for non-smooth terms such as
sign(q1), whose switching instants the integrated states blur. Minimising the error of the *simulated*
output over the fit samples, starting from the equation-error estimate, optimises what validation
measures. Same support, only the coefficients move (Gauss-Newton / trust region, scipy least_squares;
each residual evaluation is one compiled free run).

The error is taken on the interior rows only (interior_rows): band-limiting a simulation tapers its
ends, which the measured states, tapered outside the valid rows, do not share. Several recordings of one
rig (a joint fit) are each simulated on their own and their errors pooled (PooledFreeRunError).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..chain.states import StateSignals
from ..model import SparseModel
from .simulate import choose_step, simulate


def interior_rows(sig: StateSignals) -> np.ndarray:
    """Mask over the valid rows: all but the `taper_n` rows at each end.

    StateSignals.band_limit tapers the ends of what it filters, as the chain tapered the recording; the
    recording's tapers lie outside the valid rows, a simulation's fall on their first and last taper_n
    rows, where even the true model then misses by up to the whole response (Silverbox: 0.05-0.1 V over
    64 rows at each end; compared there, the two end blocks carried 97 % of the refit's error)."""
    n = sig.valid.stop - sig.valid.start
    rows = np.zeros(n, dtype=bool)
    rows[sig.taper_n:n - sig.taper_n] = True
    return rows


class FreeRunError:
    """The free-run error of models of one recording: simulate from the measured state at the first valid
    row with the measured input, band-limit like the measured states, and compare `signals` on `rows`
    (mask over the valid rows, interior_rows applied), each normalised by its std on those rows.

    residuals(model) has one entry per signal and row, scaled so that cost(model) = sum of squares =
    sum over signals of MSE / variance (dimensionless; 1.0 is a model no better than the mean)."""

    def __init__(self, sig: StateSignals, rows: np.ndarray | None = None, signals=("q2", "q1"),
                 substeps: int | None = None, model: SparseModel | None = None):
        v = sig.valid
        self.sig = sig
        self.signals = tuple(signals)
        self.measured = {"q1": sig.q1[v], "q2": sig.q2[v]}
        self.x0 = sig.states[v][0]
        self.n = self.measured["q1"].size
        self.rows = interior_rows(sig) if rows is None else np.asarray(rows, dtype=bool) & interior_rows(sig)
        self.dt = 1.0 / sig.fs_hz
        self.scale = 1.5 * np.max(np.abs(sig.states[v]), axis=0)
        self.bound = 100.0 * float(np.max(self.scale))
        # RK4 steps as validation takes them (identify.simulation.simulate.choose_step): several per sample, or, for a
        # model slow against the sample rate, one per `stride` samples; a given `substeps` is one step of
        # dt / substeps each
        substeps, stride = choose_step(model, self.dt, self.scale) if substeps is None else (int(substeps), 1)
        self.substeps, self.stride = int(substeps), int(stride)
        # exact between samples (the chain's band-limited input), where the steps read it
        self.u_fine = sig.input_fine(self.substeps, self.stride)
        self.norms = {s: (np.std(self.measured[s][self.rows]) if self.rows.any() else 0.0) or 1.0
                      for s in self.signals}
        self.n_rows = max(int(self.rows.sum()), 1)

    def residuals(self, model: SparseModel) -> np.ndarray:
        res = simulate(model, self.dt, self.x0, inputs_fine=self.u_fine, substeps=self.substeps, n_samples=self.n,
                       bound=self.bound, stride=self.stride)
        if res.diverged:  # a large but finite penalty: a trust region backs off instead of failing
            return np.full(self.n_rows * len(self.signals), 1e3 / np.sqrt(self.n_rows))
        # compared like with like: the simulation through the same band as the measured states
        col = {"q1": 0, "q2": 1}
        limited = self.sig.band_limit_many([res.states[:, col[s]] for s in self.signals])  # one batched transform
        r = np.concatenate([(x[self.rows] - self.measured[s][self.rows]) / self.norms[s]
                            for s, x in zip(self.signals, limited)])
        return np.where(np.isfinite(r), r, 1e3) / np.sqrt(self.n_rows)

    def cost(self, model: SparseModel) -> float:
        r = self.residuals(model)
        return float(r @ r)


class PooledFreeRunError:
    """The free-run error of models over several recordings of one rig: each recording is simulated on
    its own (its own initial state, input and band: a separate experiment, FreeRunError), and the
    residuals are concatenated, each recording's weighted by its share of the compared rows, so that
    cost = sum_r n_r cost_r / sum_r n_r. A recording counts by its rows, as in the summed normal
    equations of a joint fit (identify.joint); within it, as for one record, each signal's error is
    relative to that recording's own spread of the signal. A recording with no rows to compare is left
    out."""

    def __init__(self, errors: list):
        self.errors = [e for e in errors if e.rows.any()]
        if not self.errors:
            raise ValueError("no rows to compare in any recording")
        self.n_rows = sum(e.n_rows for e in self.errors)
        self.weights = [np.sqrt(e.n_rows / self.n_rows) for e in self.errors]

    def residuals(self, model: SparseModel) -> np.ndarray:
        return np.concatenate([w * e.residuals(model) for w, e in zip(self.weights, self.errors)])

    def cost(self, model: SparseModel) -> float:
        r = self.residuals(model)
        return float(r @ r)


def free_run_error(sig, rows=None, signals=("q2", "q1"), substeps: int | None = None,
                   model: SparseModel | None = None):
    """FreeRunError of one recording (sig a StateSignals, rows a mask over its valid rows or None), or
    the PooledFreeRunError of several (sig a list of StateSignals, rows None or a list of masks)."""
    if not isinstance(sig, (list, tuple)):
        return FreeRunError(sig, rows, signals, substeps, model)
    rows = [None] * len(sig) if rows is None else rows
    return PooledFreeRunError([FreeRunError(s, r, signals, substeps, model) for s, r in zip(sig, rows)])


def refine_free_run(model: SparseModel, sig: StateSignals, fit_rows: np.ndarray | None = None,
                    equation: str = "q1_dot", signals=("q2", "q1"), max_nfev: int = 60,
                    ftol: float = 1e-8, substeps: int | None = None) -> tuple[SparseModel, dict]:
    """Refit `equation`'s coefficients of `model` on the free-run error of `signals` over `fit_rows`
    (bool mask over sig.valid; interior rows only, FreeRunError). Each signal's error is normalised by its
    std. Several recordings: sig a list of StateSignals, fit_rows None or a list of masks (free_run_error).
    `ftol`: relative change of the cost at which the search stops; `substeps`: RK4 steps per sample
    (None: as FreeRunError chooses them, for `model`). Returns (model, info)."""
    error = free_run_error(sig, fit_rows, signals, substeps=substeps, model=model)
    terms = list(model.equations[equation])
    theta0 = np.array([model.equations[equation][t] for t in terms])

    def with_coefs(theta) -> SparseModel:
        eqs = {eq: dict(c) for eq, c in model.equations.items()}
        eqs[equation] = dict(zip(terms, theta))
        return SparseModel(eqs, model.states, model.inputs, travel=model.travel or None)

    def residuals(theta):
        return error.residuals(with_coefs(theta))

    r0 = residuals(theta0)
    sol = least_squares(residuals, theta0, x_scale=np.maximum(np.abs(theta0), 1e-12), diff_step=1e-7,
                        max_nfev=max_nfev, method="trf", ftol=ftol)
    better = sol.cost < 0.5 * float(r0 @ r0)
    theta = sol.x if better else theta0
    info = {"cost_before": float(r0 @ r0), "cost_after": float(2 * sol.cost) if better else float(r0 @ r0),
            "evaluations": int(sol.nfev), "status": int(sol.status), "accepted": bool(better)}
    return with_coefs(theta), info
