"""Harmonic balance of a model's q1_dot equation under base excitation, with alternating frequency/time
(AFT) evaluation of its terms.

The model's states are q1 = q2' (relative velocity) and q2 (relative displacement); its q1_dot equation
is a sum of library terms f(q1, q2, zdd). With q2_dot = q1 the model is x'' = f(x', x, zdd), x = q2.
A periodic response x(t) = a0 + sum_k (a_k cos k wt + b_k sin k wt) at the table motion
z = Z sin wt (zdd = -Z w^2 sin wt) makes the residual

    R(X, w) = w^2 D^2 X - P f(w E D X, E X, zdd)

vanish, with E the synthesis on N samples per period, P its projection (the DFT) and D the
derivative in coefficient space. f is evaluated in the time domain by the project's compiled term
evaluator (identify.simulation.simulate.equation_rows), at the samples and at central-difference offsets of each
argument, all in one call: the derivative columns give the Jacobian
dR/dX = w^2 D^2 - P [diag(f_q1) w E D + diag(f_q2) E] and dR/dw.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import ModelError
from ..model import SparseModel
from ..simulation.simulate import equation_rows

#: Relative central-difference step of the derivative columns (of each argument's range over the period).
DIFF_STEP = 1e-6
#: Time samples per period: at least this, and at least SAMPLES_PER_HARMONIC per harmonic (a product of
#: degree d of H harmonics has dH; the library's degree 4 at H <= 8 is exact on 64 samples).
MIN_SAMPLES = 64
SAMPLES_PER_HARMONIC = 8
#: Non-smooth terms (sign, |.|, end stops) alias at any N; more samples lower that error.
NONSMOOTH_SAMPLES = 256
_NONSMOOTH = ("sign(", "|", "stop(", "contact(")


def check_model(model: SparseModel) -> None:
    """Refuse what the base-excited harmonic balance cannot take, in the operator's words."""
    if tuple(model.states) != ("q1", "q2") or tuple(model.inputs) != ("zdd",):
        raise ModelError(f"a frequency response needs a base-excited model with states q1, q2 and the input zdd "
                         f"(the shaker rig's layout); this model has states {', '.join(model.states)} and "
                         f"inputs {', '.join(model.inputs)}")
    if model.equations.get("q2_dot") != {"q1": 1.0}:
        raise ModelError(f"a frequency response needs q2_dot = q1 (the relative displacement's derivative is the "
                         f"relative velocity); this model has q2_dot = {model.equations.get('q2_dot')}")
    if not model.equations.get("q1_dot"):
        raise ModelError("the model's q1_dot equation has no terms: nothing to balance")


def is_smooth(model: SparseModel) -> bool:
    """True when every term is a polynomial of q1, q2, zdd (AFT then exact up to aliasing)."""
    return not any(s in name for name in model.equations["q1_dot"] for s in _NONSMOOTH)


@dataclass
class Basis:
    """Real Fourier basis of H harmonics on N samples: synthesis E (N, 2H+1), projection P, derivative D."""

    harmonics: int
    n_samples: int

    def __post_init__(self):
        H, N = self.harmonics, self.n_samples
        tau = 2 * np.pi * np.arange(N) / N
        k = np.arange(1, H + 1)
        E = np.empty((N, 2 * H + 1))
        E[:, 0] = 1.0
        E[:, 1::2] = np.cos(np.outer(tau, k))
        E[:, 2::2] = np.sin(np.outer(tau, k))
        self.E = E
        w = np.full(2 * H + 1, 2.0 / N)
        w[0] = 1.0 / N
        self.P = w[:, None] * E.T
        D = np.zeros((2 * H + 1, 2 * H + 1))
        for j in range(1, H + 1):  # d/dtau (a cos j tau + b sin j tau) = j b cos - j a sin
            D[2 * j - 1, 2 * j] = j
            D[2 * j, 2 * j - 1] = -j
        self.D = D
        self.D2 = D @ D
        self.ED = E @ D
        self.sin1 = np.sin(tau)

    @classmethod
    def for_model(cls, model: SparseModel, harmonics: int) -> "Basis":
        n = max(MIN_SAMPLES, SAMPLES_PER_HARMONIC * harmonics)
        if not is_smooth(model):
            n = max(n, NONSMOOTH_SAMPLES)
        return cls(harmonics, int(2 ** np.ceil(np.log2(n))))

    def resize(self, X: np.ndarray, harmonics: int) -> np.ndarray:
        """Coefficients X of this basis in a basis of `harmonics` harmonics (cut or zero-padded)."""
        out = np.zeros(2 * harmonics + 1)
        m = min(X.size, out.size)
        out[:m] = X[:m]
        return out


