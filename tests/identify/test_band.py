"""The chain's band from a record's spectrum (identify.chain.band): a weak fragment below the excited band,
within MAX_GAP_BINS of it, does not pull the band's bottom down (CI, seed 337754202: a 2-20 Hz noise input's
band started at 0.25 Hz, the record lost 15 s at each end to the live-edge guard and the cubic term was not
found); a real one (a multisine's lowest line) still counts."""
import numpy as np

from identify.chain.band import EDGE_FRAGMENT_SHARE, MAX_GAP_BINS, band_from_psd
from identify.chain.states import reconstruct_states
from identify.identifier import SparseIdentifier
from sim.synth import noise_input_recording

FS = 1024.0
NPER, N = 8192, 14 * 4096 + 4096  # 14 Welch segments, as a 60 s record at 1024 Hz has


def _psd(weak_bin_share: float):
    """A flat noise floor (1), a band of 100 bins at 1e6 from bin 12, and one bin 6 below it (within
    MAX_GAP_BINS) holding `weak_bin_share` of the band's power."""
    f = np.arange(NPER // 2 + 1) * FS / NPER
    p = np.ones_like(f)
    p[12:112] = 1e6
    p[6] = weak_bin_share * p[12:112].sum()
    return f, p


def test_a_weak_fragment_below_the_band_is_left_out_and_a_real_one_kept():
    df = FS / NPER
    assert 12 - 6 <= MAX_GAP_BINS  # the fragment would be merged by the gap rule alone
    lo, _ = band_from_psd(*_psd(EDGE_FRAGMENT_SHARE / 10), N, NPER)
    assert lo == 11 * df                            # the band's first bin less one
    lo, _ = band_from_psd(*_psd(EDGE_FRAGMENT_SHARE * 10), N, NPER)
    assert lo == 5 * df                             # a line with 0.1 % of the power is excitation


def test_noise_input_band_starts_where_the_excitation_does_and_its_cubic_term_is_found():
    """A 60 s record of 2-20 Hz noise on the Table 1 rig (0.5 % sensor noise), on a fresh seed and on the
    seed that failed: the chain's band starts within the filter's skirt (1.0-1.2 Hz on 201 fresh draws; was
    0.2 Hz), and the identified model holds every true term (seed 16 of a quick look also kept q1^4 and
    q2^4 before uncertain terms were judged by their standard errors alone)."""
    for seed in (337754202, int(np.random.SeedSequence().entropy % 2**31)):
        print("seed", seed)
        rec = noise_input_recording(seed)
        lo, _ = reconstruct_states(rec).band_hz
        assert 0.5 <= lo < 2.0, (seed, lo)
        res = SparseIdentifier().fit(rec).result()
        assert {"q1", "q2", "q1*q2^2", "q2^3", "zdd"} <= set(res["model"]["q1_dot"]), (seed, res["model"])
