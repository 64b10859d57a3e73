"""Real data: the Silverbox benchmark (data/silverbox/SNLS80mV.mat and the distribution's second record,
Schroeder80mV.mat, vendored in the repository).

Identification on the usual estimation range, free-run on the multisine test range, scored as the
literature does (1000 * RMSE after the first 50 samples, in mV). The default (equation-error) model
reaches 0.35 mV here (benchmarks/silverbox.py); the bound leaves room for numerical differences but
fails for any model that misses the cubic (~5 mV) or is merely linear (13.5 mV)."""
import importlib.util

import numpy as np
import pytest

from identify.identifier import SparseIdentifier
from identify.data.recording import read_recording
from identify.simulation.simulate import simulate

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


SECOND = DATA.parent / "Schroeder80mV.mat"
#: the 7-term rivals: the free-run budget's choice on the estimation range (q1^3) and the damping
#: form that extrapolates better on the arrowhead alone (q1*q2^2), benchmarks/silverbox_criteria.py
CANDIDATES = {"1", "q1", "q2", "q2^2", "q1^3", "q1*q2^2", "q2^3", "u"}


@pytest.mark.slow
def test_silverbox_two_records_budget_extrapolates_to_the_arrowhead(silverbox):
    """The free-run budget over the estimation range and the distribution's second record (vendored; none
    of it in a test set, output peaks 23 % higher): 7 of 8 candidate terms chosen by the pooled free-run
    error, refit on both records. The arrowhead test set, whose last 8500 samples exceed the estimation
    range's amplitudes by 39 %, then scores 0.312 mV, the same here and with the whole default support
    (benchmarks/silverbox.py; 0.376-0.384 mV from the estimation range alone, the target 0.36). The
    in-range multisine test pays for it: 0.280 against 0.249 mV."""
    from identify.selection.budget import choose_budget
    from identify.regression.gram import BlockGram
    from identify.identifier import holdout_blocks, per_record
    from identify.simulation.refine import FreeRunError

    spec = importlib.util.spec_from_file_location("silverbox_bench", DATA.parents[2] / "benchmarks" / "silverbox.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert SECOND.exists(), f"the second Silverbox record expected at {SECOND} (vendored in the repository)"
    recs = [silverbox.slice(*bench.ESTIMATION), read_recording(SECOND, "force", "V1", "V2", fs_hz=FS)]
    ident = SparseIdentifier(validate=False, bias_replicates=0, placements=0).fit(recs)
    sigs, names = ident.joint_states_, ident.library_.names
    parts = [holdout_blocks(s) for s in sigs]
    gram = BlockGram.concatenate([ident._gram(s, e) for s, (e, _) in zip(sigs, parts)])
    held = np.concatenate([h for _, h in parts])
    rows = per_record(ident.heldout_rows_, sigs)
    support = np.array([n in CANDIDATES for n in names])
    choice = choose_budget(ident.model_, names, support, 7, gram.equations(~held), sigs, rows(np.logical_not),
                           rows(np.asarray), n_refit=2)
    assert set(choice.model.equations["q1_dot"]) == CANDIDATES - {"q1*q2^2"}
    substeps = FreeRunError(sigs[0], None, model=choice.model).substeps
    rmse = bench.score(choice.model, silverbox.input, silverbox.output, substeps)
    assert rmse["arrow_full"] < 0.34 and rmse["multisine"] < 0.30
