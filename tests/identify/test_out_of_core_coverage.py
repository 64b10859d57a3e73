"""Out of core with the same trust as in core: long DAQ recordings (daq.long_record over the simulated
sweep of sim.synth.noise_free_sweep: fresh sensor noise on every sample) written to HDF5 and read chunk by chunk (daq.h5source), against the in-core identifier on
the same samples and against the truth. Fresh seeds every run, printed (pytest -s shows them; a failure
names them)."""
import h5py
import numpy as np
import pytest

from daq.h5source import H5ChunkSource
from daq.long_record import write_long_record
from identify.identifier import SparseIdentifier
from identify.out_of_core import ChunkedIdentifier
from identify.data.recording import Recording
from sim.synth import noise_free_sweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

#: Coverage, counted by record: a record misses when one of its q1_dot terms lies more than Z_COVER standard
#: errors from the truth. q2, q2^3 and zdd are estimated together and their errors are correlated (-0.74,
#: 0.51, -0.64 over 29 fresh records), so misses come in twos and threes: the per-term count this test
#: used (one miss of 20) failed CI on an honest record (seed 4253729712: z -3.68, 3.07, 3.75; 29 other
#: records had mean z^2 0.84 and max |z| 2.7). With honest standard errors a record misses with probability
#: <= 5 x 0.27 % = 1.35 % whatever the correlation (Bonferroni), so more than MISSED_RECORDS of RECORDS
#: miss with probability <= 1.5e-4.
RECORDS, MISSED_RECORDS, Z_COVER = 8, 2, 3.0
#: ... and on average: the mean z^2 over all terms x records is ~1 with honest standard errors (sd ~0.27 for
#: 8 records of 5 correlated terms); over MEAN_Z2 it says they are too small by more than 1.5x overall.
MEAN_Z2 = 2.25


def _fresh_seeds(k: int) -> list[int]:
    seeds = [int(s) for s in np.random.SeedSequence().generate_state(k)]
    print("seeds", seeds)
    return seeds


def _q1_terms(res: dict):
    return res["model"]["q1_dot"], res["standard_errors"]["q1_dot"]


@pytest.mark.slow
def test_in_core_and_out_of_core_agree_on_a_million_samples(tmp_path):
    """The same 1e6 samples in core and in four chunks of 2^18 out of core: the same support, coefficients
    (chain bias removed in closed form in both) to 1e-5 and standard errors to 1e-3. Measured: 4e-7 and
    8.5e-5 in one chunk; the chunks add the chains' overlap-save error and the noise's share summed chunk
    by chunk over the overlap (2e-4 on the acceptance sweep in four chunks, tests/identify/test_out_of_core.py)."""
    (seed,) = _fresh_seeds(1)
    path = tmp_path / "long.h5"
    write_long_record(path, 1_000_000, noise_free_sweep().recording, seed=seed)
    out = ChunkedIdentifier(chunk_samples=1 << 18).fit_source(H5ChunkSource(path)).result()
    with h5py.File(path) as f:
        d = f["entry/data"]
        rec = Recording(d["table_acc"][:].astype(float), d["mass_acc"][:].astype(float), 2048.0, "base")
    inc = SparseIdentifier().fit(rec).result()
    assert out["out_of_core"]["chunks"] == 4 and out["uncertainty"]["chain_bias"]["method"] == "analytic (corrected score)"
    (c_out, se_out), (c_in, se_in) = _q1_terms(out), _q1_terms(inc)
    assert set(c_out) == set(c_in), seed
    for t in c_in:
        assert c_out[t] == pytest.approx(c_in[t], rel=1e-5), (seed, t)
        assert se_out[t] == pytest.approx(se_in[t], rel=1e-3), (seed, t)


@pytest.mark.slow
def test_out_of_core_standard_errors_cover_the_truth_at_ten_million_samples(tmp_path):
    """RECORDS records of 1e7 samples (81 min at 2048 Hz each, Table 1 rig, 0.5 % noise), identified out of
    core from HDF5 with the defaults: at most MISSED_RECORDS with a q1_dot term more than 3 standard errors
    from the truth, and the mean z^2 under MEAN_Z2. Before the chain bias was removed out of core, 1e7
    samples gave |z| up to 45 (issue 30, on records that also repeated their noise)."""
    zs = {}
    run = noise_free_sweep()
    for seed in _fresh_seeds(RECORDS):
        path = tmp_path / f"long_{seed}.h5"
        write_long_record(path, 10_000_000, run.recording, seed=seed)
        truth = run.recording.metadata["truth"]["model"]["q1_dot"]
        res = ChunkedIdentifier().fit_source(H5ChunkSource(path)).result()
        path.unlink()
        coefs, ses = _q1_terms(res)
        assert res["status"] == "ok" and set(coefs) == set(truth), (seed, res["reason"], coefs)
        zs[seed] = {t: (coefs[t] - truth[t]) / ses[t] for t in truth}
        print(seed, {t: round(z, 2) for t, z in zs[seed].items()})
    z = np.array([list(by_term.values()) for by_term in zs.values()])
    missed = [seed for seed, row in zip(zs, z) if np.abs(row).max() > Z_COVER]
    assert len(missed) <= MISSED_RECORDS, (missed, zs)
    assert np.mean(z ** 2) <= MEAN_Z2, (np.mean(z ** 2), zs)
