"""Free-run simulation of a SparseModel driven by a sampled (or analytic) input.

Fixed-step classical RK4 in a compiled kernel, `substeps` steps per sample interval. The input at
the RK stages (every half step) comes from interpolating the samples: band-limited by default
(polyphase windowed-sinc, right for signals sampled above Nyquist such as accelerometer channels),
or linear / cubic. Inputs known between samples can be given on the fine grid: the rig simulator's
analytic table motion, and the chain's band-limited input, exact from its spectrum
(identify.chain.states.StateSignals.input_fine: what validation and the free-run refit use).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import resample_poly

from .. import _simkernel
from ..model import SparseModel

#: RK4 step size target: h * omega_max. The global error grows as (h omega)^4 below it: the Table 1 rig
#: under an 8 s sweep, of its peak, 1.2e-8 / 2.0e-7 / 3.4e-6 at h omega 0.036 / 0.072 / 0.14
#: (tests/identify/test_simulate.py); on the million-sample sweep of benchmarks/identify_speed.py,
#: whose error peaks at resonance, 6.9e-7 / 1.4e-5 at 0.036 / 0.072. Either way below any
#: accelerometer's noise (0.5 % = 5e-3), which is what a free run is compared with.
STEP_OMEGA = 0.1
#: ... and h * |lambda| for a real eigenvalue (a mode that decays or grows without oscillating: a
#: hysteresis state's relaxation, beta |q1| + gamma |q1|, thousands of 1/s). Its error does not pile up
#: period after period as an oscillation's does: RK4's per-step error on it is (h lambda)^5 / 120, 2.6e-4 of
#: the mode at 0.5, well inside RK4's stability (2.78), and the slow states it follows move by far less. A
#: Bouc-Wen candidate of a 5 Hz rig at 2048 Hz (lambda ~2600 1/s): 13 steps per sample under STEP_OMEGA, 3
#: under this, q1 and q2 then within 4e-5 of their largest value of a 52-step reference, z 8e-4 (1.8e-6 at 13;
#: the |q1| kink, not the eigenvalue, sets that error, which falls as h^2).
STEP_DECAY = 0.5
MAX_SUBSTEPS = 256
#: Longest RK4 step, in samples, of a smooth model slow against the sample rate (choose_step).
MAX_STRIDE = 4
#: |q1| that stands for "at rest, on one side of 0" where sampled_q1_dot reads a jump's two sides: sign(q1)
#: takes the side, and every power of it up to the 5th (1e-300) is still a normal number, so a term with q1
#: in it adds nothing a double can hold (1e-60 of it) and costs nothing. np.finfo(float).tiny did the same
#: but made every product with it subnormal: on Intel cores each such operation takes a microcode assist,
#: and each side evaluation cost 4.3x the plain one (240 against 56 us per 2000 rows of a Coulomb model;
#: 28 % of a Coulomb case's explanation CPU went to the read-out, seed 2238485666 case 137).
AT_REST_Q1 = 1e-60


@dataclass
class SimulationResult:
    """Simulated states (n, n_states); rows after a divergence are NaN."""

    states: np.ndarray
    n_valid: int
    substeps: int
    #: samples per RK4 step (simulate's stride; 1: `substeps` steps per sample)
    stride: int = 1

    @property
    def diverged(self) -> bool:
        return self.n_valid < self.states.shape[0]


def fine_grid_input(inputs: np.ndarray, substeps: int, interpolation: str = "bandlimited",
                    mean: np.ndarray | None = None) -> np.ndarray:
    """Input samples (n, n_inputs) -> values every h/2, shape ((n-1)*2*substeps+1, n_inputs). `mean`: what
    the band-limited interpolation removes before and adds after (default the inputs' own mean; a
    stretch of a longer record passes the record's, to get the record's values)."""
    inputs = np.asarray(inputs, dtype=float)
    if inputs.ndim == 1:
        inputs = inputs[:, None]
    n = inputs.shape[0]
    up = 2 * substeps
    n_fine = (n - 1) * up + 1
    if n < 2 or up == 1:
        return np.ascontiguousarray(inputs[:n_fine])
    if interpolation == "linear":
        x = np.arange(n_fine) / up
        return np.column_stack([np.interp(x, np.arange(n), c) for c in inputs.T])
    if interpolation == "cubic":
        return CubicSpline(np.arange(n), inputs, axis=0)(np.arange(n_fine) / up)
    if interpolation == "bandlimited":
        # resample_poly keeps the original samples' positions (output[k*up] ~= input[k]) and handles
        # non-periodic records without wrap-around; mean removed so its zero-padded edges do not ring.
        mean = inputs.mean(axis=0) if mean is None else np.broadcast_to(np.asarray(mean, dtype=float), inputs.shape[1:])
        if inputs.shape[1] == 1:  # one channel as a 1-D signal: the same numbers, without the strided axis
            return (resample_poly(inputs[:, 0] - mean[0], up, 1)[:n_fine] + mean[0])[:, None]
        fine = resample_poly(inputs - mean, up, 1, axis=0)[:n_fine] + mean
        return np.ascontiguousarray(fine)
    raise ValueError(f"unknown interpolation {interpolation!r} (bandlimited, cubic, linear)")


def state_jacobians(model: SparseModel, state_scale, n_grid: int = 6) -> np.ndarray:
    """The model's Jacobians d rhs / d state (n_points, n_states, n_states) on a grid of states within
    +-state_scale, by central differences.

    The grid has an even number of points, so no point sits on a state's zero, where sign(q) and |q|
    jump or kink: a difference quotient across the jump is 1/eps, not a frequency."""
    scale = np.asarray(state_scale, dtype=float)
    axes = [np.linspace(-s, s, n_grid) for s in scale]
    pts = np.stack(np.meshgrid(*axes), axis=-1).reshape(-1, len(scale))
    u = np.zeros((pts.shape[0], len(model.inputs)))
    eps = 1e-6 * np.maximum(scale, 1e-12)
    jac = np.empty((pts.shape[0], len(scale), len(scale)))
    for i in range(len(scale)):
        dp = np.zeros(len(scale))
        dp[i] = eps[i]
        jac[:, :, i] = (model.rhs(pts + dp, u) - model.rhs(pts - dp, u)) / (2 * eps[i])
    jac = np.where(np.isfinite(jac), jac, 0.0)
    return jac


def _eigenvalues(model: SparseModel, state_scale, n_grid: int) -> np.ndarray:
    """Every eigenvalue of state_jacobians' Jacobians (empty for a model without states)."""
    jac = state_jacobians(model, state_scale, n_grid)
    return np.linalg.eigvals(jac).ravel() if jac.size else np.zeros(0)


