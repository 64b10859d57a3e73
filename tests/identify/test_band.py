"""The chain's band from a record's spectrum (identify.chain.band): a weak fragment below the excited band,
within MAX_GAP_BINS of it, does not pull the band's bottom down (CI, seed 337754202: a 2-20 Hz noise input's
band started at 0.25 Hz, the record lost 15 s at each end to the live-edge guard and the cubic term was not
found); a real one (a multisine's lowest line) still counts."""
import numpy as np
from scipy.signal import butter, sosfiltfilt

from identify.chain.band import EDGE_FRAGMENT_SHARE, MAX_GAP_BINS, band_from_psd
from identify.chain.states import reconstruct_states
from identify.data.recording import Recording
from identify.identifier import SparseIdentifier
from identify.simulation.simulate import equation_rows, simulate
from sim.rig import RigParameters

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
    seed that failed: the chain's band starts within the filter's skirt (>= 1 Hz, was 0.2 Hz), and the
    identified model holds every true term (seed 16 of a quick look also kept q1^4 and q2^4, a spurious
    pair this change does not touch)."""
    model = RigParameters.paper_table1().model()
    for seed in (337754202, int(np.random.SeedSequence().entropy % 2**31)):
        print("seed", seed)
        rng = np.random.default_rng(seed)
        zdd = sosfiltfilt(butter(4, [2.0, 20.0], "bandpass", fs=FS, output="sos"),
                          rng.standard_normal(int(60 * FS))) * 5
        run = simulate(model, 1 / FS, [0.0, 0.0], zdd[:, None], state_scale=np.array([0.1, 0.01]))
        mass = equation_rows(model, run.states, zdd) + zdd
        rec = Recording(zdd + 0.005 * np.std(zdd) * rng.standard_normal(zdd.size),
                        mass + 0.005 * np.std(mass) * rng.standard_normal(zdd.size), FS)
        lo, _ = reconstruct_states(rec).band_hz
        assert 1.0 <= lo < 2.0, (seed, lo)
        res = SparseIdentifier().fit(rec).result()
        assert {"q1", "q2", "q1*q2^2", "q2^3", "zdd"} <= set(res["model"]["q1_dot"]), (seed, res["model"])
