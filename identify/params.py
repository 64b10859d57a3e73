"""The user-settable parameters of SparseIdentifier, declared once (as scikit-learn's `_parameter_constraints`).

Each Param gives name, type, default, range or choices, unit and help. From this one list are derived:
the estimator's checks (SparseIdentifier refuses a value out of range before any work, `check`), the
`shakeid identify/batch` options (shakeid.cli builds its argparse options from PARAMS), the HTTP request
body (server.schemas.IdentifyIn is built from PARAMS) and the table in docs/identification.md
(`markdown_table`; tests/identify/test_params.py checks the docs hold what it generates).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import IdentificationError
from .trust.uncertainty import N_PLACEMENTS, N_REPLICATES


@dataclass(frozen=True)
class Param:
    """One parameter. kind: int, float, bool, str (with choices) or "terms" (a list of term names).
    low/high: inclusive bounds unless low_open/high_open; nullable: None is allowed (its meaning in help).
    flag: the CLI option (default --name-with-dashes); negate_flag: a store_true flag setting it False."""
    name: str
    kind: object
    default: object
    help: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple | None = None
    nullable: bool = False
    flag: str | None = None
    metavar: str | None = None
    negate_flag: bool = False
    max_items: int | None = None

    @property
    def cli_flag(self) -> str:
        return self.flag or "--" + self.name.replace("_", "-")

    def range_text(self) -> str:
        """The admissible values in words, as the error messages and the docs table print them."""
        if self.choices:
            return ", ".join(str(c) for c in self.choices)
        if self.kind is bool:
            return "true, false"
        if self.kind == "terms":
            return f"up to {self.max_items} term names"
        if self.low is None and self.high is None:
            return "any"
        lo = "" if self.low is None else ("(" if self.low_open else "[") + _num(self.low)
        hi = "inf)" if self.high is None else _num(self.high) + (")" if self.high_open else "]")
        return f"{lo or '(-inf'}, {hi}"


def _num(x) -> str:
    return str(int(x)) if float(x).is_integer() else repr(x)


PARAMS: tuple[Param, ...] = (
    Param("degree", int, 4, "highest monomial degree of the library", low=1, high=8, metavar="N"),
    Param("extra_terms", "terms", (), "extra library terms, e.g. sign(q1), q1*|q1| (CLI: comma-separated)",
          max_items=20, metavar="TERMS"),
    Param("method", str, "admm", "admm: LASSO solved by ADMM along a lambda path (the paper); stlsq: "
          "sequentially thresholded least squares", choices=("admm", "stlsq")),
    Param("n_lambdas", int, 100, "number of points on the lambda path", low=2, high=1000, flag="--lambdas",
          metavar="N"),
    Param("threshold", float, None, "STLSQ: a single threshold on the coefficients (normalised unless "
          "normalize_threshold is false) instead of a path (none: a path)", low=0, nullable=True,
          metavar="T"),
    Param("normalize_threshold", bool, True, "STLSQ: threshold the coefficients of unit-RMS columns (true) or the raw "
          "coefficients, as the paper's Table 2 with lambda = 0.95 (false; CLI --raw-threshold)",
          flag="--raw-threshold", negate_flag=True),
    Param("selection", str, "heldout", "how a model is chosen on the path: held-out error of the refit "
          "(heldout), the paper's relative-MSE tolerance (paper), or the Bayesian information criterion (bic)",
          choices=("heldout", "paper", "bic")),
    Param("tolerance", float, None, "selection tolerance, relative MSE (none: 0.25 for paper, 0.003 for "
          "heldout)", low=0, high=10, low_open=True, nullable=True, metavar="TOL"),
    Param("max_terms", int, None, "at most this many terms per equation (none: no limit)", low=1, high=100,
          nullable=True, metavar="K"),
    Param("budget", str, "equation-error", "how max_terms chooses q1_dot's terms: by one-step acceleration "
          "error or by the free-run error of refit candidates on the data (slower; implies the refit)",
          choices=("equation-error", "free-run")),
    Param("budget_refit", str, "fit", "budget free-run: refit the chosen terms on the fit rows or on all rows, "
          "held-out ones included (validation figures are then not out-of-sample)", choices=("fit", "all")),
    Param("refine", str, None, "refit the kept coefficients on the free-run simulation error (none: no "
          "refinement)", choices=("free-run",), nullable=True),
    Param("holdout_fraction", float, 0.2, "share of samples held out in interleaved blocks when "
          "holdout_samples is not given", low=0, high=0.9, high_open=True, metavar="F"),
    Param("holdout_samples", int, None, "hold out the first N samples instead, as the paper (30000)",
          "samples", low=1, nullable=True, metavar="N"),
    Param("bias_method", str, "auto", "how the measurement chain's bias is estimated: auto (closed form when "
          "every kept term is a monomial, SIMEX otherwise) or simex (always SIMEX)", choices=("auto", "simex")),
    Param("bias_replicates", int, N_REPLICATES, "SIMEX replicates where SIMEX runs; 0: no chain-bias correction (none: "
          "by the record's length, 64 up to 250 000 samples, 16 from 1 000 000)", low=0, high=200,
          nullable=True, metavar="N"),
    Param("placements", int, N_PLACEMENTS, "random held-out placements for the inclusion probabilities (0: none, "
          "faster; the model is the same)", low=0, high=500, metavar="N"),
    Param("mass_kg", float, None, "moving mass for the physical parameters (none: the recording's, which a "
          "sweep takes from its rig configuration, else 0.49, the paper's rig, said to be assumed)", "kg",
          low=0, low_open=True, nullable=True, metavar="KG"),
)

BY_NAME = {p.name: p for p in PARAMS}


def problem(p: Param, value) -> str | None:
    """What is wrong with value for p, in the operator's words; None when it is admissible."""
    if value is None:
        return None if p.nullable else f"{p.name} must be given"
    if p.kind == "terms":
        if isinstance(value, str) or not all(isinstance(t, str) for t in value):
            return f"{p.name} must be a list of term names"
        return f"{p.name}: at most {p.max_items} terms, got {len(value)}" if len(value) > p.max_items else None
    if p.kind is bool:
        return None if isinstance(value, (bool, np.bool_)) else f"{p.name} must be true or false"
    if p.choices:
        return None if value in p.choices else f"unknown {p.name} {value!r} ({', '.join(p.choices)})"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (p.kind is int and value != int(value)):
        return f"{p.name} must be {'an integer' if p.kind is int else 'a number'}, got {value!r}"
    if not math.isfinite(value):
        return f"{p.name} must be finite, got {value}"
    msg = out_of_range(p, value)
    return f"{p.name} {msg}" if msg else None