def max_frequency(model: SparseModel, state_scale, n_grid: int = 6) -> float:
    """Largest |eigenvalue| (rad/s) of the model's Jacobian over a grid of states within +-state_scale
    (state_jacobians' grid)."""
    ev = _eigenvalues(model, state_scale, n_grid)
    return float(np.max(np.abs(ev))) if ev.size else 0.0


def step_rate(model: SparseModel, state_scale, n_grid: int = 6) -> float:
    """The rate (1/s) RK4's step is held to, h step_rate <= STEP_OMEGA: max_frequency's, a real eigenvalue's
    |lambda| scaled by STEP_OMEGA / STEP_DECAY (it may take STEP_DECAY)."""
    ev = _eigenvalues(model, state_scale, n_grid)
    if not ev.size:
        return 0.0
    real = np.abs(ev.imag) <= 1e-9 * np.abs(ev)
    return float(np.max(np.abs(ev) * np.where(real, STEP_OMEGA / STEP_DECAY, 1.0)))


def choose_substeps(model: SparseModel, dt: float, state_scale) -> int:
    """RK4 steps per sample so that h step_rate <= STEP_OMEGA."""
    return choose_step(model, dt, state_scale)[0]


def choose_step(model: SparseModel, dt: float, state_scale) -> tuple[int, int]:
    """(substeps, stride): RK4 steps of dt / substeps with h step_rate <= STEP_OMEGA, or, for a model
    without end stops slow enough for steps of several samples, steps of `stride` <= MAX_STRIDE samples
    within the same bound (simulate's stride: the Table 1 rig at 2048 Hz, omega_max dt = 0.036, takes
    steps of 2 samples)."""
    omega = step_rate(model, state_scale)
    substeps = int(np.clip(np.ceil(omega * dt / STEP_OMEGA), 1, MAX_SUBSTEPS))
    if substeps > 1 or has_end_stops(model):
        return substeps, 1
    return 1, int(np.clip(np.floor(STEP_OMEGA / max(omega * dt, 1e-300)), 1, MAX_STRIDE))


