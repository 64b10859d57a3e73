"""FFT mechanics of the measurement chain, arranged to do each transform once.

`welch_psd` is scipy.signal.welch with a periodic Hann window, 50 % overlap, linear detrend of every
segment, density scaling and a one-sided mean, for one or several equally long signals: the same
numbers (tests/identify/test_spectral.py: to 1e-12 of the largest bin), at a fraction of the cost,
because the per-segment straight line is a closed-form projection instead of a least-squares solve per
segment, and all segments of all signals go through one batched rfft.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.fft import irfft, rfft, rfftfreq
from scipy.stats import chi2


#: Segments detrended and windowed together in welch_psd: 16 of 16384 samples are 2 MB of doubles.
WELCH_BLOCK = 16


def welch_psd(x: np.ndarray, fs_hz: float, nperseg: int, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and power spectral density ((unit)^2/Hz) of x, shape (n,) or (k, n) (one PSD per row).

    Equal to scipy.signal.welch(x, fs_hz, nperseg=nperseg, detrend="linear", axis=-1). dtype: the
    precision the detrended, windowed segments are transformed in (the segments' lines and the average
    stay double). np.float32 moves a PSD by ~2e-7 of its largest bin (tests/identify/test_spectral.py
    allows 1e-6) and puts its own floor ~157 dB below the peak (double: ~212 dB; a noise-free sweep of a
    million samples): a bin of a sweep in 0.5 % noise moves by at most 1.4e-5 of itself, but a bin of a
    noise-free signal below that floor is rounding (the segments are detrended in double and cast once:
    ~8e-8 of the largest bin). 27-42 % less time on a million samples."""
    x = np.asarray(x, dtype=float)
    rows = x[None, :] if x.ndim == 1 else x
    n = rows.shape[-1]
    nperseg = int(min(nperseg, n))
    noverlap = nperseg // 2
    hop = nperseg - noverlap
    n_seg = (n - noverlap) // hop
    # (k, n_seg, nperseg) views of the overlapping segments; the arithmetic below makes one copy
    segs = np.lib.stride_tricks.sliding_window_view(rows, nperseg, axis=-1)[:, ::hop][:, :n_seg]
    # least-squares line per segment: t centred, so mean and slope are independent projections
    t = np.arange(nperseg) - (nperseg - 1) / 2.0
    mean = segs.mean(axis=-1)
    slope = (segs @ t) / (t @ t)
    win = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)  # periodic Hann
    # segment win - (mean win + slope t win), in double, WELCH_BLOCK segments at a time (in cache: whole-
    # array steps made a (k, n_seg, nperseg) double temporary of the lines, 16 MB for a million samples,
    # and took over half the time), the windowed lines as one product [mean, slope] @ [win; t win], the
    # difference cast once into the array the transform reads
    basis = np.vstack([win, t * win])
    detrended = np.empty(segs.shape, dtype=dtype)
    d = np.empty((min(WELCH_BLOCK, n_seg), nperseg))
    for i in range(segs.shape[0]):
        for a in range(0, n_seg, WELCH_BLOCK):
            b = min(a + WELCH_BLOCK, n_seg)
            np.multiply(segs[i, a:b], win, out=d[:b - a])
            lines = np.column_stack([mean[i, a:b], slope[i, a:b]]) @ basis
            np.subtract(d[:b - a], lines, out=detrended[i, a:b], casting="same_kind")
    spec = rfft(detrended, axis=-1, overwrite_x=True)
    power = spec.real**2 + spec.imag**2
    p = power.mean(axis=1, dtype=np.float64) / (fs_hz * float(np.sum(win**2)))
    p[:, 1:-1 if nperseg % 2 == 0 else None] *= 2.0  # one-sided: negative frequencies folded in
    f = rfftfreq(nperseg, 1.0 / fs_hz)
    return f, (p[0] if x.ndim == 1 else p)


def welch_segments(n: int, nper: int) -> int:
    """How many segments (50 % overlap) welch_psd averages over a record of n samples."""
    return 1 + max(n - nper, 0) // (nper - nper // 2)


def welch_dof(segments: int) -> float:
    """Degrees of freedom of a bin of white noise in a Welch estimate over `segments` Hann segments of
    50 % overlap: ~2K / (1 + 2 c^2 (K - 1) / K), c = 0.167 (the overlapping segments are correlated)."""
    k = segments
    return 2 * k / (1 + 2 * 0.167**2 * (k - 1) / k)


def noise_level(p: np.ndarray, segments: int, quantile: float = 0.5) -> float:
    """The white-noise level (PSD) under Welch bins p, each the mean over `segments` Hann segments (50 %
    overlap): the bins' `quantile` divided by that quantile of the bins' own distribution as a fraction
    of its mean. The one noise-floor estimator of the identification (identify.noise.floor; docs/identification.md,
    "The noise floor"): the band search reads the whole spectrum's low decile (the band may fill most
    bins), the noise floors the median of the bins above the band (robust to a stray harmonic).

    A noise bin is chi-square with welch_dof(segments) degrees of freedom: its median lies below its
    mean by 0.3 % over the ~120 segments of a million-sample record in 16384-sample segments, by 11 %
    over 3; its low decile is 0.67 of the mean over 14 segments and 0.37 over 3 (undivided, a 10 dB
    threshold over it sat at 3.7 dB over the noise of a short record, and noise bins crossed it)."""
    dof = welch_dof(segments)
    return float(np.quantile(p, quantile) / (chi2.ppf(quantile, dof) / dof))


