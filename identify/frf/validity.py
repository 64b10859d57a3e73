"""The displacement range over which a model's damping stays positive.

An identified model is a fit over the amplitudes its recording reached; a term such as the Table 1
rig's +1.162e4 q1*q2^2 makes the damping -df/dq1 at rest (q1 = 0) negative beyond |q2| = 17.9 mm, and
a periodic response reaching there is the model's extrapolation, not the rig's physics (the rig hits
its end stops; a slow sweep in the model runs away). The frequency response stops a branch there and
says so, instead of following it to a fold the rig never shows.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from ..simulation.simulate import equation_rows

#: Displacements scanned for the damping's sign change, m (geometric grid up to 1 m: beyond any rail).
SCAN_M = np.geomspace(1e-6, 1.0, 400)


def damping(model, q2_m: np.ndarray) -> np.ndarray:
    """-df/dq1 (1/s) at q1 = 0, zdd = 0 and the displacements q2_m: the model's local viscous damping."""
    q2 = np.asarray(q2_m, float)
    h = 1e-6
    q1 = np.concatenate([np.full(q2.size, h), np.full(q2.size, -h)])
    f = equation_rows(model, [q1, np.concatenate([q2, q2])], np.zeros(2 * q2.size), 0)
    return -(f[: q2.size] - f[q2.size:]) / (2 * h)


def damping_limits(model) -> tuple[float, float] | None:
    """(lower, upper) displacement (m, lower < 0 < upper; +-inf where it never turns) beyond which the
    damping at rest is negative; None when it is not positive at rest to begin with (a friction-only
    model: no viscous damping to lose)."""
    if not damping(model, np.array([0.0]))[0] > 0:
        return None
    out = []
    for side in (-1.0, 1.0):
        d = damping(model, side * SCAN_M)
        bad = np.flatnonzero(d <= 0)
        if bad.size == 0:
            out.append(side * np.inf)
            continue
        j = int(bad[0])
        a = side * (SCAN_M[j - 1] if j > 0 else 0.0)
        b = side * SCAN_M[j]
        root = brentq(lambda q: damping(model, np.array([q]))[0], a, b, xtol=1e-9)
        out.append(float(root))
    return out[0], out[1]