def has_end_stops(model: SparseModel) -> bool:
    """Whether any term uses an end-stop feature (stop(q), contact(q)), whose jumps need the kernel's
    step cutting, sample by sample."""
    _, feat, _ = model.space.encode(model.terms)
    return bool(np.any(np.asarray(feat) >= 3 * len(model.states) + len(model.inputs)))


def sign_jump_terms(model: SparseModel) -> np.ndarray:
    """Per term, whether it makes the q1_dot equation's force jump where q1 crosses 0: a kept term with an
    odd power of sign(q1) (Coulomb friction), FeatureSpace's feature 2."""
    ptr, feat, powr = (np.asarray(a) for a in model.space.encode(model.terms))
    return np.array([model.coef_[0, j] != 0 and bool(np.any((feat[ptr[j]:ptr[j + 1]] == 2)
                                                            & (powr[ptr[j]:ptr[j + 1]] % 2 == 1)))
                     for j in range(len(model.terms))], dtype=bool)


def jumps_at_rest(model: SparseModel) -> bool:
    """Whether the q1_dot equation's force jumps where q1 crosses 0 (sign_jump_terms)."""
    return bool(sign_jump_terms(model).any())


def sampled_q1_dot(model: SparseModel, states: np.ndarray, inputs: np.ndarray, dt_s: float,
                   jump_terms: np.ndarray | None = None) -> np.ndarray:
    """q1_dot (m/s^2) at the samples of a run the kernel integrated (states (n, n_states), inputs (n,
    n_inputs), dt_s apart), as an accelerometer reads it: equation_rows, except where the mass sticks.

    Where the force jumps at q1 = 0 (sign_jump_terms: Coulomb friction's sign(q1)) and the other forces
    cannot overcome it, both one-sided accelerations point at q1 = 0 (q1_dot(0+) < 0 < q1_dot(0-),
    Filippov's sliding condition): the mass sticks and the true q1_dot is 0. RK4 steps through the jump, so
    there its q1 chatters about 0 within a step's worth of the jump (the states stay right to that) while
    q1_dot read at the samples flips between q1_dot(0+) and q1_dot(0-) from sample to sample: white
    content of the friction's size that no rig has. Samples with |q1| within (q1_dot(0-) - q1_dot(0+)) dt_s
    of 0 that meet the sliding condition read 0. The simulated rig's mass accelerometer reads its truth
    this way (sim.physics.mass_acceleration) and the shooting error a model's runs (identify.simulation.shooting).
    The two sides are read only on the rows within reach of the jump, -2 x the jumping terms at 0+ (the
    rest of the force is the same on both sides): a shooting run reads every segment of a Coulomb model.
    jump_terms: sign_jump_terms(model) when the caller knows it (once per run, not per segment)."""
    states = np.asarray(states, dtype=float)
    qdd = equation_rows(model, states, inputs, 0)
    jump_terms = sign_jump_terms(model) if jump_terms is None else jump_terms
    if not jump_terms.any():
        return qdd
    rest = list(states.T)  # the states as columns, q1 replaced by AT_REST_Q1: no copy of the others
    rest[0] = np.full(states.shape[0], AT_REST_Q1)
    # rows that can stick: the sliding condition needs |the smooth force| < |the jump's half|, so there the
    # two-sided difference below equals this one to rounding of the jump itself (1e-9: generous)
    reach = -2.0 * equation_rows(model, rest, inputs, 0, terms=jump_terms) * dt_s
    near = np.flatnonzero(np.abs(states[:, 0]) <= reach * (1.0 + 1e-9))
    if near.size:
        u = np.asarray(inputs, dtype=float)[near]
        side = {}
        for sign in (1.0, -1.0):
            side[sign] = equation_rows(model, [np.full(near.size, sign * AT_REST_Q1)] + [c[near] for c in rest[1:]], u, 0)
        stuck = (side[1.0] < 0) & (side[-1.0] > 0) & (np.abs(states[near, 0]) <= (side[-1.0] - side[1.0]) * dt_s)
        qdd[near[stuck]] = 0.0
    return qdd


