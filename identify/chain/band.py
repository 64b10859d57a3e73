"""Which band the measurement chain integrates in: the range a record's input excites above its noise
floor, read from Welch spectra (identify.chain.states.reconstruct_states reads them from the whole record,
identify.chain.chunked accumulates the same segments chunk by chunk; one rule, band_from_psd)."""
from __future__ import annotations

import numpy as np

from ..errors import IdentificationError
from .spectral import noise_level, welch_psd, welch_segments

#: Excited = Welch PSD at least this many dB above the noise floor (excited_band: the noise level itself).
EXCITATION_MARGIN_DB = 8.0  # over the noise level: the old rule's 10 dB over a low decile (0.55-0.67 of it)
#: Excited bins closer than this (Welch bins, ~0.125 Hz each) belong to one band.
MAX_GAP_BINS = 8
#: A fragment at the bottom of a band (excited bins cut off from the rest by a gap) counts only when it
#: holds at least this share of the band's power. The bin just above the skipped lowest ones carries the
#: Welch detrend's and window's leakage, 5e-8 to 8e-7 of the power of a 2-20 Hz noise input: over 201 fresh
#: draws the input's crossed the threshold within the gap rule's reach in 183, the response's in 9 (the
#: band's bottom follows the higher of the two): merged into the band it moved f_lo from ~1.1 Hz to 0.2 Hz, cost the record 15 s of live-edge
#: guard at each end and integrated noise below 1 Hz into the displacement (the cubic term was lost;
#: tests/identify/test_band.py). 1e-4 (40 dB under the band) keeps
#: every line of a multisine of up to 10^4 lines and a sweep's lowest bin (~1 % of its power). The top
#: edge is left as found: it is widened for harmonics anyway and costs no guard nor integrated noise.
EDGE_FRAGMENT_SHARE = 1e-4


def excited_band(x: np.ndarray, fs_hz: float, margin_db: float = EXCITATION_MARGIN_DB) -> tuple[float, float]:
    """Frequency range (Hz) where the signal's PSD stands `margin_db` above its noise floor."""
    f, p, nper = excitation_spectrum(x, fs_hz)
    return band_from_psd(f, p, x.size, nper, margin_db)


def excitation_spectrum(x: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(f Hz, PSD, segment length) of x that excited_band reads: scipy.signal.welch(..., detrend="linear")
    in segments of welch_length, transformed in single precision: a threshold 8 dB over the noise floor
    does not see the 1.4e-5 it moves a noisy bin by, and its own floor, ~157 dB below the peak, lies under
    any sensor's noise (welch_psd)."""
    nper = welch_length(x.size, fs_hz)
    f, p = welch_psd(x, fs_hz, nper, np.float32)
    return f, p, nper


def welch_length(n: int, fs_hz: float) -> int:
    """The Welch segment length excited_band uses on a record of n samples (~0.125 Hz resolution)."""
    nper = int(min(n, 2 ** int(np.ceil(np.log2(fs_hz * 8.0)))))
    return max(min(nper, n // 2), 16)


def band_from_psd(f: np.ndarray, p: np.ndarray, n: int, nper: int,
                  margin_db: float = EXCITATION_MARGIN_DB) -> tuple[float, float]:
    """excited_band's rule on a Welch PSD of a record of n samples in segments of nper (identify.chain.chunked
    accumulates that PSD chunk by chunk, without holding the record)."""
    skip = 3  # the lowest bins hold the window's leakage of offsets and drifts, not excitation
    # the noise level: the spectrum's low decile (robust to how many bins the excitation fills) over
    # the low decile of a noise bin's own distribution (spectral.noise_level, the one estimator)
    floor = noise_level(p[skip:], welch_segments(n, nper), 0.1)
    above = np.flatnonzero(p[skip:] > floor * 10 ** (margin_db / 10)) + skip
    if above.size == 0:
        raise IdentificationError("the input shows no excited frequency band above its noise floor")
    # With few Welch averages single bins of noise cross any threshold: keep the run of excited bins
    # (gaps up to MAX_GAP bins merged, for multisines' sparse lines) that holds the most power.
    breaks = np.flatnonzero(np.diff(above) > MAX_GAP_BINS)
    starts = np.concatenate([[0], breaks + 1])
    stops = np.concatenate([breaks, [above.size - 1]])
    power = [p[above[a]:above[b] + 1].sum() for a, b in zip(starts, stops)]
    best = int(np.argmax(power))
    lo_bin, hi_bin = _without_weak_bottom_fragments(p, above[starts[best]:stops[best] + 1]), above[stops[best]]
    df = f[1] - f[0]
    return float(max(f[lo_bin] - df, df)), float(min(f[hi_bin] + df, df * nper / 2))  # df nper / 2: Nyquist


def _without_weak_bottom_fragments(p: np.ndarray, bins: np.ndarray) -> int:
    """The first bin of a band (its excited bins, gaps merged) once the fragments at its bottom that hold
    less than EDGE_FRAGMENT_SHARE of its power are left out (a fragment: contiguous excited bins)."""
    fragments = np.split(bins, np.flatnonzero(np.diff(bins) > 1) + 1)
    power = np.array([p[f].sum() for f in fragments])
    first = 0
    while first < len(fragments) - 1 and power[first] < EDGE_FRAGMENT_SHARE * power.sum():
        first += 1
    return int(fragments[first][0])
