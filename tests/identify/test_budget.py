"""The term budget chosen by free-run error (identify/selection/budget.py), against known truth.

Simulated rig: the paper's Table 1 model (5 terms in q1_dot) under a 30 s 1-20 Hz sweep at 1.3 mm, 0.5 %
noise, sampled at 1024 Hz. Given the true terms plus spurious candidates that can stand in for them (the constant, q2^2, and
the other cubic damping terms q1^3 and q1^2*q2, rivals of the weak q1*q2^2), a budget of 5 must keep
exactly the true terms, with their coefficients. Measured: the true set's refit free-run error 5.7e-5,
the runner-up {q1, q2, q1^3, q2^3, zdd} 9.3e-5, everything else > 2e-3; q1*q2^2 within 3.0 % of the
truth, the rest within 0.4 %. (The equation-error budget keeps the true terms here too: this rig does
not tell the two rules apart, Silverbox does.)

Silverbox (real data; the full 7-term figure is benchmarks/silverbox.py, minutes): from
{1, q1, q2, q2^2, q1^2*q2, q2^3, u} a budget of 6 chosen on the estimation range. Equation error drops
q2^2; free-run error drops q1^2*q2 (refit free-run error 9.0e-5 against 1.07e-4), and the arrowhead test
set, never seen in the choice, agrees: 0.393 mV against 0.456 mV for the set equation error keeps.
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from identify.selection.budget import choose_budget
from identify.errors import IdentificationError
from identify.regression.gram import BlockGram
from identify.identifier import SparseIdentifier, holdout_blocks
from identify.data.recording import read_recording
from identify.regression.optimizers.base import least_squares
from identify.selection.pareto import _backward_eliminate
from identify.simulation.simulate import choose_substeps
from protocol.sweep import SineSweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

REPO = Path(__file__).resolve().parents[2]
SPURIOUS = ("1", "q2^2", "q1^3", "q1^2*q2")


def _normal_equations(ident):
    """The fit-row normal equations and held-out mask the identifier used (for a given candidate set)."""
    sig, lib = ident.states_, ident.library_
    v = sig.valid
    edges, held = holdout_blocks(sig)
    gram = BlockGram.from_library(lib, (sig.q1[v], sig.q2[v]), sig.input[v][:, None],
                                  (sig.q1_dot[v], sig.q1[v]), edges)
    return gram.equations(~held), gram.equations(held), np.repeat(held, np.diff(edges))


def _equation_error_budget(support, train, heldout, max_terms):
    x = least_squares(train.G, train.B[:, 0], support)
    kept, _ = _backward_eliminate(support.copy(), x, train, heldout, 0, "paper", np.inf, 0.0, None, max_terms)
    return kept


@pytest.fixture(scope="module")
def rig_run(make_run):
    return make_run(sweep=SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1024.0)


@pytest.mark.parametrize("signals", [("q2", "q1"), ("q2",)], ids=["states", "output"])
def test_budget_keeps_the_true_terms_among_spurious_ones(rig_run, table1_truth, true_q1_terms, signals):
    """Chosen on the two states' free-run error (the default) or on the displacement's alone."""
    ident = SparseIdentifier(validate=False).fit(rig_run.recording)
    names = ident.library_.names
    train, _, held_rows = _normal_equations(ident)
    support = np.array([n in true_q1_terms or n in SPURIOUS for n in names])
    assert support.sum() == 9
    choice = choose_budget(ident.model_, names, support, 5, train, ident.states_, ~held_rows, held_rows,
                           signals=signals)
    q1 = choice.model.equations["q1_dot"]
    assert set(q1) == true_q1_terms
    assert {names[j] for j in np.flatnonzero(choice.support)} == true_q1_terms
    truth = table1_truth["q1_dot"]
    for term, c in q1.items():  # the weak q1*q2^2 comes out 3.0 % off, the rest within 0.4 % (0.5 % noise)
        assert c == pytest.approx(truth[term], rel=0.05 if term == "q1*q2^2" else 0.01), term
    # every candidate was screened, the refit ones ranked: the winner first, rivals clearly behind
    assert len(choice.candidates) == 126 and set(choice.candidates[0]["terms"]) == true_q1_terms
    # 1.64x measured on the two states; 1.15x on the displacement alone, which sees the damping terms less
    margin = 1.3 if "q1" in signals else 1.1
    assert choice.candidates[1]["refit"] > margin * choice.candidates[0]["refit"]
    assert choice.model.equations["q2_dot"] == {"q1": pytest.approx(1.0)}


def test_identifier_budget_by_free_run(rig_run, true_q1_terms):
    """Through SparseIdentifier: the paper's rule with a tight tolerance admits q1*q2 and q1^2*q2 on this
    record; max_terms=5 with the free-run budget removes them, and the result says how it chose."""
    ident = SparseIdentifier(selection="paper", tolerance=1e-3, max_terms=5, budget="free-run").fit(rig_run.recording)
    assert ident.budget_ is not None  # the rule's own choice was over budget
    assert set(ident.model_.equations["q1_dot"]) == true_q1_terms
    res = ident.result()
    assert res["status"] == "ok" and res["selection"]["budget"] == "free-run"
    assert res["refinement"]["accepted"] and res["budget"]["candidates"][0]["refit"] is not None
    assert res["selection"]["q1_dot"]["n_terms"] == 5
    assert set(res["standard_errors"]["q1_dot"]) == true_q1_terms
    assert "heldout_fitted" not in res["validation"]  # default: the winner never saw the held-out rows
    with pytest.raises(IdentificationError, match="unknown budget"):
        SparseIdentifier(max_terms=5, budget="aic").fit(rig_run.recording)
    with pytest.raises(IdentificationError, match="unknown budget_refit"):
        SparseIdentifier(max_terms=5, budget="free-run", budget_refit="heldout").fit(rig_run.recording)


def test_budget_refit_on_all_rows(rig_run, table1_truth, true_q1_terms):
    """budget_refit="all": the same terms (chosen before the final refit), their coefficients refit on
    the fit and held-out rows together, still the truth within the noise, and the result says that the
    validation's held-out rows were fitted."""
    ident = SparseIdentifier(selection="paper", tolerance=1e-3, max_terms=5, budget="free-run",
                             budget_refit="all").fit(rig_run.recording)
    q1 = ident.model_.equations["q1_dot"]
    assert set(q1) == true_q1_terms
    truth = table1_truth["q1_dot"]
    for term, c in q1.items():
        assert c == pytest.approx(truth[term], rel=0.05 if term == "q1*q2^2" else 0.01), term
    res = ident.result()
    assert res["selection"]["budget_refit"] == "all" and res["validation"]["heldout_fitted"] is True
    assert res["status"] == "ok"