def equation_rows(model: SparseModel, states, inputs, equation: int = 0, terms: np.ndarray | None = None) -> np.ndarray:
    """model.rhs(states, inputs)[:, equation] (the equation's derivative, e.g. q1_dot in m/s^2) at n
    independent rows, in the compiled kernel: one pass, none of the library's intermediate columns.

    states : sequence of n_states 1-D arrays (n,) (strided views are fine), or an (n, n_states) array;
    inputs : (n, n_inputs) array, a sequence of columns, or one column (n,). End-stop features take each
    row's own side. terms: a mask of the model's terms to sum (None: all)."""
    def columns(a):
        if isinstance(a, np.ndarray):
            return list(a.T) if a.ndim == 2 else [a]
        return list(a)

    cols = [c if isinstance(c, np.ndarray) and c.dtype == np.float64 else np.asarray(c, dtype=float)
            for c in columns(states) + columns(inputs)]  # (called per shooting span: no needless copies)
    n = cols[0].shape[0] if cols else 0
    if len(cols) != len(model.states) + len(model.inputs):
        raise ValueError(f"{len(cols)} columns; model has states {model.states} and inputs {model.inputs}")
    coef = np.zeros_like(model.coef_)
    coef[equation] = model.coef_[equation]  # the other equations' terms are not evaluated at all
    if terms is not None:
        coef[equation, ~np.asarray(terms, dtype=bool)] = 0.0
    out = np.empty(n)
    if n == 0 or not coef.any():
        out[:] = 0.0
        return out
    ptr, feat, powr, travel = model.kernel_terms()
    _simkernel.rhs_rows(ptr, feat, powr, coef.tobytes(), tuple(cols), int(equation), out, travel)
    return out


