"""A sparse ODE model: for each state q_i, dq_i/dt as a sum of coefficient x named term.

This is the product's model type: identification returns it, `sim/` runs the rig physics with it,
JSON carries it between them. Equation names are the state name plus `_dot` (`q1_dot`, `q2_dot`).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .errors import ModelError
from .regression.library import evaluate_terms
from .regression.terms import FeatureSpace

MODEL_FORMAT = "shakeid.model/1"


class SparseModel:
    """dq/dt = Xi^T theta(q, u), stored term by term.

    Parameters
    ----------
    equations : {"q1_dot": {"q1": -3.73, "q2^3": -2.5e6, "zdd": -1.02, ...}, "q2_dot": {"q1": 1.0}}
        Nonzero coefficients only, in SI units of the states (q1 in m/s, q2 in m, zdd in m/s^2).
    states, inputs : signal names; default the base-excited rig (q1 = relative velocity,
        q2 = relative displacement, zdd = table acceleration).
    standard_errors : optional, same shape as `equations`.
    travel : {state: end-stop travel in m} for the terms `stop(q2)`, `q1*contact(q2)` (identify.regression.terms);
        JSON "travel", written only when set, so models without end stops keep their JSON.
    """

    def __init__(self, equations: dict, states=("q1", "q2"), inputs=("zdd",), standard_errors=None,
                 travel=None):
        self.states = tuple(states)
        self.inputs = tuple(inputs)
        if travel is not None and not isinstance(travel, dict):
            raise ModelError(f"model 'travel' must be an object {{state: metres}}, got {travel!r}")
        self.space = FeatureSpace(self.states, self.inputs, travel)
        self.travel = dict(self.space.travel)
        expected = [f"{s}_dot" for s in self.states]
        unknown = set(equations) - set(expected)
        if unknown:
            raise ModelError(f"model has equations {sorted(unknown)}; expected {expected}")
        self.equations = {eq: {self.space.parse(t).name: float(c) for t, c in equations.get(eq, {}).items()
                               if float(c) != 0.0} for eq in expected}
        for eq, terms in self.equations.items():
            bad = [t for t, c in terms.items() if not np.isfinite(c)]
            if bad:
                raise ModelError(f"model equation {eq}: non-finite coefficient for {bad}")
        self.standard_errors = standard_errors
        names: list[str] = []
        for terms in self.equations.values():
            names += [t for t in terms if t not in names]
        self.term_names = names
        self.terms = [self.space.parse(n) for n in names]
        self.coef_ = np.array([[self.equations[eq].get(n, 0.0) for n in names] for eq in expected]).reshape(
            len(expected), len(names))
        self._kernel_terms: tuple | None = None

    def kernel_terms(self) -> tuple[bytes, bytes, bytes, bytes]:
        """The terms as the compiled kernel reads them (identify/_simkernel_run.h: term pointers, features and
        powers as int32 bytes) and the travels (float64 bytes): packed once per model, not per call (a
        shooting refit calls the kernel and the read-out thousands of times in one explanation)."""
        if self._kernel_terms is None:
            ptr, feat, powr = self.space.encode(self.terms)
            self._kernel_terms = tuple(np.asarray(a, dtype=np.int32).tobytes() for a in (ptr, feat, powr)) + (
                np.array([self.travel.get(s, np.inf) for s in self.states]).tobytes(),)
        return self._kernel_terms

    # -- evaluation -------------------------------------------------------------------------------
    def rhs(self, states: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """dq/dt at samples: states (n, n_states), inputs (n, n_inputs) -> (n, n_states)."""
        if not self.terms:
            return np.zeros_like(np.asarray(states, dtype=float))
        theta = evaluate_terms(self.space, self.terms, states, inputs)
        return theta @ self.coef_.T

    def coefficient(self, equation: str, term: str) -> float:
        return self.equations[equation].get(self.space.parse(term).name, 0.0)

    @property
    def n_terms(self) -> int:
        return sum(len(t) for t in self.equations.values())

    # -- JSON -------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = {"format": MODEL_FORMAT, "states": list(self.states), "inputs": list(self.inputs),
             "model": {eq: dict(terms) for eq, terms in self.equations.items()}}
        if self.travel:
            d["travel"] = dict(self.travel)
        if self.standard_errors is not None:
            d["standard_errors"] = self.standard_errors
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SparseModel":
        if not isinstance(d, dict) or "model" not in d:
            raise ModelError("model JSON needs a 'model' object: {\"model\": {\"q1_dot\": {...}, ...}}")
        return cls(d["model"], states=tuple(d.get("states", ("q1", "q2"))),
                   inputs=tuple(d.get("inputs", ("zdd",))), standard_errors=d.get("standard_errors"),
                   travel=d.get("travel"))

    def save(self, path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2))

    @classmethod
    def load(cls, path) -> "SparseModel":
        return cls.from_dict(read_document(path))

    def __repr__(self) -> str:
        eqs = "; ".join(f"{eq} = " + " + ".join(f"{c:.5g}*{t}" for t, c in terms.items())
                        for eq, terms in self.equations.items())
        stops = f"; travel {self.travel}" if self.travel else ""
        return f"SparseModel({eqs}{stops})"


def read_document(path) -> dict:
    """A model file's JSON (SparseModel.save's, or a whole identify result with its status); ModelError
    naming the file when it cannot be read."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"cannot read model {path}: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"{path}: not a model file: a model is the JSON `shakeid identify --json` prints or a "
                         f"report's model.json (this is not JSON: {exc.msg} at line {exc.lineno}, column "
                         f"{exc.colno})") from None
    if not isinstance(doc, dict):
        raise ModelError(f"{path}: not a model file: JSON {type(doc).__name__}, not an object with a 'model'")
    return doc