def bin_weights(n_bins: int, nfft: int) -> np.ndarray:
    """w_k of an nfft-point rfft's bins 0 .. n_bins - 1 in a sum over the whole spectrum (Parseval, the
    inverse transform): 2, a bin and its negative frequency, except the bins that are their own twin, DC
    and, for an even nfft only, Nyquist (an odd nfft's last bin has a twin)."""
    w = np.full(n_bins, 2.0)
    w[0] = 1.0
    if nfft % 2 == 0 and n_bins - 1 == nfft // 2:
        w[-1] = 1.0
    return w


def polyphase_factor(nfft: int, k_max: int, largest: int = 8) -> int:
    """The largest M <= `largest` that divides nfft with k_max < nfft / (2 M): the number of polyphase
    components a spectrum that is zero above bin k_max can be split into without aliasing (1: none)."""
    for m in range(largest, 1, -1):
        if nfft % m == 0 and 2 * k_max * m < nfft:
            return m
    return 1


def _twiddles(nfft: int, m: int, k_max: int, dtype=np.complex128) -> np.ndarray:
    """exp(-2 pi i k r / nfft) for r < m, k <= k_max, shape (m, k_max + 1), in the precision of the
    spectra they multiply (complex64 for identify.trust.noise_spread's). Cached, one entry per precision
    whatever the argument's spelling: the chain's forward and inverse transforms of one record share them
    (read-only)."""
    return _cached_twiddles(nfft, m, k_max, np.dtype(dtype).name)


