"""End-stop features: stop(q2) = sign(q2) max(|q2| - d, 0) and contact(q2) = [|q2| > d], in the library,
the model JSON and the compiled kernel, against their formulas, a tight reference integrator and the
closed-form bounce of a mass on a linear damped bumper."""
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from identify.errors import ModelError
from identify.regression.library import Library
from identify.model import SparseModel
from identify.simulation.simulate import simulate
from identify.regression.terms import FeatureSpace

D = 0.0175                      # travel, m
W = 2 * np.pi * 200.0           # contact frequency, rad/s
TABLE1 = {"q1": -3.7294, "q2": -971.0169, "q1*q2^2": 1.162e4, "q2^3": -2.5033e6, "zdd": -1.0243}


def bumper(zeta: float, spring=None) -> SparseModel:
    """A mass on a rail with a damped bumper beyond +-D (coefficients per unit mass)."""
    q1 = {**(spring or {}), "stop(q2)": -W**2, "q1*contact(q2)": -2 * zeta * W}
    return SparseModel({"q1_dot": q1, "q2_dot": {"q1": 1.0}}, travel={"q2": D})


def test_features_equal_their_formulas():
    rng = np.random.default_rng(2)
    X = rng.uniform(-2 * D, 2 * D, (400, 2))
    X[:4, 1] = [D, -D, 0.0, D * (1 + 1e-12)]  # on the travel: not in contact; just beyond: in contact
    lib = Library(degree=2, extra_terms=("stop(q2)", "contact(q2)", "q1*contact(q2)", "stop(q2)^3"),
                  travel={"q2": D})
    A = lib.evaluate(X, rng.standard_normal((400, 1)))
    q1, q2 = X.T
    pen = np.sign(q2) * np.maximum(np.abs(q2) - D, 0.0)
    on = (np.abs(q2) > D).astype(float)
    for name, col in {"stop(q2)": pen, "contact(q2)": on, "q1*contact(q2)": q1 * on, "stop(q2)^3": pen**3}.items():
        np.testing.assert_allclose(A[:, lib.names.index(name)], col, rtol=1e-15, atol=0)
    assert list(A[:4, lib.names.index("contact(q2)")]) == [0, 0, 0, 1]


@pytest.mark.parametrize("term", ["stop(q2)", "q1*contact(q2)", "contact(q1)^2"])
def test_end_stop_terms_need_a_travel(term):
    with pytest.raises(ModelError, match="needs an end-stop travel"):
        FeatureSpace(("q1", "q2"), ("zdd",)).parse(term)
    with pytest.raises(ModelError, match="needs an end-stop travel"):
        SparseModel({"q1_dot": {term: 1.0}, "q2_dot": {"q1": 1.0}})
    with pytest.raises(ModelError, match="needs an end-stop travel"):
        Library(extra_terms=(term,), travel={"q1" if "q2" in term else "q2": D})


@pytest.mark.parametrize("travel,message", [({"q3": D}, "not a state"), ({"q2": -1e-3}, "positive and finite"),
                                            ({"q2": float("inf")}, "positive and finite"),
                                            ({"q2": "far"}, "not a number"), ([D], "must be an object")])
def test_bad_travel_is_refused(travel, message):
    with pytest.raises(ModelError, match=message):
        SparseModel({"q1_dot": {"q2": -1.0}, "q2_dot": {"q1": 1.0}}, travel=travel)


def test_model_json_round_trip_keeps_the_travel(tmp_path):
    model = bumper(0.25, {"q2": -971.0})
    d = model.to_dict()
    assert d["travel"] == {"q2": D} and d["model"]["q1_dot"]["q1*contact(q2)"] == pytest.approx(-0.5 * W)
    model.save(tmp_path / "m.json")
    back = SparseModel.load(tmp_path / "m.json")
    assert back.travel == {"q2": D} and back.equations == model.equations
    # a model without end stops writes exactly the JSON it always did
    plain = SparseModel({"q1_dot": TABLE1, "q2_dot": {"q1": 1.0}}).to_dict()
    assert "travel" not in plain and set(plain) == {"format", "states", "inputs", "model"}
    assert SparseModel.from_dict(json.loads(json.dumps(plain))).travel == {}


@pytest.mark.parametrize("zeta", [0.0, 0.25])
@pytest.mark.parametrize("offset", [0.5, 0.3])
def test_mass_pushed_into_the_stop_bounces_back(zeta, offset):
    """A free mass at 0.5 m/s into the bumper: penetration (v/w) exp(-zeta acos(zeta)/sqrt(1-zeta^2)),
    rebound speed e v with e = exp(-zeta pi/sqrt(1-zeta^2)) and contact time pi/(w sqrt(1-zeta^2)), exact
    for a linear damped contact. One RK4 step per output sample at the PLC's step h = 1/(2048 x 8); the
    contact starts `offset` of a step after a grid point. Without the cut at the crossing the rebound
    speed was 1.2-1.4 % off (the contact damping force jumps there); with it 8e-7."""
    v, fs = 0.5, 2048.0 * 8
    res = simulate(bumper(zeta), 1 / fs, [v, D - offset * v / fs], np.zeros(8 * 64), substeps=1)
    q1, q2 = res.states.T
    s = np.sqrt(1 - zeta**2)
    # the peak between output points: at most (w h / 2)^2 / 2 = 7e-4 below the true one
    assert q2.max() - D == pytest.approx(v / W * np.exp(-zeta * np.arccos(zeta) / s), rel=1e-3)
    assert q1[-1] == pytest.approx(-v * np.exp(-zeta * np.pi / s), rel=1e-5)  # free flight after the rebound
    assert np.count_nonzero(q2 > D) == pytest.approx(np.pi / (W * s) * fs, abs=1.0)  # contact time, steps


@pytest.mark.slow
def test_kernel_and_library_agree_through_repeated_contacts():
    """The Table 1 rig with stops, thrown at 1 m/s and shaken: the kernel (features in C) against DOP853
    on the library's right-hand side (features in numpy), over 0.5 s and 8 contacts."""
    fs, n, S = 2048.0, 1024, 8
    model = bumper(0.25, TABLE1)

    def u(t):
        return 20.0 * np.sin(2 * np.pi * 7.0 * t)

    t = np.arange(n) / fs
    ref = solve_ivp(lambda tt, x: model.rhs(x[None, :], [[u(tt)]])[0], (0, t[-1]), [1.0, 0.0], t_eval=t,
                    method="DOP853", rtol=1e-11, atol=1e-14)
    t_fine = np.arange((n - 1) * 2 * S + 1) / (2 * S * fs)
    res = simulate(model, 1 / fs, [1.0, 0.0], inputs_fine=u(t_fine)[:, None], substeps=S, n_samples=n)
    in_contact = np.abs(ref.y[1]) > D
    assert np.count_nonzero(np.diff(in_contact.astype(int)) == 1) >= 6
    # measured 6.3e-7 and 1.0e-5, fourth order (2, 4, 8, 16 substeps: 1.4e-4, 9.5e-6, 6.3e-7, 4.1e-8 of
    # the travel), because the kernel cuts its steps at each contact change (see the bounce test)
    assert np.max(np.abs(res.states[:, 1] - ref.y[1])) < 3e-6 * D
    assert np.max(np.abs(res.states[:, 0] - ref.y[0])) < 5e-5 * np.max(np.abs(ref.y[0]))
