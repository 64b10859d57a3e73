"""Pseudo-arclength continuation of the forced harmonic balance over a frequency band.

The unknowns y = (X / x_scale, w / w_scale) are continued along the solution curve G(y) = 0 by a
tangent predictor and a Newton corrector on the extended system (G(y) = 0, t . (y - y_pred) = 0)
(Keller's pseudo-arclength), so the curve is followed through its turning points in w: the folds,
where the tangent's w component changes sign. A fold's frequency is where the cubic Hermite
interpolant of w(s) between the two points around it is stationary.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .balance import Basis, coefficient_amplitude, forced_residual

#: Newton tolerance on the scaled residual, and the iterations a corrector may take.
NEWTON_TOL = 1e-10
NEWTON_ITERATIONS = 12
#: Arclength steps (scaled units): first, largest, smallest.
STEP_FIRST = 0.01
STEP_MAX = 0.2
STEP_MIN = 1e-6
#: Largest turn of the tangent in one step (rad): the curvature control that keeps steps short at folds,
#: where the fold's Hermite interpolation needs them (a step that turns more is halved).
MAX_TURN = 0.1
#: At most this many points per branch (a safety net: a band takes 100-400).
MAX_POINTS = 5000


@dataclass
class BranchPoint:
    """One converged periodic response: coefficients X (m), w (rad/s), unit tangent (scaled)."""

    X: np.ndarray
    w: float
    tangent: np.ndarray
    amplitude_m: float
    samples: tuple = ()   # (q1, q2, f_q1) on the basis' samples


@dataclass
class Branch:
    points: list[BranchPoint] = field(default_factory=list)
    stop: str = "band"           # "band" | "validity" | "runaway" | "stalled" | "points"
    stop_detail: str = ""


class Continuation:
    """Continue the response of `model` at table amplitude `table_m` (m) in basis `basis`."""

    def __init__(self, model, basis: Basis, table_m: float, x_scale: float, w_scale: float):
        self.model, self.basis, self.table_m = model, basis, table_m
        self.xs, self.ws = x_scale, w_scale
        self.n = 2 * basis.harmonics + 1
        self.g_scale = 1.0 / (w_scale * w_scale * x_scale)

    def _eval(self, y):
        X, w = y[:-1] * self.xs, y[-1] * self.ws
        R, J, Jw, samples = forced_residual(self.model, self.basis, X, w, self.table_m)
        G = R * self.g_scale
        JG = np.column_stack([J * (self.xs * self.g_scale), Jw * (self.ws * self.g_scale)])
        return G, JG, samples

    def solve_fixed(self, X0: np.ndarray, w: float):
        """Newton at fixed w from X0: (X, samples) or None when it does not converge."""
        y = np.append(X0 / self.xs, w / self.ws)
        for _ in range(3 * NEWTON_ITERATIONS):
            G, JG, samples = self._eval(y)
            if not np.all(np.isfinite(G)):
                return None
            if np.linalg.norm(G) < NEWTON_TOL:
                return y[:-1] * self.xs, samples
            try:
                y[:-1] -= np.linalg.solve(JG[:, :-1], G)
            except np.linalg.LinAlgError:
                return None
        return None

    def tangent(self, JG, previous=None):
        """Unit tangent of the curve, oriented like `previous` (or towards increasing w)."""
        A = np.vstack([JG, previous if previous is not None else np.eye(self.n + 1)[-1]])
        b = np.zeros(self.n + 1)
        b[-1] = 1.0
        try:
            t = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            _, _, vt = np.linalg.svd(JG)
            t = vt[-1]
        t /= np.linalg.norm(t)
        ref = previous if previous is not None else np.eye(self.n + 1)[-1]
        return t if t @ ref >= 0 else -t

    def correct(self, y_pred, t):
        """Newton on (G = 0, t.(y - y_pred) = 0): (y, JG, samples, iterations) or None."""
        y = y_pred.copy()
        for it in range(1, NEWTON_ITERATIONS + 1):
            G, JG, samples = self._eval(y)
            if not np.all(np.isfinite(G)) or not np.all(np.isfinite(JG)):
                return None
            if np.linalg.norm(G) < NEWTON_TOL and it > 1:
                return y, JG, samples, it
            A = np.vstack([JG, t])
            rhs = np.append(G, t @ (y - y_pred))
            try:
                y = y - np.linalg.solve(A, rhs)
            except np.linalg.LinAlgError:
                return None
        G, JG, samples = self._eval(y)
        return (y, JG, samples, NEWTON_ITERATIONS) if np.linalg.norm(G) < NEWTON_TOL else None

    def run(self, X0: np.ndarray, w_start: float, w_stop: float, limit=None, direction: int = 1) -> Branch:
        """Follow the curve from the solution X0 at w_start until w passes w_stop (or leaves the band at
        the other end); `limit(point)` returns a reason string to stop (the model's range of validity)."""
        y = np.append(X0 / self.xs, w_start / self.ws)
        G, JG, samples = self._eval(y)
        t = self.tangent(JG, np.append(np.zeros(self.n), float(direction)))
        branch = Branch()
        branch.points.append(self._point(y, t, samples))
        step, w_lo, w_hi = STEP_FIRST, min(w_start, w_stop), max(w_start, w_stop)
        while len(branch.points) < MAX_POINTS:
            out = self.correct(y + step * t, t)
            if out is None:
                step /= 3
                if step < STEP_MIN:
                    branch.stop, branch.stop_detail = "stalled", "the corrector did not converge at the smallest step"
                    return branch
                continue
            y_new, JG, samples, iterations = out
            t_new = self.tangent(JG, t)
            if np.arccos(np.clip(t_new @ t, -1, 1)) > MAX_TURN and step > 1e3 * STEP_MIN:
                step /= 2
                continue
            point = self._point(y_new, t_new, samples)
            reason = limit(point) if limit is not None else None
            if reason:
                branch.stop, branch.stop_detail = reason
                branch.points.append(point)
                return branch
            branch.points.append(point)
            y, t = y_new, t_new
            if not w_lo * (1 - 1e-12) <= point.w <= w_hi * (1 + 1e-12):
                return branch
            step = min(STEP_MAX, step * (1.6 if iterations <= 3 else 1.0 if iterations <= 5 else 0.5))
        branch.stop = "points"
        return branch

    def _point(self, y, t, samples) -> BranchPoint:
        X = y[:-1] * self.xs
        return BranchPoint(X, float(y[-1] * self.ws), t, coefficient_amplitude(X), samples)


def fold_between(a: BranchPoint, b: BranchPoint, x_scale: float, w_scale: float) -> tuple[float, float]:
    """(w, amplitude_m) of the fold between two points whose tangents' w components differ in sign:
    the stationary point of the cubic Hermite interpolant of w(s) (s: scaled arclength)."""
    ya = np.append(a.X / x_scale, a.w / w_scale)
    yb = np.append(b.X / x_scale, b.w / w_scale)
    L = float(np.linalg.norm(yb - ya))
    w0, w1, d0, d1 = a.w / w_scale, b.w / w_scale, a.tangent[-1] * L, b.tangent[-1] * L
    # Hermite w(u) on u in [0, 1]; w'(u) = quadratic: p u^2 + q u + r
    p = 6 * w0 + 3 * d0 - 6 * w1 + 3 * d1
    q = -6 * w0 - 4 * d0 + 6 * w1 - 2 * d1
    r = d0
    roots = np.roots([p, q, r]) if abs(p) > 1e-14 else np.array([-r / q])
    roots = [float(u.real) for u in np.atleast_1d(roots) if abs(u.imag) < 1e-12 and -1e-9 <= u.real <= 1 + 1e-9]
    u = roots[0] if roots else d0 / (d0 - d1)
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    w = (h00 * w0 + h10 * d0 + h01 * w1 + h11 * d1) * w_scale
    amp = a.amplitude_m + u * (b.amplitude_m - a.amplitude_m)
    return float(w), float(amp)