def out_of_range(p: Param, value, shown: str | None = None) -> str | None:
    """"must be 1..8, got 0" (the CLI's words, shown: the value as typed) when value is outside p's bounds."""
    below = p.low is not None and (value <= p.low if p.low_open else value < p.low)
    above = p.high is not None and (value >= p.high if p.high_open else value > p.high)
    if not (below or above):
        return None
    if p.kind is int and p.high is not None:
        rule = f"{_num(p.low)}..{_num(p.high)}"
    elif p.high is None:
        rule = (">" if p.low_open else ">=") + f" {_num(p.low)}"
    else:
        rule = f"in {p.range_text()}"
    return f"must be {rule}, got {value if shown is None else shown}"


def check(values: dict) -> None:
    """Refuse the first inadmissible value among values (name -> value), IdentificationError naming it."""
    for name, value in values.items():
        msg = problem(BY_NAME[name], value)
        if msg:
            raise IdentificationError(msg)


def markdown_table() -> str:
    """The parameter table of docs/identification.md (between its `params table` markers)."""
    rows = ["| parameter | CLI option | type | default | range | unit | meaning |", "|---|---|---|---|---|---|---|"]
    for p in PARAMS:
        kind = "list of str" if p.kind == "terms" else p.kind.__name__
        default = "none" if p.default is None else ("[]" if p.default == () else str(p.default).lower()
                                                    if p.kind is bool else str(p.default))
        rows.append(f"| `{p.name}` | `{p.cli_flag}` | {kind} | {default} | {p.range_text()} | {p.unit or '-'} "
                    f"| {p.help.replace('|', '&#124;')} |")
    return "\n".join(rows)
