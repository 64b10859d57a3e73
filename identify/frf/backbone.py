"""The backbone curve: free-vibration frequency against amplitude of the model's conservative part.

The conservative part is the restoring force g(q2) = f(q1 = 0, q2, zdd = 0) of the q1_dot equation
(damping, friction and every other velocity-dependent term dropped; a term even in q1 such as q1^2 q2
is dropped too). Its free vibration x'' = g(x) is balanced with the same basis and AFT as the forced
response, the phase fixed by b1 = 0 and the fundamental's amplitude a1 prescribed; a1 is stepped from
small to the largest forced response, each solution starting from the previous one.
"""
from __future__ import annotations

import numpy as np

from .balance import Basis, coefficient_amplitude, derivative_columns
from .response import natural_frequency_hz

#: Points on the backbone (fundamental amplitudes from BACKBONE_START x the largest to the largest).
BACKBONE_POINTS = 40
BACKBONE_START = 0.02
NEWTON_TOL = 1e-12


def _residual(model, basis: Basis, X: np.ndarray, w: float):
    q2 = basis.E @ X
    zero = np.zeros_like(q2)
    g, _, gq2, _ = derivative_columns(model, zero, q2, zero, need_u=False)
    R = w * w * (basis.D2 @ X) - basis.P @ g
    J = w * w * basis.D2 - basis.P @ (gq2[:, None] * basis.E)
    return R, J, 2 * w * (basis.D2 @ X)


def backbone(model, max_amplitude_mm: float, harmonics: int = 5, points: int = BACKBONE_POINTS) -> dict:
    """{"frequency_hz": [...], "amplitude_mm": [...] (half peak-to-peak), "fundamental_mm": [...]}, up to a
    fundamental of `max_amplitude_mm`; the list ends early where the balance stops converging (a softening
    spring past its escape amplitude)."""
    basis = Basis.for_model(model, harmonics)
    n = 2 * harmonics + 1
    free = np.array([j for j in range(n) if j not in (1, 2)])   # unknowns: all but a1 (set) and b1 (0)
    rows = np.array([j for j in range(n) if j != 2])            # b1's equation vanishes by symmetry
    w = 2 * np.pi * natural_frequency_hz(model)
    X = np.zeros(n)
    out = {"frequency_hz": [], "amplitude_mm": [], "fundamental_mm": [], "harmonics": harmonics}
    for a1 in np.linspace(BACKBONE_START, 1.0, points) * max_amplitude_mm * 1e-3:
        X[1] = a1
        xs = a1
        for _ in range(30):
            R, J, Jw = _residual(model, basis, X, w)
            scale = w * w * xs
            if np.linalg.norm(R[rows]) < NEWTON_TOL * scale:
                break
            A = np.column_stack([J[np.ix_(rows, free)], Jw[rows]])
            try:
                step = np.linalg.solve(A, R[rows])
            except np.linalg.LinAlgError:
                return out
            X[free] -= step[:-1]
            w -= step[-1]
        else:
            return out
        if not (np.all(np.isfinite(X)) and w > 0):
            return out
        out["frequency_hz"].append(float(w / (2 * np.pi)))
        out["amplitude_mm"].append(coefficient_amplitude(X) * 1e3)
        out["fundamental_mm"].append(float(a1 * 1e3))
    return out