def _silverbox_scorer():
    spec = importlib.util.spec_from_file_location("silverbox_bench", REPO / "benchmarks" / "silverbox.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_silverbox_budget_keeps_the_asymmetry():
    bench = _silverbox_scorer()
    rec = read_recording(REPO / "data/silverbox/SNLS80mV.mat", "force", "V1", "V2", fs_hz=bench.FS_HZ)
    ident = SparseIdentifier(validate=False).fit(rec.slice(*bench.ESTIMATION))
    names = ident.library_.names
    train, heldout, held_rows = _normal_equations(ident)
    support = np.array([n in {"1", "q1", "q2", "q2^2", "q1^2*q2", "q2^3", "u"} for n in names])
    by_equation_error = {names[j] for j in np.flatnonzero(_equation_error_budget(support, train, heldout, 6))}
    assert "q2^2" not in by_equation_error  # the choice this budget rule exists to correct
    choice = choose_budget(ident.model_, names, support, 6, train, ident.states_, ~held_rows, held_rows,
                           n_refit=2)
    assert set(choice.model.equations["q1_dot"]) == {"1", "q1", "q2", "q2^2", "q2^3", "u"}
    sig = ident.states_
    substeps = choose_substeps(choice.model, 1 / sig.fs_hz, 1.5 * np.max(np.abs(sig.states[sig.valid]), axis=0))
    rmse = bench.score(choice.model, rec.input, rec.output, substeps)
    # 0.393 / 0.317 mV measured; the set equation error keeps reaches 0.456 / 0.355 after the same refit
    assert rmse["arrow_full"] < 0.42 and rmse["arrow_no_extrapolation"] < 0.335
