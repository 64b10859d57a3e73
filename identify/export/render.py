"""One renderer of a term in four syntaxes (C, numpy, LaTeX, identifier), driven by the term's structure.

A term is a product of powers of features (identify.regression.terms); a feature's kind and signal come from
FeatureSpace.describe, the same feature order the library matrix and the compiled kernel use. So each
syntax knows only how to write the six feature kinds, a power and a product: a new term needs nothing
here, and no table of term names exists to drift from the library.
"""
from __future__ import annotations

import keyword
import re

from ..errors import ModelError
from ..regression.terms import FEATURE_KINDS, FeatureSpace, Term

#: Significant digits of the coefficients in the LaTeX equations (as reports.text.model_text prints them);
#: C and Python carry every coefficient exactly (repr, 17 digits).
LATEX_DIGITS = 5

_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if inline int long "
    "register restrict return short signed sizeof static struct switch typedef union unsigned void volatile while "
    "fabs copysign".split())
#: names the Python module uses beside the signals (rhs's q; simulate's dt, q0, substeps; its module names)
_PY_RESERVED = frozenset("np rhs simulate q dt q0 substeps COEFFICIENTS TRAVEL STATES INPUTS".split())


class Syntax:
    """How one language writes a feature of each kind, a power, a product and the constant term."""

    name = ""
    one = "1"

    def feature(self, kind: str, signal: str) -> str:
        raise NotImplementedError

    def power(self, base: str, p: int) -> str:
        raise NotImplementedError

    def product(self, parts: list[str]) -> str:
        return " * ".join(parts)

    def term(self, space: FeatureSpace, term: Term) -> str:
        """The term as an expression of this syntax."""
        if not term.factors:
            return self.one
        parts = []
        for feature, p in term.factors:
            kind, signal = space.describe(feature)
            assert kind in FEATURE_KINDS
            base = self.feature(kind, signal)
            parts.append(base if p == 1 else self.power(base, p))
        return self.product(parts)


class CSyntax(Syntax):
    """C99 with <math.h>: signals are local doubles named as the model's signals; a power is repeated
    products (as the compiled kernel evaluates it); end stops use shakeid_stop and the travel constants."""

    name = "C"
    one = "1.0"

    def feature(self, kind, signal):
        return {"value": signal, "abs": f"fabs({signal})", "sign": f"(double)(({signal} > 0.0) - ({signal} < 0.0))",
                "input": signal, "stop": f"shakeid_stop({signal}, SHAKEID_TRAVEL_{signal})",
                "contact": f"(fabs({signal}) > SHAKEID_TRAVEL_{signal} ? 1.0 : 0.0)"}[kind]

    def power(self, base, p):
        return "(" + " * ".join([base] * p) + ")"


class NumpySyntax(Syntax):
    """numpy on arrays of any shape: signals are arrays named as the model's signals."""

    name = "Python"
    one = "1.0"

    def feature(self, kind, signal):
        return {"value": signal, "abs": f"np.abs({signal})", "sign": f"np.sign({signal})", "input": signal,
                "stop": f"_stop({signal}, TRAVEL[{signal!r}])",
                "contact": f"(np.abs({signal}) > TRAVEL[{signal!r}]) * 1.0"}[kind]

    def power(self, base, p):
        return f"{base}**{p}"


class LatexSyntax(Syntax):
    """The paper's notation: q_{1}, \\ddot{z}, powers as superscripts, factors side by side."""

    name = "LaTeX"

    def feature(self, kind, signal):
        s = latex_symbol(signal)
        return {"value": s, "abs": rf"\lvert {s} \rvert", "sign": rf"\operatorname{{sign}}({s})", "input": s,
                "stop": rf"\operatorname{{stop}}({s})", "contact": rf"\operatorname{{contact}}({s})"}[kind]

    def power(self, base, p):
        return f"{base}^{{{p}}}"

    def product(self, parts):
        return " ".join(parts)


class IdentifierSyntax(Syntax):
    """A term as an identifier (letters, digits, `_`): the FMU's parameter names, e.g. q1_q2p2."""

    name = "identifier"
    one = "one"

    def feature(self, kind, signal):
        return signal if kind in ("value", "input") else f"{kind}_{signal}"

    def power(self, base, p):
        return f"{base}p{p}"

    def product(self, parts):
        return "_".join(parts)


C, NUMPY, LATEX, IDENTIFIER = CSyntax(), NumpySyntax(), LatexSyntax(), IdentifierSyntax()


def latex_symbol(signal: str) -> str:
    """q1 -> q_{1}; zdd -> \\ddot{z} (a one-letter name with d/dd: its time derivatives, as the paper
    writes the table acceleration); u -> u; longer names upright, underscores escaped."""
    m = re.fullmatch(r"([A-Za-z])(d{1,2})", signal)
    if m:
        return rf"\{'d' * len(m.group(2))}ot{{{m.group(1)}}}"
    m = re.fullmatch(r"([A-Za-z])_?(\d+)", signal)
    if m:
        return f"{m.group(1)}_{{{m.group(2)}}}"
    return signal if len(signal) == 1 else r"\mathrm{" + signal.replace("_", r"\_") + "}"


def latex_derivative(equation: str) -> str:
    """q1_dot -> \\dot{q}_{1}: the left side of an equation, as the paper writes it."""
    state = equation[:-len("_dot")]
    m = re.fullmatch(r"([A-Za-z])_?(\d+)", state)
    return rf"\dot{{{m.group(1)}}}_{{{m.group(2)}}}" if m else rf"\dot{{{latex_symbol(state)}}}"


def latex_number(value: float, digits: int = LATEX_DIGITS) -> str:
    """1.162e4 -> 1.162 \\times 10^{4}; -3.7294 -> -3.7294: written out from 1e-3 to below 1e4, as the paper's
    tables, else as a power of ten."""
    mant, exp = f"{value:.{digits - 1}e}".split("e")
    if value == 0 or -3 <= int(exp) < 4:
        return f"{value:.{digits}g}"
    mant = mant.rstrip("0").rstrip(".")
    return rf"{mant} \times 10^{{{int(exp)}}}"


def check_names(space: FeatureSpace, reserved=_C_KEYWORDS | _PY_RESERVED) -> None:
    """Signal names become C and Python variables: refuse ones that are keywords or the generated code's own."""
    bad = [n for n in space.states + space.inputs
           if n in reserved or keyword.iskeyword(n) or n.startswith("shakeid_") or n.startswith("_")]
    if bad:
        raise ModelError(f"signal name(s) {', '.join(bad)} cannot be exported as code variables (C keywords or the "
                         f"generated code's own names); rename them in the model JSON")
