"""The measurement chain's image of white sensor noise, drawn or in closed form, without running the
chain on it: what the chain bias and the noise's share of the variance are computed from
(identify.trust.uncertainty, identify.chain.bias_correction, identify.trust.noise_spread)."""
from __future__ import annotations

import numpy as np

from ..chain.states import STATE_REQUESTS, _band_response, band_bins, padded_length
from ..chain.spectral import bin_weights, lowband_irfft


class BandLimitedNoise:
    """The chain's image (q1, q2, q1_dot, input; STATE_REQUESTS) of independent white noise on the two
    raw channels, drawn on the band's bins directly.

    The spectrum of white noise on nfft points is an independent complex Gaussian per bin (variance
    nfft std^2, real at DC and Nyquist); drawing the band's bins alone skips the rfft and most of the
    random numbers (a band to 87 Hz at 2048 Hz is 4 % of the bins). What this leaves out is the chain's
    detrending, taper and zero padding of the noise, which shape the record's ends only: the result is
    the stationary image the chain's output has on its valid rows (tests/identify/test_uncertainty.py
    compares covariances)."""

    def __init__(self, n: int, fs_hz: float, band: tuple[float, float], layout: str):
        self.n, self.layout, self.nfft = n, layout, padded_length(n, fs_hz, band)
        f, g = band_bins(self.nfft, fs_hz, band)
        self.requests = STATE_REQUESTS[layout]
        self.responses = [_band_response(f, g, band, power) for _, power in self.requests]  # drawn often
        self.gain, self.band, self.fs_hz = g, tuple(band), fs_hz

    def draw(self, std_in: float, std_out: float, rng: np.random.Generator) -> list[np.ndarray]:
        """One draw for white noise of std std_in, std_out (per sample) on the input and output
        channels: [q1, q2, q1_dot, input], each (n,)."""
        kk = self.responses[0].size
        # the bins that are their own twin (DC; Nyquist, for an even nfft): real, variance nfft std^2
        own_twin = np.flatnonzero(self.bin_weights() == 1.0)

        def white(std: float) -> np.ndarray:
            z = rng.standard_normal((2, kk)) * (std * np.sqrt(self.nfft / 2.0))
            spec = z[0] + 1j * z[1]
            spec[own_twin] = z[0, own_twin] * np.sqrt(2.0)
            return spec

        e_in, e_out = white(std_in), white(std_out)
        # the signals the chain transforms: [response, input]; base layout's response is output - input
        rows = [e_out - e_in if self.layout == "base" else e_out, e_in]
        out = np.array([rows[i] * h for (i, _), h in zip(self.requests, self.responses)])
        return list(lowband_irfft(out, self.nfft, self.n))

    def covariance(self, std_in: float, std_out: float) -> np.ndarray:
        """(4, 4) lag-0 covariance of what `draw` returns (q1, q2, q1_dot, input; units of those
        squared), exactly, without drawing: for outputs a, b of rows i, j (white noise of covariance
        c_ij per sample), cov = c_ij / nfft * sum_k w_k Re(H_a(k) conj H_b(k)) over the band's bins,
        w_k = 2 (each bin stands for itself and its negative frequency), 1 at DC and Nyquist.
        Stationary: the same on every row (a Gram's entries are sums of products at one time)."""
        h = np.array(self.responses)
        rows = [i for i, _ in self.requests]
        cross = (h * self.bin_weights()) @ h.conj().T  # (4, 4) sum_k w_k H_a conj(H_b)
        return cross.real * self.white_covariance(std_in, std_out)[np.ix_(rows, rows)] / self.nfft

    def bin_weights(self) -> np.ndarray:
        """w_k of the band's bins in a sum over the whole spectrum (spectral.bin_weights)."""
        return bin_weights(self.responses[0].size, self.nfft)

    def white_covariance(self, std_in: float, std_out: float) -> np.ndarray:
        """(2, 2) covariance per sample of the white signals the chain transforms, [response, input]
        (base layout's response is output - input, so it shares the input's noise)."""
        if self.layout == "base":
            return np.array([[std_out**2 + std_in**2, -std_in**2], [-std_in**2, std_in**2]])
        return np.diag([std_out**2, std_in**2])