@lru_cache(maxsize=8)
def _cached_twiddles(nfft: int, m: int, k_max: int, dtype: str) -> np.ndarray:
    """Row 1, w^k = exp(-2 pi i k / nfft), as the products of two short tables of exponentials
    (k = q B + r, B ~ sqrt(k_max): w^(qB) w^r, ~2 sqrt(k_max) exponentials instead of k_max), row r as
    row r-1 times row 1: w^(k r) = (w^k)^r. At a million samples, M = 6 rows of ~70,000 bins: 0.3 ms
    against 1.4 ms with every exponential of row 1 computed (and 19-22 ms with every row's), a cost every
    new record's first fit pays three times (the chain, and the noise share's two steps); within
    ~1e-15 of exp(kr reduced mod nfft) (tests/identify/test_spectral.py)."""
    tw = np.empty((m, k_max + 1), dtype=complex)
    tw[0] = 1.0
    if m > 1:
        b = int(np.ceil(np.sqrt(k_max + 1)))
        coarse = np.exp(-2j * np.pi * (np.arange(-(-(k_max + 1) // b)) * b) / nfft)
        fine = np.exp(-2j * np.pi * np.arange(b) / nfft)
        tw[1] = np.multiply.outer(coarse, fine).ravel()[:k_max + 1]
    for r in range(2, m):
        np.multiply(tw[r - 1], tw[1], out=tw[r])
    tw = tw.astype(dtype, copy=False)
    tw.flags.writeable = False
    return tw


def lowband_rfft(x: np.ndarray, nfft: int, k_max: int, dtype=np.float64) -> np.ndarray:
    """rfft(x, nfft, axis=-1)[..., :k_max + 1] for real rows x (k, n <= nfft), zero-padded to nfft, the
    transforms in `dtype`'s precision (complex64 spectra for float32).

    Only the bins up to k_max are needed (the band's), so the transform splits into M polyphase
    components x[r::M], each an rfft of nfft / M points, recombined as X[k] = sum_r w^(k r) X_r[k]
    (M from polyphase_factor): the same numbers to rounding (tests/identify/test_spectral.py), and
    several times faster for a record of a million samples, because a transform of 2e6 points does not
    fit in cache and M of 2e6 / M points do."""
    k, n = x.shape
    m = polyphase_factor(nfft, k_max)
    length = nfft // m
    phases = np.empty((k, m, length), dtype=dtype)
    # the whole columns j < n // M as one transposing copy ((k, j, r) -> (k, r, j)): half the time of M
    # strided copies x[:, r::M] (4.4 against 10.2 ms for 3 rows of a million samples), then the last,
    # partial column and the zero padding
    whole = n // m
    phases[:, :, :whole] = x[:, :whole * m].reshape(k, whole, m).transpose(0, 2, 1)
    phases[:, :, whole:] = 0.0
    if n > whole * m:
        phases[:, :n - whole * m, whole] = x[:, whole * m:]
    return polyphase_rfft(phases, nfft, k_max)


def polyphase_rfft(phases: np.ndarray, nfft: int, k_max: int) -> np.ndarray:
    """lowband_rfft of rows already split into their polyphase components, phases[i, r, j] = x[i, j M + r]
    (zero from n on), shape (k, M, nfft / M) with M = polyphase_factor(nfft, k_max): for a caller that
    builds its rows in that order (identify.trust.noise_spread), which spares the split's copy. `phases` is
    overwritten."""
    m = phases.shape[1]
    parts = rfft(phases, axis=-1, overwrite_x=True)  # in the rows' precision (single: noise_spread)
    out = parts[:, 0, :k_max + 1].copy()
    if m > 1:
        tw = _twiddles(nfft, m, k_max, parts.dtype)
        for r in range(1, m):
            term = parts[:, r, :k_max + 1]
            term *= tw[r]  # in place: parts is ours
            out += term
    return out


def lowband_irfft(spec: np.ndarray, nfft: int, n_out: int, out_dtype=np.float64) -> np.ndarray:
    """irfft(Y, nfft, axis=-1)[..., :n_out] for spectra Y (k, k_max + 1) that are zero above bin k_max,
    as one (k, n_out) array of out_dtype (rows C-contiguous); the transforms in Y's precision (single for
    complex64 spectra).

    The output's polyphase components y[r::M] are each an irfft of nfft / M points of Y[k] w^(-k r) / M
    (no two bins alias while k_max < nfft / (2 M))."""
    k, kk = spec.shape
    k_max = kk - 1
    m = polyphase_factor(nfft, k_max)
    length = nfft // m
    rows = -(-n_out // m)  # output rows j < ceil(n_out / M) hold the samples t = M j + r < n_out
    z = np.zeros((k, m, length // 2 + 1), dtype=np.result_type(spec.dtype, np.complex64))
    if m == 1:
        z[:, 0, :kk] = spec
    else:
        tw = _twiddles(nfft, m, k_max, z.dtype)
        for r in range(m):
            np.multiply(spec, np.conj(tw[r]) / m, out=z[:, r, :kk])
    y = irfft(z, length, axis=-1, overwrite_x=True)
    del z
    # y[:, r, j] is the sample M j + r; one transposing copy into time order, in double precision
    out = np.empty((k, rows, m), dtype=out_dtype)
    out[...] = y[:, :, :rows].transpose(0, 2, 1)
    return out.reshape(k, rows * m)[:, :n_out]


@dataclass(frozen=True)
class BandLimitedSignal:
    """A band-limited signal as the chain makes it: the inverse transform of its spectrum on the band's
    bins 0..k_max of an nfft-point grid, plus the straight line value0 + slope t (per sample) restored
    when DC is in the band. It has values between its samples, exactly (a trigonometric polynomial),
    with no interpolation filter: what a free run's RK4 stages read at half steps (identify.chain.states,
    StateSignals.input_fine). `samples`: the array of its values at the samples it describes, the first
    of them at time `offset` of the transform (a stretch of a long record transformed with `offset`
    samples of overlap before it: identify.chain.chunked); times and the line are counted from that sample."""

    bins: np.ndarray
    nfft: int
    samples: np.ndarray
    line: tuple[float, float] = (0.0, 0.0)
    offset: int = 0

    def between_samples(self, fractions, n_out: int) -> np.ndarray:
        """(len(fractions), n_out) values at t + fraction, t = 0 .. n_out - 1 (fractions in samples):
        the spectrum shifted by exp(2 pi i k fraction / nfft), one batched inverse transform."""
        fractions = np.asarray(fractions, dtype=float)
        shift = np.exp(2j * np.pi * np.outer(fractions, np.arange(self.bins.size)) / self.nfft)
        y = lowband_irfft(self.bins * shift, self.nfft, self.offset + n_out)[:, self.offset:]
        value0, slope = self.line
        if value0 or slope:
            y += value0 + slope * (np.arange(n_out) + fractions[:, None])
        return y

    def at(self, times) -> np.ndarray:
        """Values at a few times (in samples, any real numbers), each summed over the bins directly
        (bin_weights, real parts), for when a whole transform would be spent on a handful of values."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        kk = self.bins.size
        weighted = bin_weights(kk, self.nfft) * self.bins
        # exp(2 pi i t k / nfft) for k < kk as products of two short tables (k = q B + r), as _twiddles:
        # ~2 sqrt(kk) exponentials per time instead of kk (a free run's last half step: 0.2 against 2 ms)
        b = int(np.ceil(np.sqrt(kk)))
        y = np.empty(times.size)
        for i, t in enumerate(self.offset + times):
            coarse = np.exp(2j * np.pi * t * (np.arange(-(-kk // b)) * b) / self.nfft)
            fine = np.exp(2j * np.pi * t * np.arange(b) / self.nfft)
            y[i] = (np.multiply.outer(coarse, fine).ravel()[:kk] * weighted).real.sum() / self.nfft
        value0, slope = self.line
        return y + value0 + slope * times
