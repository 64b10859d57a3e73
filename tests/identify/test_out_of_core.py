"""Out-of-core identification (identify.out_of_core) against known truth and against the in-core path."""
import tracemalloc

import numpy as np
import pytest

from identify.errors import IdentificationError
from identify.identifier import SparseIdentifier
from identify.out_of_core import ChunkedIdentifier
from identify.data.recording import Recording
from protocol.sweep import SineSweep

#: as tests/identify/test_identifier.py (issue 2 acceptance): within 2 %, the weak q1*q2^2 within 5 %
TOLERANCE = {"q1*q2^2": 0.05}


@pytest.fixture(scope="module")
def fits(table1_run):
    """The acceptance sweep (60 s at 2048 Hz) in 2^15-sample chunks (4 chunks of the 123 k), and in core,
    both with their defaults (the chain bias in closed form)."""
    rec = table1_run.recording
    return ChunkedIdentifier(chunk_samples=1 << 15).fit(rec), SparseIdentifier().fit(rec)


def test_chunked_identification_recovers_the_table1_model(fits, table1_truth, true_q1_terms):
    chunked, _ = fits
    model = chunked.model_
    assert set(model.equations["q1_dot"]) == true_q1_terms
    assert set(model.equations["q2_dot"]) == {"q1"}
    for term, true in table1_truth["q1_dot"].items():
        assert abs(model.coefficient("q1_dot", term) / true - 1) < TOLERANCE.get(term, 0.02), term
    res = chunked.result()
    assert res["status"] == "ok", res["reason"]
    val = res["validation"]
    assert not val["diverged"] and val["windows"]["count"] == 10
    assert val["heldout"]["q1_dot"]["fit_percent"] > 98.0 and val["heldout"]["q2"]["fit_percent"] > 97.0
    assert res["out_of_core"]["chunks"] == 4
    # the chain's bias is removed as in core, in closed form; nothing says it was skipped
    assert res["uncertainty"]["chain_bias"]["method"] == res["out_of_core"]["chain_bias"] == "analytic (corrected score)"
    assert "chain_bias_skipped" not in res["uncertainty"]


def test_chunked_equals_in_core(fits):
    """Same data, same blocks, the same fit sequence on normal equations that differ by the chain's 1e-6:
    the same support, coefficients (chain bias removed in closed form) to 1e-6, the same row counts and
    inclusion probabilities; standard errors to 1e-3 (they rest on the residuals, the small difference
    of target and fit, which carries the chains' 1e-6 relative difference amplified, and on the noise's
    share of the variance, summed chunk by chunk over an overlap: 2e-4 measured on q2^3)."""
    chunked, incore = fits
    a, b = chunked.result(), incore.result()
    for eq, terms in b["model"].items():
        assert set(a["model"][eq]) == set(terms)
        for t, c in terms.items():
            assert a["model"][eq][t] == pytest.approx(c, rel=1e-6, abs=1e-12), (eq, t)
            assert a["standard_errors"][eq][t] == pytest.approx(b["standard_errors"][eq][t], rel=1e-3, abs=1e-12)
    for key in ("band_hz", "valid_samples", "fit_samples", "heldout_samples"):
        assert a["chain"][key] == pytest.approx(b["chain"][key]), key
    assert a["inclusion_probability"] == b["inclusion_probability"]
    assert a["uncertainty"]["chain_bias"]["noise_std"] == pytest.approx(b["uncertainty"]["chain_bias"]["noise_std"])
    # the windows (10 s in the middle of each 2.4 s held-out block = the block) score like the whole run
    for k in ("q1_dot", "q1", "q2"):
        assert a["validation"]["heldout"][k]["fit_percent"] == pytest.approx(
            b["validation"]["heldout"][k]["fit_percent"], abs=0.5), k


def _peak(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_memory_stays_bounded_by_the_chunk(make_run):
    """Peak traced memory (numpy's allocations included) of chunked identification does not grow with
    the record (12 and 24 tiles of a sweep that starts and ends at rest), while in core it grows with
    it: the in-core run of the 12-tile record already needs more than twice the chunked 24-tile run.
    Measured: chunked 23.9 MB (12 tiles) and 21.8 MB (24 tiles); in core 310 MB (12 tiles)."""
    rec = make_run(sweep=SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1024, seed=2).recording
    peaks = {}
    for reps in (12, 24):
        src = Recording(np.tile(rec.input, reps), np.tile(rec.output, reps), rec.fs_hz)
        ident = ChunkedIdentifier(chunk_samples=1 << 15, window_s=2.0, placements=4)
        peaks[reps] = _peak(lambda: ident.fit_source(src))
        assert ident.result()["status"] == "ok"
    big = Recording(np.tile(rec.input, 12), np.tile(rec.output, 12), rec.fs_hz)
    in_core = _peak(lambda: SparseIdentifier(bias_replicates=0, placements=4).fit(big))
    assert peaks[24] < 1.15 * peaks[12], peaks
    assert in_core > 2 * peaks[24], (in_core, peaks)


def test_whole_record_free_run_steps_are_refused(table1_run):
    with pytest.raises(IdentificationError, match="out of core"):
        ChunkedIdentifier(refine="free-run").fit(table1_run.recording)
