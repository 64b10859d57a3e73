"""The out-of-core measurement chain (identify.chain.chunked) against the whole-record chain (identify.chain.states).

Tolerance: the chunked states may differ from the whole-record ones by the band operator's tail beyond
the overlap (40 periods of f_lo) and the whole-record chain's own padding tail, both ~1e-6 of the peak
(measured: q2 1.3e-6 with 16k-sample chunks, the velocity and acceleration 1e-7 and below); the sensors'
noise is 0.5 % of each channel's std, so 1e-5 of the peak is far inside the noise and still catches any
misplaced taper, detrend, overlap or off-by-one sample (each of those errs by 1e-3 or more). Both chains
transform in double precision here (the algorithm is compared, not rounding: in their default single
precision the force layout's twice-differentiated q1_dot differs by ~1e-5 of its peak, each chain's
rounding, which tests/identify/test_chain.py bounds against the sensors' noise); the default's own
agreement is checked once, at the rounding's scale."""
import dataclasses

import numpy as np
import pytest

from identify.chain.band import excited_band
from identify.chain.states import reconstruct_states
from identify.chain.chunked import ChunkedChain, chunk_ranges
from identify.data.recording import Recording
from protocol.sweep import SineSweep

STATES = ("q1", "q2", "q1_dot", "input")
TOLERANCE = 1e-5  # of each state's peak on the valid rows (module doc)
DOUBLE = np.float64


def _scan(src, **kw):
    """ChunkedChain.scan with double-precision transforms (module doc)."""
    return dataclasses.replace(ChunkedChain.scan(src, **kw), dtype=DOUBLE)


@pytest.fixture(scope="module")
def sweep(make_run):
    return make_run(sweep=SineSweep(1.0, 20.0, 60.0, 1.3), fs_hz=1024, seed=1)


def _chunked_states(chain, src, chunk):
    parts = [chain.states(src, a, b) for a, b in chunk_ranges(0, src.n_samples, chunk)]
    return {name: np.concatenate([p[k] for p in parts]) for k, name in enumerate(STATES)}


def _assert_same(sig, chain, src, chunk):
    """Band, taper, valid rows identical; states within TOLERANCE of their peak on the valid rows."""
    assert chain.band_hz == pytest.approx(sig.band_hz, rel=1e-12)
    assert (chain.taper_n, chain.valid) == (sig.taper_n, sig.valid)
    got = _chunked_states(chain, src, chunk)
    v = sig.valid
    for name in STATES:
        ref = getattr(sig, name)[v]
        err = np.max(np.abs(got[name][v] - ref)) / np.max(np.abs(ref))
        assert err < TOLERANCE, (name, err)


@pytest.mark.parametrize("chunk", [1 << 14, 1 << 15, 40000])
def test_chunked_chain_equals_the_whole_record_chain(sweep, chunk):
    """Base layout (integration of accelerations): chunks smaller than, near and not a power of two of
    the overlap (29 k samples at f_lo = 1.4 Hz, 1024 Hz)."""
    rec = sweep.recording
    src = rec
    chain = _scan(src, chunk=chunk)
    assert chain.n == rec.n_samples and chunk < chain.overlap * 2 < rec.n_samples
    _assert_same(reconstruct_states(rec, dtype=DOUBLE), chain, src, chunk)


def test_chunked_chain_in_its_default_precision(sweep):
    """Both chains in their default (single-precision) transforms agree as closely on the base layout:
    rounding adds ~1e-7 of the peak to each, against TOLERANCE."""
    rec = sweep.recording
    chain = ChunkedChain.scan(rec, chunk=1 << 14)
    assert chain.dtype == reconstruct_states.__defaults__[-1] == np.float32
    _assert_same(reconstruct_states(rec), chain, rec, 1 << 14)


def test_band_from_chunked_welch_equals_excited_band(sweep):
    """The band comes from a Welch PSD accumulated over reads: the same segments, the same band as
    excited_band on the whole input (the scan's lower edge is 0.8 x the higher of input's and response's)."""
    rec = sweep.recording
    chain = ChunkedChain.scan(rec, chunk=5000)  # not a multiple of the Welch hop
    lo_in, hi_in = excited_band(rec.input, rec.fs_hz)
    lo_resp = excited_band(rec.output - rec.input, rec.fs_hz)[0]
    assert chain.band_hz[0] == pytest.approx(0.8 * max(lo_in, lo_resp), rel=1e-12)
    assert chain.band_hz[1] == pytest.approx(min(5 * hi_in, 0.8 * rec.fs_hz / 2), rel=1e-12)


def test_chunked_chain_force_layout(sweep):
    """Force layout (DC in the band, derivatives of a displacement, the line through the ends restored):
    the true relative displacement with 0.5 % noise as output, the table acceleration as input."""
    rec = sweep.recording
    rng = np.random.default_rng(3)
    y = sweep.states[:, 1] + 0.005 * np.std(sweep.states[:, 1]) * rng.standard_normal(rec.n_samples)
    force = Recording(rec.input, y, rec.fs_hz, "force", "u", "y", ("", ""))
    src = force
    chain = _scan(src, chunk=1 << 14)
    assert chain.band_hz[0] == 0.0
    _assert_same(reconstruct_states(force, dtype=DOUBLE), chain, src, 1 << 14)


@pytest.mark.parametrize("layout", ["base", "force"])
def test_a_windows_input_between_samples_is_the_chains(sweep, layout):
    """ChunkedChain.signals keeps the window's band-limited input as what it is (its spectrum, offset by
    the overlap; the line restored when DC is in the band), so a free run over a window reads the input
    between samples as the whole-record chain has it (StateSignals.input_fine), not interpolated: within
    TOLERANCE of the whole record's at the half steps (measured 6e-9 - 1e-8 of the peak)."""
    from identify.simulation.simulate import fine_grid_input
    rec = sweep.recording
    if layout == "force":
        rng = np.random.default_rng(3)
        y = sweep.states[:, 1] + 0.005 * np.std(sweep.states[:, 1]) * rng.standard_normal(rec.n_samples)
        rec = Recording(rec.input, y, rec.fs_hz, "force", "u", "y", ("", ""))
    whole = reconstruct_states(rec, dtype=DOUBLE)
    chain = _scan(rec, chunk=1 << 14)
    a, b = whole.valid.start + 20000, whole.valid.start + 40000
    window = chain.signals(rec, a, b)
    assert window.input_spectrum is not None and window.input_spectrum.samples is window.input
    got = window.input_fine(1)[:, 0]
    ref = whole.input_fine(1)[:, 0][2 * (a - whole.valid.start):2 * (b - whole.valid.start) - 1]
    scale = np.max(np.abs(ref))
    assert np.max(np.abs(got - ref)) < TOLERANCE * scale
    # interpolated: off by ~5e-4 inside the window and by 6-11 % at its edges, where resample_poly's
    # zero padding rings (the window's input is not at rest there); kept spectrum: 6e-9 - 1e-8 (measured)
    e = np.abs(fine_grid_input(window.input, 1)[:, 0] - ref)
    assert np.max(e[2000:-2000]) > 10 * np.max(np.abs(got - ref)) and np.max(e) > 0.01 * scale
