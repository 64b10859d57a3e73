"""Stability of a periodic response by its Floquet multipliers, from the monodromy matrix.

Why Floquet multipliers from a monodromy integration rather than Hill's method: the rig model has one
degree of freedom, so the monodromy matrix is 2 x 2 and one period of the project's compiled RK4
(identify.simulation.simulate) per column costs microseconds; it does not depend on the harmonic truncation (Hill's
method's eigenvalues include spurious ones from the truncated harmonics, which must be sorted out, and
its accuracy follows H), it sees the jumps of non-smooth terms (sign, |q1|, end stops) that the AFT
Jacobian's difference quotients miss, and it detects period doubling (a multiplier through -1), which
the balance's own Jacobian cannot. The columns are central differences of the flow over one period.
"""
from __future__ import annotations

import numpy as np

from ..simulation.simulate import choose_substeps, simulate

#: Output samples per period of the monodromy integration (RK4 steps: this x the substeps).
PERIOD_SAMPLES = 64
#: Relative size of the initial-state offsets (of the orbit's range in each state).
OFFSET = 1e-5


def substeps_for(model, w_max: float, scale: np.ndarray) -> int:
    """RK4 steps per output sample for periods down to 2 pi / w_max with states within `scale`
    (identify.simulation.simulate's accuracy target), at least 2: 128 steps a period."""
    return max(2, choose_substeps(model, 2 * np.pi / w_max / PERIOD_SAMPLES, scale))


def multipliers(model, w: float, table_m: float, x0: np.ndarray, scale: np.ndarray, substeps: int) -> np.ndarray:
    """Floquet multipliers (2, complex) of the periodic response through state x0 = (q1, q2) at t = 0
    of the table motion z = table_m sin(w t); `scale` = the orbit's range per state; `substeps` from
    substeps_for."""
    period = 2 * np.pi / w
    dt = period / PERIOD_SAMPLES
    n_fine = PERIOD_SAMPLES * 2 * substeps + 1
    t = np.linspace(0.0, period, n_fine)
    u = (-table_m * w * w * np.sin(w * t))[:, None]
    M = np.empty((2, 2))
    for i in range(2):
        h = OFFSET * max(float(scale[i]), 1e-12)
        ends = []
        for sgn in (1, -1):
            start = np.array(x0, float)
            start[i] += sgn * h
            res = simulate(model, dt, start, inputs_fine=u, substeps=substeps, n_samples=PERIOD_SAMPLES + 1,
                           bound=1e3 * float(np.max(scale)) + 1.0)
            ends.append(res.states[-1])
        M[:, i] = (ends[0] - ends[1]) / (2 * h)
    return np.linalg.eigvals(M)


def is_stable(mult: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(mult)) and np.max(np.abs(mult)) < 1.0)
