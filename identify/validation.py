"""Free-run validation: simulate the model from the measured input alone and compare with measurement."""
from __future__ import annotations

import numpy as np

from .chain import StateSignals
from .model import SparseModel
from .simulate import simulate


def fit_metrics(measured: np.ndarray, simulated: np.ndarray) -> dict:
    """NRMSE (RMS error / std of the measurement) and fit % = 100 (1 - ||e|| / ||y - mean y||)."""
    if measured.size == 0 or not np.all(np.isfinite(simulated)):
        return {"nrmse": None, "fit_percent": None, "rmse": None}
    err = measured - simulated
    rmse = float(np.sqrt(np.mean(err**2)))
    spread = float(np.std(measured))
    nrmse = rmse / spread if spread > 0 else float("inf")
    return {"nrmse": nrmse, "fit_percent": 100.0 * (1.0 - nrmse), "rmse": rmse}


def free_run(model: SparseModel, sig: StateSignals, substeps: int | None = None):
    """Simulate over the valid rows from the measured state at their start.

    Returns (simulated states (n, 2), simulated q1_dot (n,), substeps, diverged), each simulated signal
    passed through the measurement chain's band (StateSignals.band_limit) unless the run diverged."""
    v = sig.valid
    states = sig.states[v]
    u = sig.input[v][:, None]
    scale = 1.5 * np.max(np.abs(states), axis=0)
    res = simulate(model, 1.0 / sig.fs_hz, states[0], u, substeps=substeps, state_scale=scale,
                   bound=100.0 * float(np.max(scale)))
    qdot = np.full(u.shape[0], np.nan)
    ok = slice(0, res.n_valid)
    qdot[ok] = model.rhs(res.states[ok], u[ok])[:, 0]
    sim = res.states
    if not res.diverged:
        sim = np.column_stack([sig.band_limit(sim[:, 0]), sig.band_limit(sim[:, 1])])
        qdot = sig.band_limit(qdot)
    return sim, qdot, res.substeps, res.diverged


def validate(model: SparseModel, sig: StateSignals, heldout_rows: np.ndarray, substeps: int | None = None):
    """Free-run metrics on the held-out rows (mask over the valid rows) and on all valid rows.

    Returns (metrics dict, simulated states (n, 2), simulated q1_dot (n,)), as free_run()."""
    sim_states, sim_qdot, used, diverged = free_run(model, sig, substeps)
    v = sig.valid
    measured = {"q1_dot": sig.q1_dot[v], "q1": sig.q1[v], "q2": sig.q2[v]}
    simulated = {"q1_dot": sim_qdot, "q1": sim_states[:, 0], "q2": sim_states[:, 1]}
    out = {"diverged": bool(diverged), "substeps": int(used), "heldout": {}, "all": {},
           "heldout_samples": int(np.count_nonzero(heldout_rows))}
    for name in measured:
        out["heldout"][name] = fit_metrics(measured[name][heldout_rows], simulated[name][heldout_rows])
        out["all"][name] = fit_metrics(measured[name], simulated[name])
    return out, sim_states, sim_qdot
