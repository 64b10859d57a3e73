"""Named candidate terms: products of small integer powers of *features*.

A feature is a state `q1`, its magnitude `|q1|`, its sign `sign(q1)`, an input (`zdd`, `u`), or, for a
state with an end-stop travel d (m), its penetration `stop(q2)` = sign(q2) max(|q2| - d, 0) (m) and
contact indicator `contact(q2)` = 1 while |q2| > d, else 0. Every library term the product knows
(monomials, Coulomb friction `sign(q1)`, quadratic damping `q1*|q1|`, end-stop spring `stop(q2)` and
damping `q1*contact(q2)`, ...) is such a product, so one representation serves the library matrix, the
model JSON and the compiled simulation kernel alike.

Canonical names: factors joined by `*`, a power as `^p`, the constant as `1`, factors in feature order:
`q1^2*q2`, `q1*q2^2`, `q1*|q1|`, `sign(q1)`, `zdd`, `q1*contact(q2)`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from itertools import combinations_with_replacement

from ..errors import ModelError

_FACTOR = re.compile(r"^(?P<base>\|[A-Za-z_]\w*\||(?:sign|stop|contact)\([A-Za-z_]\w*\)|[A-Za-z_]\w*)"
                     r"(?:\^(?P<pow>\d+))?$")
_STOP = re.compile(r"^(?:stop|contact)\((?P<state>[A-Za-z_]\w*)\)$")
#: A feature's kind, in the feature order's pattern: per state q, |q|, sign(q); inputs; per state stop(q),
#: contact(q) (FeatureSpace.describe).
FEATURE_KINDS = ("value", "abs", "sign", "input", "stop", "contact")


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

    Feature order (also the compiled kernel's): for each state i: q_i, |q_i|, sign(q_i); then the
    inputs; then for each state i: stop(q_i), contact(q_i). `travel` {state: d in m, > 0} sets the
    end stops; stop/contact features of a state without one are refused by `parse`.
    """

    def __init__(self, states: tuple[str, ...], inputs: tuple[str, ...], travel: dict | None = None):
        self.states = tuple(states)
        self.inputs = tuple(inputs)
        self.travel = check_travel(travel, self.states)
        names: list[str] = []
        for s in self.states:
            names += [s, f"|{s}|", f"sign({s})"]
        names += list(self.inputs)
        usable = list(names)  # the features a term may use: stop/contact only where a travel is set
        for s in self.states:
            names += [f"stop({s})", f"contact({s})"]
            usable += names[-2:] if s in self.travel else []
        self.index = {n: i for i, n in enumerate(names)}
        if len(self.index) != len(names):
            raise ModelError(f"state and input names must be distinct: {states} {inputs}")
        self.names = tuple(usable)

    def parse(self, name: str) -> Term:
        """Parse a term name (`q1*q2^2`, `sign(q1)`, `1`) into a Term in canonical order."""
        text = name.replace(" ", "")
        if text in ("1", ""):
            return Term(())
        powers: dict[str, int] = {}
        for part in text.split("*"):
            m = _FACTOR.match(part)
            stop = _STOP.match(m.group("base")) if m else None
            state = stop.group("state") if stop else None
            if state in self.states and state not in self.travel:
                raise ModelError(f"term {name!r}: {m.group('base')} needs an end-stop travel for {state} "
                                 f"(model JSON: \"travel\": {{\"{state}\": <metres>}})")
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

    def describe(self, name: str) -> tuple[str, str]:
        """(kind, signal) of a feature, decoded from its place in the feature order: kind is one of
        FEATURE_KINDS (`q2` -> ("value", "q2"), `|q1|` -> ("abs", "q1"), `zdd` -> ("input", "zdd"),
        `stop(q2)` -> ("stop", "q2")); what a code generator renders a factor from (identify.export)."""
        idx, ns, ni = self.index[name], len(self.states), len(self.inputs)
        if idx < 3 * ns:
            return FEATURE_KINDS[idx % 3], self.states[idx // 3]
        if idx < 3 * ns + ni:
            return "input", self.inputs[idx - 3 * ns]
        i, kind = divmod(idx - 3 * ns - ni, 2)
        return FEATURE_KINDS[4 + kind], self.states[i]

    def encode(self, terms: list[Term]) -> tuple[list[int], list[int], list[int]]:
        """Flatten terms for the compiled kernel: (term_ptr, factor feature index, factor power)."""
        ptr, feat, powr = [0], [], []
        for t in terms:
            for f, p in t.factors:
                feat.append(self.index[f])
                powr.append(p)
            ptr.append(len(feat))
        return ptr, feat, powr


def check_travel(travel, states) -> dict[str, float]:
    """{state: end-stop travel in m}: states known, values finite and positive; None = no stops."""
    out: dict[str, float] = {}
    for state, d in (travel or {}).items():
        if state not in states:
            raise ModelError(f"end-stop travel for {state!r}, which is not a state ({', '.join(states)})")
        try:
            d = float(d)
        except (TypeError, ValueError):
            raise ModelError(f"end-stop travel for {state}: {d!r} is not a number") from None
        if not 0 < d < float("inf"):
            raise ModelError(f"end-stop travel for {state} must be positive and finite, got {d!r} m")
        out[state] = d
    return out
