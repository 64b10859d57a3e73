"""Measurement chain: from recorded channels to the states q1 (velocity), q2 (displacement) and q1_dot.

Band-limited frequency-domain integration (Schoukens 1990, cited by the paper's section 2.2): divide the
spectrum by (j w)^p inside the excited band and zero it outside, so drift and noise outside the band
are not integrated. Derivatives of displacement-type outputs are the converse, times (j w)^p.

Records are not periodic, so before the FFT each channel is
1. detrended: before differentiation, or filtering with DC in the band, by the straight line through
   its end samples (its periodic extension is then continuous; the line, or its derivative, is added
   back exactly); otherwise by its mean only: before integration (a line in an acceleration is a cubic
   in the displacement, not an offset), and before filtering with DC outside the band (the base
   layout's q1_dot and input), where the line would not be added back and the taper already makes the
   edges continuous (by_mean_alone),
2. tapered at both ends by a half-cosine over `taper_s` (no jump at the record's edges),
3. zero-padded to at least twice its length (no circular wrap-around of the integrals),
and afterwards the tapered edges plus a guard are *trimmed*: those samples are excluded from fitting.
The guard depends on the edge: a record that starts (ends) at rest, as a sweep with fades and settle
time does, loses nothing to the taper; a record cut while the rig moves has an error tail that decays
over a few periods of f_lo (0.9 % at 0.5 s, 0.1 % at 3 s for f_lo = 1 Hz: tests/identify/test_chain.py),
so a live edge is guarded by LIVE_EDGE_PERIODS periods of f_lo.
Band edges roll off with a half-cosine over a fraction of the edge frequency, which keeps the operator's
impulse response short (hard edges ring for seconds). Every signal that enters the regression, the input
included, goes through the same band so the equation stays consistent.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.fft import next_fast_len, rfftfreq

from .band import band_from_psd, excitation_spectrum
from ..errors import IdentificationError
from ..data.recording import Recording
from ..simulation.simulate import fine_grid_input
from .spectral import BandLimitedSignal, lowband_irfft, lowband_rfft, welch_segments

#: Band edge roll-off as a fraction of the edge frequency (lower: down to f_lo/2; upper: up to 1.25 f_hi).
EDGE_FRACTION = 0.5
#: Zero padding of the transforms in periods of f_lo (padded_length): what the states lose to wrap-around
#: is below 1e-9 of their peak from ~20 periods on (docs/identification.md, Benchmarks).
PAD_PERIODS = 40
#: Guard beyond the taper at an edge where the record is not at rest, in periods of f_lo.
LIVE_EDGE_PERIODS = 3.0
#: An edge is at rest when its RMS is below this fraction of the record's RMS.
AT_REST_FRACTION = 0.02
#: Precision of the states' transforms (reconstruct_states; detrending, taper, filters and states are double
#: whatever it is). Single: its rounding is white noise of ~1e-7 of a channel's scale, imaged like the
#: sensors' noise (>= 1.5e-5 of full scale at 16 bits): beside noise at 1e-4 of the channels' std, 0.1-0.6 %
#: of the noise's image in RMS (tests/identify/test_chain.py). A million-sample sweep's coefficients moved by
#: <= 1.1e-7 of themselves, its chain took 0.075 s against 0.11 s (benchmarks/identify_speed.py).
STATE_DTYPE = np.float32


@dataclass(frozen=True)
class BandSpectra:
    """Welch PSDs ((unit)^2/Hz, one-sided) of a record's input and response (base layout: output - input)
    on the bins f_hz, each the mean over `segments` Hann segments (identify.chain.band.excited_band's, single precision)."""

    f_hz: np.ndarray
    input: np.ndarray
    response: np.ndarray
    segments: int


@dataclass
class StateSignals:
    """States and derivatives on the recording's samples; only rows in `valid` are fit for use."""

    q1: np.ndarray      # velocity (m/s for the rig)
    q2: np.ndarray      # displacement (m)
    q1_dot: np.ndarray  # acceleration (m/s^2): the regression target of the first equation
    input: np.ndarray   # band-limited input (zdd or u)
    fs_hz: float
    band_hz: tuple[float, float]
    valid: slice
    input_name: str
    taper_n: int = 0
    #: the displacement below the band (m), when identified (identify.chain.inband.slow_displacement)
    q2_offset: np.ndarray | None = None
    #: the input as the chain made it (its band's spectrum), when kept: exact between samples (input_fine)
    input_spectrum: BandLimitedSignal | None = None
    #: the raw channels' Welch spectra the band search read (base layout, automatic band): the noise
    #: floors are read from them too (identify.trust.uncertainty.noise_floors), not from spectra of their own
    spectra: BandSpectra | None = None

    @property
    def states(self) -> np.ndarray:
        """The states a model is written in: q1, and q2 plus the displacement below the band when it
        is known (accelerometers miss the static offset an even force produces; the terms of a rig's
        force are those of the true displacement)."""
        return np.column_stack(self.state_columns())

    def state_columns(self, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(q1, q2 [+ q2_offset]) on `rows`: the states' columns, without building the (n, 2) array."""
        q2 = self.q2[rows] if self.q2_offset is None else self.q2[rows] + self.q2_offset[rows]
        return self.q1[rows], q2

    def input_fine(self, substeps: int, stride: int = 1) -> np.ndarray:
        """The input on the valid rows every h/2, h = 1 / (fs substeps): simulate()'s inputs_fine, shape
        ((n - 1) 2 substeps + 1, 1). The chain's input is band-limited by construction, a trigonometric
        polynomial, so when its spectrum was kept (and `input` is still the array it describes) the
        values between samples are that polynomial's, exactly, from one inverse transform of the shifted
        spectrum; otherwise fine_grid_input interpolates the samples (its windowed-sinc filter scales the
        samples themselves by 1.0005 at 1 substep, 1.0007 at 3, and misses an in-band tone by ~4e-4).
        stride (even, substeps 1): the grid a run in steps of `stride` samples reads (simulate's stride):
        its steps' middles are samples, so only the last, shorter step's middle, when it falls between
        samples, is computed (from the spectrum directly); the half samples no step reads are NaN."""
        v = self.valid
        up = 2 * substeps
        spec = self.input_spectrum
        if spec is None or spec.samples is not self.input or up == 1 or v.stop - v.start < 2:
            return fine_grid_input(self.input[v][:, None], substeps)
        n = v.stop - v.start
        fine = np.empty(((n - 1) * up + 1, 1))
        fine[::up, 0] = self.input[v]
        if stride > 1 and stride % 2 == 0 and substeps == 1:
            fine[1::2, 0] = np.nan
            last = (n - 1) % stride  # the last step's length, in samples
            if last % 2:
                start = n - 1 - last
                fine[2 * start + last, 0] = spec.at(v.start + start + last / 2)[0]
            return fine
        between = spec.between_samples(np.arange(1, up) / up, v.stop - 1)
        for p in range(1, up):
            fine[p::up, 0] = between[p - 1, v.start:]
        return fine

    def band_limit(self, x: np.ndarray) -> np.ndarray:
        """Pass a signal on the valid rows (a simulation, a library column) through the same band as the
        measured states, so that it is compared with them like with like: accelerometers cannot see
        what lies outside the band (e.g. the static offset an asymmetric spring produces)."""
        return spectral_op(x, self.fs_hz, self.band_hz, 0, self.taper_n)

    def band_limit_many(self, xs) -> list[np.ndarray]:
        """band_limit of several equally long signals, their transforms batched (a few at a time, so a
        long record's padded spectra stay within a few hundred MB)."""
        xs = list(xs)
        out = []
        for a in range(0, len(xs), 4):
            group = xs[a:a + 4]
            out += spectral_ops(group, self.fs_hz, self.band_hz, [(i, 0) for i in range(len(group))], self.taper_n)
        return out

    def band_limit_derivatives(self, x: np.ndarray, powers, dtype=np.float64) -> np.ndarray:
        """x through the band, times (j w)^p on the band's bins for each p of `powers`, from one transform:
        what the chain makes of a displacement x and of its derivatives (its q1 and q1_dot are those of
        its q2), for a simulated displacement (identify.simulation.validation), as the rows of one (len(powers), n)
        array. Every power shares the detrending of the lowest (for power 0: x's mean, or with DC in the
        band the line through its ends, as band_limit); on a tapered signal a derivative's own line would
        differ within the taper alone. dtype: the transforms' precision and the results'."""
        return _spectral_ops([x], self.fs_hz, self.band_hz, [(0, p) for p in powers], self.taper_n, dtype,
                             shared=True, out_dtype=dtype)[0]


def band_gain(f: np.ndarray, band: tuple[float, float], fs_hz: float) -> np.ndarray:
    """1 inside [f_lo, f_hi], half-cosine roll-off outside, 0 beyond (the cosines evaluated on the
    roll-off bins only: on a record's million FFT bins they were most of the operator's cost)."""
    lo, hi = band
    f = np.asarray(f, dtype=float)
    g = np.ones_like(f)
    if lo > 0:
        a = lo * (1 - EDGE_FRACTION)
        below = f < lo
        g[below] = 0.5 - 0.5 * np.cos(np.pi * np.clip((f[below] - a) / (lo - a), 0, 1))
    top = min(hi * (1 + EDGE_FRACTION / 2), fs_hz / 2)
    if top > hi:
        roll = (f > hi) & (f < top)
        g[roll] = 0.5 + 0.5 * np.cos(np.pi * np.clip((f[roll] - hi) / (top - hi), 0, 1))
        g[f >= top] = 0.0  # = 0.5 + 0.5 cos(pi), exactly
    return g


def padded_length(n: int, fs_hz: float, band: tuple[float, float]) -> int:
    """FFT length for a record of n samples: zero padding long enough that the band-limited operators'
    impulse responses (they decay within a few periods of f_lo, the roll-off being a half-cosine down
    to f_lo/2) do not wrap around: PAD_PERIODS periods of f_lo, at most the record's own length (the
    earlier rule, 2n in all, which a long record pays for with FFTs twice its size for nothing)."""
    pad = n if band[0] <= 0 else min(n, int(np.ceil(PAD_PERIODS * fs_hz / band[0])))
    return next_fast_len(n + pad, real=True)


#: (signal row, power) for q1, q2, q1_dot and the input, in that order, from the signals [response,
#: input]: base layout, the relative acceleration integrated once and twice; force layout, the output
#: (a displacement) as q2, differentiated once and twice.
STATE_REQUESTS = {"base": [(0, -1), (0, -2), (0, 0), (1, 0)], "force": [(0, 1), (0, 0), (0, 2), (1, 0)]}


def taper_ramp(k: np.ndarray, taper_n: int) -> np.ndarray:
    """The edge taper's half-cosine at sample k (0-based) of a taper_n-sample edge."""
    return 0.5 - 0.5 * np.cos(np.pi * (np.asarray(k) + 0.5) / taper_n)


def band_bins(nfft: int, fs_hz: float, band: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and band gains of the bins 0..k_max an nfft-point spectrum keeps: the bins above
    the band's roll-off are zero, so only these are transformed (identify.chain.spectral)."""
    n_bins = nfft // 2 + 1
    step = 1.0 / (nfft * (1.0 / fs_hz))  # rfftfreq's bin spacing, computed as it does: the same numbers
    top = min(band[1] * (1 + EDGE_FRACTION / 2), fs_hz / 2)  # band_gain is zero from here on
    k_top = min(int(top / step) + 2, n_bins)  # a band to 133 Hz at 2048 Hz: 13 % of a million bins
    f = np.arange(k_top) * step
    g = band_gain(f, band, fs_hz)
    if k_top < n_bins and g[-1] != 0:  # not zero past `top` after all: every bin
        f = rfftfreq(nfft, 1.0 / fs_hz)
        g = band_gain(f, band, fs_hz)
    k_max = int(np.flatnonzero(g)[-1])
    return f[:k_max + 1], g[:k_max + 1]


def band_filter(pairs, f: np.ndarray, g: np.ndarray, band: tuple[float, float], dtype=complex) -> np.ndarray:
    """(len(pairs), f.size) spectra of `dtype`: each (spectrum, power) pair times the band-limited (j w)^power."""
    out = np.empty((len(pairs), f.size), dtype=dtype)
    for k, (spectrum, power) in enumerate(pairs):
        np.multiply(spectrum, _band_response(f, g, band, power), out=out[k])
    return out


def spectral_op(x: np.ndarray, fs_hz: float, band: tuple[float, float], power: int, taper_n: int) -> np.ndarray:
    """Band-limit x and multiply its spectrum by (j w)^power (power < 0 integrates)."""
    return spectral_ops([x], fs_hz, band, [(0, power)], taper_n)[0]


def spectral_ops(signals, fs_hz: float, band: tuple[float, float], requests, taper_n: int,
                 dtype=np.float64) -> list[np.ndarray]:
    """spectral_op for several (signal index, power) `requests` on equally long `signals`, with each
    detrended signal transformed once: integrals of one signal share its spectrum, and all forward
    and all inverse transforms go through one batched rfft / irfft each, of the band's bins only.
    dtype : the transforms' precision (the detrending and the results are double whatever it is)."""
    return list(_spectral_ops(signals, fs_hz, band, requests, taper_n, dtype)[0])


def _spectral_ops(signals, fs_hz, band, requests, taper_n, dtype=np.float64, shared=False, out_dtype=np.float64):
    """spectral_ops' results as the rows of one (len(requests), n) array of out_dtype, and each as a
    BandLimitedSignal (its filtered bins, shared; the line). shared: every request of a signal detrended
    as its lowest power's (detrend_rows; StateSignals.band_limit_derivatives)."""
    signals = [np.asarray(x, dtype=float) for x in signals]
    n = signals[0].size
    # integrating: only the mean goes. A line removed from an acceleration is a cubic removed from
    # the displacement, which leaks into the band; the taper alone makes the edges continuous.
    # Differentiating/filtering with DC in the band: the straight line through the end samples, whose
    # own derivative is known exactly and is restored below (by_mean_alone).
    rows, row_of = detrend_rows(requests, band, shared)
    lines = {}  # the end-point lines, kept only when DC is in the band (restored below)
    xd = np.empty((len(rows), n), dtype=dtype)  # detrended in double, stored as the transforms read it
    ramp = taper_ramp(np.arange(taper_n), taper_n) if taper_n > 0 else None
    steps = None  # 0, 1, ..., n - 1 as floats, shared by the lines
    for r, (i, alone) in enumerate(rows):
        x = signals[i]
        if alone:
            np.subtract(x, x.mean(), out=xd[r], casting="same_kind")
        else:
            # x[0] + (x[-1] - x[0]) k / (n - 1), in place, operation for operation (the same numbers)
            steps = np.arange(n, dtype=float) if steps is None else steps
            line = np.multiply(steps, x[-1] - x[0])
            line /= max(n - 1, 1)
            line += x[0]
            np.subtract(x, line, out=xd[r], casting="same_kind")
            if band[0] == 0:
                lines[i] = line
        if taper_n > 0:
            xd[r, :taper_n] *= ramp
            xd[r, n - taper_n:] *= ramp[::-1]
    nfft = padded_length(n, fs_hz, band)  # zero-padded: no circular wrap-around of the integrals
    f, g = band_bins(nfft, fs_hz, band)
    spectra = lowband_rfft(xd, nfft, f.size - 1, dtype)
    del xd
    out = band_filter([(spectra[r], power) for r, (_, power) in zip(row_of, requests)], f, g, band, spectra.dtype)
    del spectra
    y = lowband_irfft(out, nfft, n, out_dtype)
    exact = []
    for k, (i, power) in enumerate(requests):
        yk = y[k]
        line = (0.0, 0.0)
        if band[0] == 0 and power in (0, 1):
            # DC is in the band: the detrending line is signal, restore it (or its slope)
            x = signals[i]
            slope = (x[-1] - x[0]) / max(n - 1, 1)
            yk += lines[i] if power == 0 else slope * fs_hz
            line = (float(x[0]), float(slope)) if power == 0 else (float(slope * fs_hz), 0.0)
        exact.append(BandLimitedSignal(out[k], nfft, yk, line))
    return y, exact


def by_mean_alone(requests, band: tuple[float, float]) -> list[bool]:
    """Per (signal, power) request, whether its signal is detrended by its mean alone (else by the line
    through its end samples), request by request (a result does not depend on what else is asked). The
    line serves a derivative (power > 0: a continuous periodic extension, whatever the taper) and a
    signal filtered with DC in the band (the line is signal, restored). Otherwise the mean alone:
    integrals, and a signal filtered with DC outside the band (the base layout's q1_dot and input),
    whose line would not be restored and would only take its image in the band out of the signal. The
    base layout's q1_dot is then exactly the derivative of q1 on the band's bins, both from one
    transform of the response: two forward transforms for its states, not three (the line moved the
    Table 1 fits' coefficients by < 7e-8 of themselves, their free-run fits by < 4e-5 percentage points,
    docs/identification.md section 1)."""
    return [p < 0 or (p == 0 and band[0] > 0) for _, p in requests]


def detrend_rows(requests, band: tuple[float, float], shared: bool = False) -> tuple[list[tuple[int, bool]], list[int]]:
    """The distinct detrended signals the requests need, as sorted (signal, by mean alone) rows (one
    forward transform each), and per request the index of its row (by_mean_alone; shared: each signal
    detrended as its request of the lowest power is, one row per signal)."""
    alone = by_mean_alone(requests, band)
    if shared:
        lowest = {}  # signal -> (lowest power, its detrending)
        for (i, p), a in zip(requests, alone):
            if i not in lowest or p < lowest[i][0]:
                lowest[i] = (p, a)
        alone = [lowest[i][1] for i, _ in requests]
    keys = [(i, a) for (i, _), a in zip(requests, alone)]
    rows = sorted(set(keys))
    return rows, [rows.index(k) for k in keys]


def _band_response(f: np.ndarray, g: np.ndarray, band: tuple[float, float], power: int) -> np.ndarray:
    """Band gain g times (j w)^power, w = 2 pi f, as g w^power times the constant j^power (one real
    array and one exact rotation instead of a complex power of every bin); 0 at DC unless filtering
    with DC in the band."""
    if power == 0:
        h = g.astype(complex)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            h = (g * (2.0 * np.pi * f) ** power) * (1j ** power)
    h[0] = 0.0 if power < 0 or band[0] > 0 else g[0] * (power == 0)
    return h


def band_and_taper(fs_hz: float, n: int, layout: str, band_hz, harmonics: float, taper_s, excited):
    """The chain's band (f_lo, f_hi) in Hz, edge taper (samples) and live-edge guard (samples), from the
    given band or, when band_hz is None, from excited() -> ((f_lo, f_hi) the input excites, f_lo where
    the response clears its noise floor, or None for the force layout): reconstruct_states reads them
    from the record, identify.chain.chunked from spectra accumulated chunk by chunk; the rule is this one."""
    nyq = fs_hz / 2
    if band_hz is None:
        (lo, hi), response_lo = excited()
        if layout == "base":
            # What is integrated is the response q'', which below resonance is weaker than the input by
            # (f/f_n)^2: where it does not clear its own noise floor, integrating amplifies only noise.
            lo = 0.8 * max(lo, response_lo)
        else:
            lo = 0.0
        band_hz = (lo, min(hi * harmonics, 0.8 * nyq))
    lo, hi = float(band_hz[0]), float(band_hz[1])
    if not (0 <= lo < hi <= nyq):
        raise IdentificationError(f"band {band_hz} Hz must satisfy 0 <= f_lo < f_hi <= Nyquist ({nyq:g} Hz)")
    if layout == "base" and lo <= 0:
        raise IdentificationError("integrating accelerations needs a band with f_lo > 0 Hz")
    if taper_s is None:
        taper_s = 1.0 / lo if lo > 0 else 64.0 / fs_hz
    taper_n = int(min(round(taper_s * fs_hz), n // 8))
    live_guard = int(round(LIVE_EDGE_PERIODS * fs_hz / lo)) if lo > 0 else 4 * taper_n
    return (lo, hi), taper_n, live_guard


def reconstruct_states(rec: Recording, band_hz: tuple[float, float] | None = None, harmonics: float = 5.0,
                       taper_s: float | None = None, dtype=STATE_DTYPE) -> StateSignals:
    """States of the paper (q1 = velocity, q2 = displacement) and q1_dot from a recording.

    band_hz : (f_lo, f_hi) to integrate in; default from the input's spectrum: its excited range, the top
        widened `harmonics`-fold for the response's nonlinear harmonics, capped below Nyquist; the
        bottom no lower than where the integrated response clears its noise floor, less 20 %.
    taper_s : edge taper length; default one period of f_lo (base layout) or 64 samples (force layout).
    dtype : the transforms' precision (STATE_DTYPE; np.float64 for the chain's numbers to rounding).
    """
    fs, n = rec.fs_hz, rec.n_samples
    response = rec.output - rec.input if rec.layout == "base" else rec.output
    read = {}

    def excited():
        """excited_band of the input and (base layout) the response's f_lo, the spectra kept in `read`."""
        f, p_in, nper = excitation_spectrum(rec.input, fs)
        if rec.layout != "base":
            return band_from_psd(f, p_in, n, nper), None
        p_resp = excitation_spectrum(response, fs)[1]
        read["spectra"] = BandSpectra(f, p_in, p_resp, welch_segments(n, nper))
        return band_from_psd(f, p_in, n, nper), band_from_psd(f, p_resp, n, nper)[0]

    (lo, hi), taper_n, live_guard = band_and_taper(fs, n, rec.layout, band_hz, harmonics, taper_s, excited)
    overall = _rms_about_mean(response)
    trims = [taper_n + (live_guard if _edge_is_live(response, edge, taper_n, overall) else taper_n // 2 + 1)
             for edge in ("start", "end")]
    if rec.n_samples - sum(trims) < 64:
        raise IdentificationError(f"{rec.source}: too short for band {lo:.3g}-{hi:.3g} Hz: "
                                  f"{rec.n_samples} samples, {sum(trims)} lost to edge tapers and guards")
    band = (lo, hi)
    # base layout: the relative acceleration q'' = x'' - z''; force layout: the output (a displacement)
    exact = _spectral_ops([response, rec.input], fs, band, STATE_REQUESTS[rec.layout], taper_n, dtype)[1]
    q1, q2, q1_dot, u = (e.samples for e in exact)  # the arrays the input's spectrum describes (input_fine)
    return StateSignals(q1, q2, q1_dot, u, fs, band, slice(trims[0], rec.n_samples - trims[1]),
                        "zdd" if rec.layout == "base" else "u", taper_n, input_spectrum=exact[3],
                        spectra=read.get("spectra"))


def _rms_about_mean(x: np.ndarray) -> float:
    """The record's RMS about its mean (what _edge_is_live compares an edge with), from x.x and the mean
    (no centred copy; what it compares needs a few digits, and cancellation costs eps (mean / RMS)^2)."""
    m = float(x.mean())
    return float(np.sqrt(max(np.dot(x, x) / max(x.size, 1) - m * m, 0.0)))


def _edge_is_live(x: np.ndarray, edge: str, n: int, overall: float | None = None) -> bool:
    """True when the record is not at rest over its first/last n samples (`overall`: _rms_about_mean(x),
    when already known: both edges compare with it)."""
    seg = x[:max(n, 1)] if edge == "start" else x[-max(n, 1):]
    overall = _rms_about_mean(x) if overall is None else overall
    return bool(np.sqrt(np.mean((seg - x.mean()) ** 2)) > AT_REST_FRACTION * overall)
