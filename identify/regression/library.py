"""The library of candidate terms (the paper's matrix A(q, zdd), eq. 7)."""
from __future__ import annotations

import numpy as np

from ..errors import ModelError
from .terms import FeatureSpace, Term

#: Non-polynomial terms of physical effects the library can add on request.
PHYSICAL_TERMS = ("sign(q1)", "q1*|q1|", "|q1|", "|q2|")


class Library:
    """Named candidate terms: constant, state monomials up to `degree`, extra terms, then the inputs.

    Parameters
    ----------
    states, inputs : names of the state and input signals (default: q1 = relative velocity,
        q2 = relative displacement, zdd = table acceleration).
    degree : highest total degree of the state monomials (the paper uses 4: 16 columns with zdd).
    extra_terms : further term names, e.g. ``("sign(q1)", "q1*|q1|")`` for friction effects, or
        ``("stop(q2)", "q1*contact(q2)")`` for end stops (which need `travel`).
    travel : {state: end-stop travel in m} for the stop/contact features, e.g. ``{"q2": 0.0175}``.
    """

    def __init__(self, states=("q1", "q2"), inputs=("zdd",), degree: int = 4, extra_terms=(), travel=None):
        self.states = tuple(states)
        self.inputs = tuple(inputs)
        self.degree = int(degree)
        self.extra_terms = tuple(extra_terms)
        if not 1 <= self.degree <= 8:
            raise ModelError(f"library degree must be 1..8, got {degree}")
        self.space = FeatureSpace(self.states, self.inputs, travel)
        terms = self.space.monomials(self.degree)
        terms += [self.space.parse(n) for n in self.extra_terms]
        terms += [self.space.parse(n) for n in self.inputs]
        names = [t.name for t in terms]
        dupes = {n for n in names if names.count(n) > 1}
        if dupes:
            raise ModelError(f"library has duplicate terms: {sorted(dupes)}")
        self.terms: list[Term] = terms
        self.names: list[str] = names

    @classmethod
    def from_terms(cls, names, states=("q1", "q2"), inputs=("zdd",), travel=None) -> "Library":
        """A library of exactly these terms (canonical names, duplicates removed, order kept)."""
        lib = cls.__new__(cls)
        lib.states, lib.inputs, lib.degree, lib.extra_terms = tuple(states), tuple(inputs), None, ()
        lib.space = FeatureSpace(lib.states, lib.inputs, travel)
        terms: list[Term] = []
        for n in names:
            t = lib.space.parse(n)
            if t not in terms:
                terms.append(t)
        lib.terms, lib.names = terms, [t.name for t in terms]
        return lib

    def subset(self, columns) -> "Library":
        """The library of these columns (indices) only, in the same feature space: what a refit of
        kept terms needs (identify.trust.uncertainty's SIMEX replicates)."""
        lib = Library.__new__(Library)
        lib.states, lib.inputs, lib.degree, lib.extra_terms, lib.space = (self.states, self.inputs, None, (),
                                                                         self.space)
        lib.terms = [self.terms[j] for j in columns]
        lib.names = [t.name for t in lib.terms]
        return lib

    def __len__(self) -> int:
        return len(self.terms)

    def evaluate(self, states: np.ndarray, inputs: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Library matrix (n_samples, n_terms) for states (n, n_states) and inputs (n, n_inputs).

        Each column is its parent column (one factor power lower) times one feature: one multiply
        per column. `out` may be any (n, n_terms) view; a Fortran-ordered one is fastest.
        """
        return evaluate_terms(self.space, self.terms, states, inputs, out)


def evaluate_terms(space: FeatureSpace, terms, states, inputs, out=None) -> np.ndarray:
    """states: (n, n_states) array or a sequence of 1-D columns (contiguous columns are faster)."""
    if isinstance(states, np.ndarray):
        states = states.T if states.ndim == 2 else states[None, :]
    cols = [np.asarray(c, dtype=float) for c in states]
    inputs = np.asarray(inputs, dtype=float)
    n = cols[0].shape[0]
    if out is None:
        out = np.empty((n, len(terms)), order="F")
    feats: dict[str, np.ndarray] = {}

    def feature(name: str) -> np.ndarray:
        if name not in feats:
            idx = space.index[name]
            ns, ni = len(space.states), len(space.inputs)
            if idx < 3 * ns:
                q = cols[idx // 3]
                feats[name] = (q, np.abs(q), np.sign(q))[idx % 3]
            elif idx < 3 * ns + ni:
                feats[name] = inputs[:, idx - 3 * ns]
            else:  # stop(q) = sign(q) max(|q| - d, 0), contact(q) = [|q| > d]
                i, kind = divmod(idx - 3 * ns - ni, 2)
                q = cols[i]
                pen = np.abs(q) - space.travel[space.states[i]]
                feats[name] = np.where(pen > 0, np.copysign(pen, q), 0.0) if kind == 0 else (pen > 0) * 1.0
        return feats[name]

    done: dict[tuple, np.ndarray] = {}
    for j, term in enumerate(terms):
        col = out[:, j]
        if not term.factors:
            col[:] = 1.0
        else:
            # parent: the same term with the last factor's power lowered by one
            f, p = term.factors[-1]
            parent = term.factors[:-1] + (((f, p - 1),) if p > 1 else ())
            if parent in done:
                np.multiply(done[parent], feature(f), out=col)
            elif not parent:
                col[:] = feature(f)
            else:
                col[:] = evaluate_terms(space, [Term(parent)], cols, inputs)[:, 0] * feature(f)
        done[term.factors] = col
    return out