def simulate_segments(model: SparseModel, dt: float, x0s: np.ndarray, inputs_fine: np.ndarray, substeps: int,
                      starts: np.ndarray, stops: np.ndarray, out: np.ndarray, *, bound: float, stride: int = 1) -> np.ndarray:
    """simulate for segments of one record in one compiled call (multiple shooting: identify.simulation.
    shooting): segment j from state x0s[j] over the record's samples starts[j] .. stops[j] - 1, its input
    read from inputs_fine (the whole record's h/2 grid, fine_grid_input's rows) from sample starts[j] on,
    its states written into out[starts[j]:stops[j]] (out: (n_rows, n_states), C-contiguous float64; the segments
    in order and not overlapping, so callers in several threads write disjoint rows). Returns
    the samples written per segment (fewer than its length: it diverged, and the rest of its rows are
    not written). The same numbers as simulate segment by segment."""
    x0s = np.ascontiguousarray(x0s, dtype=float)
    u = np.ascontiguousarray(inputs_fine, dtype=float)
    u = u[:, None] if u.ndim == 1 else u
    if x0s.ndim != 2 or x0s.shape[1] != len(model.states) or u.shape[1] != len(model.inputs):
        raise ValueError(f"x0s {x0s.shape} and inputs {u.shape}; model has states {model.states} and inputs {model.inputs}")
    if not (out.flags.c_contiguous and out.dtype == np.float64 and out.ndim == 2 and out.shape[1] == x0s.shape[1]):
        raise ValueError("out must be a C-contiguous (n_rows, n_states) float64 array")
    starts = np.asarray(starts, dtype=np.int64)
    stops = np.asarray(stops, dtype=np.int64)
    if np.any(starts[1:] < stops[:-1]):  # threads write their segments' rows of one `out` side by side
        raise ValueError("segments must be in order and must not overlap")
    written = np.zeros(starts.size, dtype=np.int64)
    run = np.flatnonzero(stops > starts)  # an empty segment has nothing to write (as simulate: 0 samples)
    if run.size == 0:
        return written
    ptr, feat, powr, travel = model.kernel_terms()
    done = np.zeros(run.size, dtype=np.int64)
    _simkernel.simulate_segments(ptr, feat, powr, np.ascontiguousarray(model.coef_).tobytes(), x0s[run].tobytes(),
                                 u.reshape(-1), u.shape[1], np.ascontiguousarray(starts[run]),
                                 np.ascontiguousarray(stops[run]), int(substeps), int(stride), float(dt),
                                 float(bound), out.reshape(-1), done, travel)
    written[run] = done
    return written


def simulate(model: SparseModel, dt: float, x0, inputs=None, *, inputs_fine=None, substeps: int | None = None,
             interpolation: str = "bandlimited", state_scale=None, n_samples: int | None = None,
             bound: float | None = None, stride: int = 1) -> SimulationResult:
    """Free-run `model` from state `x0` over the input's samples (spacing `dt` seconds).

    Give either `inputs` (n, n_inputs) sampled at dt, or `inputs_fine` already on the h/2 grid (then
    `substeps` and `n_samples` are required). `state_scale` (typical |state| per state) sets the
    substeps automatically; `bound` stops the run when a state leaves [-bound, bound] (divergence).
    `stride` > 1 (substeps 1, a model without end stops; choose_step says when): RK4 steps of `stride`
    samples, their input read from the same half-sample grid, the samples inside a step from RK4's
    continuous extension (third order, like a step's local error).
    """
    x0 = np.ascontiguousarray(np.asarray(x0, dtype=float).ravel())
    if x0.size != len(model.states):
        raise ValueError(f"x0 has {x0.size} values; model has {len(model.states)} states")
    if inputs_fine is None:
        inputs = np.asarray(inputs, dtype=float)
        inputs = inputs[:, None] if inputs.ndim == 1 else inputs
        n_samples = inputs.shape[0]
        if substeps is None:
            scale = state_scale if state_scale is not None else np.maximum(np.abs(x0), 1e-3)
            substeps = choose_substeps(model, dt, scale)
        inputs_fine = fine_grid_input(inputs, substeps, interpolation)
    elif substeps is None or n_samples is None:
        raise ValueError("inputs_fine needs substeps and n_samples")
    u = np.ascontiguousarray(inputs_fine, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    if u.shape[1] != len(model.inputs):
        raise ValueError(f"input has {u.shape[1]} channels; model expects {model.inputs}")
    if bound is None:
        bound = 1e6 if state_scale is None else 1e3 * float(np.max(state_scale))
    ptr, feat, powr, travel = model.kernel_terms()
    out = np.empty((n_samples, x0.size))  # the kernel writes the rows it reaches; the rest are NaN'd below
    n_valid = _simkernel.simulate(
        ptr, feat, powr, np.ascontiguousarray(model.coef_).tobytes(),
        x0.tobytes(), u.reshape(-1), u.shape[1], int(n_samples), int(substeps), int(stride), float(dt), float(bound),
        out.reshape(-1), travel)
    if n_valid < n_samples:
        out[n_valid:] = np.nan
    return SimulationResult(out, int(n_valid), int(substeps), int(stride))
