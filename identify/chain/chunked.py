"""The measurement chain (identify.chain.states) on a record read in chunks: a recording larger than memory.

The whole-record chain is linear: every output sample is the (detrended, tapered, zero-padded) record
convolved with the band-limited operator's impulse response, which decays within a few periods of the
band's bottom f_lo (what identify.chain.states.padded_length relies on). So the states of any stretch
[a, b) follow from the raw channels on [a - L, b + L) alone (overlap-save): that stretch, zeros where it
runs past the record's ends, is transformed with the same band and (j w)^p, and only its middle
b - a samples are kept; what the outer samples would have added is the impulse response's tail beyond
L = OVERLAP_PERIODS periods of f_lo, the same tail the whole-record chain loses to its padding.

What the whole-record chain reads from the whole record comes from one scan (`ChunkedChain.scan`):
- the band: excited_band's Welch PSD, accumulated over the very segments the whole-record Welch
  estimate averages (segments never straddle two reads), then the same rule (band.band_from_psd);
- the detrending (chain.by_mean_alone): the channel means and the end samples (the line through them),
- whether each edge is at rest (its RMS against the record's), hence the trims and the valid rows.
Memory is O(chunk + 2 L) whatever the record's length (tests/identify/test_chunked_chain.py).

A record comes from a *chunk source*: any object with `n_samples`, `fs_hz`, `layout`, `source` and
`read(start, stop) -> (input, output)` float arrays in the recording's units (identify.data.recording's
channels: base layout table and mass acceleration). A Recording in memory is one; daq.h5source reads the
DAQ's HDF5 files (identify itself stays numpy/scipy only).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.fft import next_fast_len

from .band import band_from_psd, welch_length
from .states import (EDGE_FRACTION, AT_REST_FRACTION, PAD_PERIODS, STATE_DTYPE, STATE_REQUESTS, BandSpectra,
                    StateSignals, band_and_taper, band_bins, band_filter, detrend_rows, taper_ramp)
from ..errors import IdentificationError
from .spectral import BandLimitedSignal, lowband_irfft, lowband_rfft, welch_psd

#: Overlap on each side of a chunk, in periods of f_lo: the same reach as the whole-record chain's padding.
OVERLAP_PERIODS = PAD_PERIODS
#: Samples per chunk (2^20: 8 MB a channel). With it the whole `shakeid identify --chunked` process peaked
#: at 262-394 MB RSS for 1e6-1e8 samples at 2048 Hz, f_lo 1.4 Hz (benchmarks/out_of_core.py).
CHUNK_SAMPLES = 1 << 20


class ChunkSource(Protocol):
    n_samples: int
    fs_hz: float
    layout: str
    source: str

    def read(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(input, output) samples [start, stop) as float arrays."""


def chunk_ranges(start: int, stop: int, size: int) -> list[tuple[int, int]]:
    """[a, b) ranges of at most `size` samples covering [start, stop)."""
    cuts = list(range(start, stop, max(int(size), 1))) + [stop]
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]


