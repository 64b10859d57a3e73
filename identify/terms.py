"""Named candidate terms: products of small integer powers of *features*.

A feature is a state `q1`, its magnitude `|q1|`, its sign `sign(q1)`, or an input (`zdd`, `u`).
Every library term the product knows (monomials, Coulomb friction `sign(q1)`, quadratic damping
`q1*|q1|`, ...) is such a product, so one representation serves the library matrix, the model JSON and
the compiled simulation kernel alike.

Canonical names: factors joined by `*`, a power as `^p`, the constant as `1`. Monomials list states in
order (`q1^2*q2`), then magnitudes, signs and inputs: `q1*q2^2`, `q1*|q1|`, `sign(q1)`, `zdd`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from itertools import combinations_with_replacement

from .errors import ModelError

_FACTOR = re.compile(r"^(?P<base>\|[A-Za-z_]\w*\||sign\([A-Za-z_]\w*\)|[A-Za-z_]\w*)(?:\^(?P<pow>\d+))?$")


@dataclass(frozen=True)
class Term:
    """One candidate term: `factors` is a tuple of (feature name, power >= 1) in canonical order."""

    factors: tuple[tuple[str, int], ...]

    @property
    def name(self) -> str:
        if not self.factors:
            return "1"
        return "*".join(f if p == 1 else f"{f}^{p}" for f, p in self.factors)

    @property
    def degree(self) -> int:
        return sum(p for _, p in self.factors)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.name


class FeatureSpace:
    """The features of a system with the given state and input names.

    Feature order (also the compiled kernel's): for each state i: q_i, |q_i|, sign(q_i); then inputs.
    """

    def __init__(self, states: tuple[str, ...], inputs: tuple[str, ...]):
        self.states = tuple(states)
        self.inputs = tuple(inputs)
        names: list[str] = []
        for s in self.states:
            names += [s, f"|{s}|", f"sign({s})"]
        names += list(self.inputs)
        self.names = tuple(names)
        self.index = {n: i for i, n in enumerate(names)}
        if len(self.index) != len(names):
            raise ModelError(f"state and input names must be distinct: {states} {inputs}")

    def parse(self, name: str) -> Term:
        """Parse a term name (`q1*q2^2`, `sign(q1)`, `1`) into a Term in canonical order."""
        text = name.replace(" ", "")
        if text in ("1", ""):
            return Term(())
        powers: dict[str, int] = {}
        for part in text.split("*"):
            m = _FACTOR.match(part)
            if not m or m.group("base") not in self.index:
                raise ModelError(f"unknown term {name!r}: factor {part!r} is not one of {', '.join(self.names)}")
            p = int(m.group("pow") or 1)
            if p < 1:
                raise ModelError(f"term {name!r}: powers must be >= 1")
            powers[m.group("base")] = powers.get(m.group("base"), 0) + p
        return Term(tuple(sorted(powers.items(), key=lambda fp: self.index[fp[0]])))

    def monomials(self, degree: int) -> list[Term]:
        """Constant and all monomials of the states up to `degree`, in the paper's order."""
        out = [Term(())]
        for d in range(1, degree + 1):
            for combo in combinations_with_replacement(self.states, d):
                counts: dict[str, int] = {}
                for s in combo:
                    counts[s] = counts.get(s, 0) + 1
                out.append(Term(tuple(sorted(counts.items(), key=lambda fp: self.index[fp[0]]))))
        return out

    def encode(self, terms: list[Term]) -> tuple[list[int], list[int], list[int]]:
        """Flatten terms for the compiled kernel: (term_ptr, factor feature index, factor power)."""
        ptr, feat, powr = [0], [], []
        for t in terms:
            for f, p in t.factors:
                feat.append(self.index[f])
                powr.append(p)
            ptr.append(len(feat))
        return ptr, feat, powr
