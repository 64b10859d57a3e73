"""Real data: the Silverbox benchmark (data/silverbox/SNLS80mV.mat, vendored in the repository).

Identification on the usual estimation range, free-run on the multisine test range, scored as the
literature does (1000 * RMSE after the first 50 samples, in mV). The default (equation-error) model
reaches 0.35 mV here (benchmarks/silverbox.py); the bound leaves room for numerical differences but
fails for any model that misses the cubic (~5 mV) or is merely linear (13.5 mV)."""
import numpy as np
import pytest

from identify.identifier import SparseIdentifier
from identify.recording import read_recording
from identify.simulate import simulate

DATA = __import__("pathlib").Path(__file__).resolve().parents[2] / "data/silverbox/SNLS80mV.mat"
FS = 1e7 / 2**14


@pytest.fixture(scope="module")
def silverbox():
    assert DATA.exists(), f"Silverbox data expected at {DATA} (vendored in the repository)"
    return read_recording(DATA, "force", "V1", "V2", fs_hz=FS)


def test_silverbox_multisine_free_run(silverbox):
    ident = SparseIdentifier().fit(silverbox.slice(40650, 105712))
    q1 = ident.model_.equations["q1_dot"]
    assert {"q2", "q2^3", "u", "q1"} <= set(q1) and q1["q2^3"] < 0  # a hardening Duffing structure
    a, b = 105712, 127400
    u, y = silverbox.input[a:b], silverbox.output[a:b]
    x0 = [(y[1] - y[0]) * FS, y[0]]
    sim = simulate(ident.model_, 1 / FS, x0, u[:, None], substeps=ident.validation_["substeps"], bound=1e4)
    rmse_mv = 1000 * np.sqrt(np.mean((y[50:] - sim.states[50:, 1]) ** 2))
    assert not sim.diverged and rmse_mv < 0.6