def _regressed(layout: str, inp: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The chain's two signals: (response, input); base layout's response is q'' = x'' - z''."""
    return np.vstack([out - inp if layout == "base" else out, inp])


@dataclass
class ChunkedChain:
    """What the chain knows of the whole record after one scan; `states(source, a, b)` then gives the
    states on any stretch from the raw channels on that stretch and its overlap."""

    fs_hz: float
    n: int
    layout: str
    band_hz: tuple[float, float]
    taper_n: int
    valid: slice
    overlap: int
    means: np.ndarray   # (2,) mean of response and input (detrending before integration)
    firsts: np.ndarray  # (2,) first samples (the line through the ends, before filtering/differentiation)
    lasts: np.ndarray   # (2,) last samples
    live_guard: int     # samples guarded at an edge that is not at rest (chain.band_and_taper)
    dtype: type = STATE_DTYPE  # the transforms' precision, as the whole-record chain's (reconstruct_states)
    #: the Welch spectra the band search read (base layout, automatic band), as StateSignals.spectra: the
    #: noise floors are read from them (identify.trust.uncertainty.noise_floors)
    spectra: BandSpectra | None = None

    @property
    def input_name(self) -> str:
        return "zdd" if self.layout == "base" else "u"

    @classmethod
    def scan(cls, source: ChunkSource, band_hz=None, harmonics: float = 5.0, taper_s: float | None = None,
             chunk: int = CHUNK_SAMPLES, progress=None) -> "ChunkedChain":
        """One pass over the record: Welch PSD (band), means, RMS; then the edges. Arguments as
        identify.chain.states.reconstruct_states; progress(stage, done, total) is called after each chunk."""
        n, fs, layout = int(source.n_samples), float(source.fs_hz), source.layout
        nper = welch_length(n, fs)
        hop = nper - nper // 2
        n_seg = (n - nper // 2) // hop
        chunk = max(hop, (int(chunk) // hop) * hop)  # whole segments start in each read
        psd = None
        sums, shift = np.zeros(2), None
        sumsq = np.zeros(2)
        ranges = chunk_ranges(0, n, chunk)
        for i, (a, b) in enumerate(ranges):
            x = _regressed(layout, *source.read(a, min(b + nper, n)))
            body = x[:, :b - a]
            if shift is None:
                shift = body.mean(axis=1)  # sums about a first estimate: no cancellation in the RMS
            d = body - shift[:, None]
            sums += d.sum(axis=1)
            sumsq += (d * d).sum(axis=1)
            k0, k1 = -(-a // hop), min(-(-b // hop), n_seg)  # segments starting in [a, b)
            if k1 > k0:
                # segments in single precision, as band.excited_band takes them: one rule for the band
                f, p = welch_psd(x[:, k0 * hop - a:(k1 - 1) * hop + nper - a], fs, nper, np.float32)
                psd = p * (k1 - k0) if psd is None else psd + p * (k1 - k0)
            if progress:
                progress("scan", i + 1, len(ranges))
        means = shift + sums / n
        rms = np.sqrt(np.maximum(sumsq / n - (sums / n) ** 2, 0.0))
        psd = psd / n_seg
        read = {}

        def excited():
            if layout != "base":
                return band_from_psd(f, psd[1], n, nper), None
            read["spectra"] = BandSpectra(f, psd[1], psd[0], n_seg)
            return band_from_psd(f, psd[1], n, nper), band_from_psd(f, psd[0], n, nper)[0]

        (lo, hi), taper_n, live_guard = band_and_taper(fs, n, layout, band_hz, harmonics, taper_s, excited)
        m = max(taper_n, 1)
        head = _regressed(layout, *source.read(0, min(m, n)))
        tail = _regressed(layout, *source.read(max(n - m, 0), n))
        trims = []
        for seg in (head[0], tail[0]):  # identify.chain.states._edge_is_live on the response
            live = np.sqrt(np.mean((seg - means[0]) ** 2)) > AT_REST_FRACTION * rms[0]
            trims.append(taper_n + (live_guard if live else taper_n // 2 + 1))
        if n - sum(trims) < 64:
            raise IdentificationError(f"{source.source}: too short for band {lo:.3g}-{hi:.3g} Hz: "
                                      f"{n} samples, {sum(trims)} lost to edge tapers and guards")
        # the operator's reach: periods of f_lo (integration), else of the top roll-off's width
        reach_hz = lo if lo > 0 else hi * EDGE_FRACTION / 2
        overlap = int(np.ceil(OVERLAP_PERIODS * fs / reach_hz))
        return cls(fs, n, layout, (lo, hi), taper_n, slice(trims[0], n - trims[1]), overlap, means,
                   head[:, 0].copy(), tail[:, -1].copy(), live_guard, spectra=read.get("spectra"))

    def _line(self, row: int, idx: np.ndarray) -> np.ndarray:
        """The straight line through the record's end samples of signal `row`, at sample indices idx."""
        return self.firsts[row] + (self.lasts[row] - self.firsts[row]) * idx / max(self.n - 1, 1)

    def states(self, source: ChunkSource, a: int, b: int):
        """(q1, q2, q1_dot, input) on samples [a, b), equal to reconstruct_states' on those rows up to
        the operator's tail beyond the overlap."""
        return self._states(source, a, b)[0]

    def _states(self, source: ChunkSource, a: int, b: int):
        """states(), and the input as a BandLimitedSignal (exact between samples, as the chain's)."""
        n, L, fs, band = self.n, self.overlap, self.fs_hz, self.band_hz
        s0, s1 = max(a - L, 0), min(b + L, n)
        x = _regressed(self.layout, *source.read(s0, s1))
        idx = np.arange(s0, s1, dtype=float)
        requests = STATE_REQUESTS[self.layout]
        rows, row_of = detrend_rows(requests, band)  # the chain's detrending, request by request
        length = (b - a) + 2 * L
        nfft = next_fast_len(length, real=True)
        off = s0 - (a - L)  # zeros before the record's start
        xd = np.zeros((len(rows), s1 - s0 + off))
        taper = self.taper_n
        w = None
        if taper > 0 and (s0 < taper or s1 > n - taper):  # the chain's half-cosine at the record's edges
            w = np.ones(s1 - s0)
            head, tail = idx < taper, idx >= n - taper
            w[head] = taper_ramp(idx[head], taper)
            w[tail] = taper_ramp(n - 1 - idx[tail], taper)
        for r, (i, alone) in enumerate(rows):
            trend = self.means[i] if alone else self._line(i, idx)
            xd[r, off:] = x[i] - trend
            if w is not None:
                xd[r, off:] *= w
        del x
        f, g = band_bins(nfft, fs, band)
        spectra = lowband_rfft(xd, nfft, f.size - 1, self.dtype)
        del xd
        out = band_filter([(spectra[r], p) for r, (_, p) in zip(row_of, requests)], f, g, band, spectra.dtype)
        del spectra
        y = lowband_irfft(out, nfft, L + (b - a))[:, L:]
        results = []
        for k, (i, p) in enumerate(requests):
            yk = np.ascontiguousarray(y[k])
            if band[0] == 0 and p in (0, 1):  # DC in the band: the detrending line is signal (chain)
                yk += self._line(i, np.arange(a, b, dtype=float)) if p == 0 else \
                    (self.lasts[i] - self.firsts[i]) * fs / max(n - 1, 1)
            results.append(yk)
        i = requests[3][0]  # the input, filtered (power 0): its line is restored when DC is in the band
        line = ((float(self._line(i, np.array([float(a)]))[0]), (self.lasts[i] - self.firsts[i]) / max(n - 1, 1))
                if band[0] == 0 else (0.0, 0.0))
        return tuple(results), BandLimitedSignal(out[3], nfft, results[3], line, offset=L)

    def signals(self, source: ChunkSource, a: int, b: int) -> StateSignals:
        """StateSignals of the stretch [a, b), all of it valid (free-run windows: identify.out_of_core)."""
        (q1, q2, q1_dot, u), exact = self._states(source, a, b)
        return StateSignals(q1, q2, q1_dot, u, self.fs_hz, self.band_hz, slice(0, b - a), self.input_name,
                            self.taper_n, input_spectrum=exact)

    def summary(self) -> StateSignals:
        """StateSignals without samples: band, valid rows, sample rate and input name of the record (what
        the identifier's selection and result need of the states when they are never held together)."""
        e = np.empty(0)
        return StateSignals(e, e, e, e, self.fs_hz, self.band_hz, self.valid, self.input_name, self.taper_n,
                            spectra=self.spectra)