def derivative_columns(model: SparseModel, q1, q2, u, need_u: bool = True):
    """f and its partial derivatives f_q1, f_q2 (and f_zdd) at the samples, by central differences, in
    one call of the compiled evaluator."""
    h1 = DIFF_STEP * max(float(np.ptp(q1)), float(np.max(np.abs(q1))), 1e-12)
    h2 = DIFF_STEP * max(float(np.ptp(q2)), float(np.max(np.abs(q2))), 1e-12)
    hu = DIFF_STEP * max(float(np.max(np.abs(u))), 1e-12)
    n = q1.size
    blocks = [(q1, q2, u), (q1 + h1, q2, u), (q1 - h1, q2, u), (q1, q2 + h2, u), (q1, q2 - h2, u)]
    if need_u:
        blocks += [(q1, q2, u + hu), (q1, q2, u - hu)]
    cols = [np.concatenate([b[i] for b in blocks]) for i in range(3)]
    f = equation_rows(model, cols[:2], cols[2], 0).reshape(len(blocks), n)
    fq1 = (f[1] - f[2]) / (2 * h1)
    fq2 = (f[3] - f[4]) / (2 * h2)
    fu = (f[5] - f[6]) / (2 * hu) if need_u else None
    return f[0], fq1, fq2, fu


def forced_residual(model: SparseModel, basis: Basis, X: np.ndarray, w: float, table_m: float):
    """R(X, w), dR/dX, dR/dw and the time samples (q1, q2, f_q1) of the response at table amplitude
    `table_m` (m) and angular frequency `w` (rad/s)."""
    q2 = basis.E @ X
    dX = basis.ED @ X
    q1 = w * dX
    u = -table_m * w * w * basis.sin1
    f, fq1, fq2, fu = derivative_columns(model, q1, q2, u)
    R = w * w * (basis.D2 @ X) - basis.P @ f
    J = w * w * basis.D2 - basis.P @ (fq1[:, None] * (w * basis.ED) + fq2[:, None] * basis.E)
    Jw = 2 * w * (basis.D2 @ X) - basis.P @ (fq1 * dX) - basis.P @ (fu * (-2 * table_m * w * basis.sin1))
    return R, J, Jw, (q1, q2, fq1)


def peak_amplitude(x_period: np.ndarray, fine: int = 2048) -> float:
    """Half the peak-to-peak of one period of samples, from its spectrum on a fine grid (band-limited
    interpolation: the peak between samples, not the largest sample)."""
    spec = np.fft.rfft(np.asarray(x_period, float))
    y = np.fft.irfft(spec, fine) * (fine / x_period.size)
    return 0.5 * float(np.max(y) - np.min(y))


@lru_cache(maxsize=64)
def _fine_synthesis(harmonics: int) -> np.ndarray:
    return Basis(harmonics, max(1024, 16 * harmonics)).E


def coefficient_amplitude(X: np.ndarray) -> float:
    """Half the peak-to-peak of the response with coefficients X (on a fine grid: the peak between
    samples, to 1e-5 of it)."""
    y = _fine_synthesis((X.size - 1) // 2) @ X
    return 0.5 * float(np.max(y) - np.min(y))
