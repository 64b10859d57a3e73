"""The estimator's options of `shakeid identify` / `shakeid batch`, derived from identify.params.PARAMS (one
declaration: name, type, default, range, help); the option names are the ones users already type."""
from __future__ import annotations

import argparse

from identify import params as spec

from .argtypes import _number


def _parser(p: spec.Param):
    """An argparse type that refuses a value outside p's range while the command line is parsed, naming it
    the way the estimator does (identify.params.problem)."""
    def parse(text: str):
        if p.kind == "terms":
            value = tuple(t.strip() for t in text.split(",") if t.strip())
        else:
            value = _number(p.kind, text)
            msg = spec.out_of_range(p, value, text)
            if msg:
                raise argparse.ArgumentTypeError(msg)
        msg = spec.problem(p, value)
        if msg:
            raise argparse.ArgumentTypeError(msg.replace(p.name, p.cli_flag, 1))
        return value
    parse.__name__ = {int: "integer", float: "number"}.get(p.kind, "value")
    return parse


def add_estimator_options(group) -> None:
    """One option per identify.params.PARAMS entry, with its default and range."""
    for p in spec.PARAMS:
        unit = f" ({p.unit})" if p.unit else ""
        if p.kind is bool:
            group.add_argument(p.cli_flag, dest=p.name, action="store_false" if p.negate_flag else "store_true",
                               help=p.help)
        elif p.choices:
            group.add_argument(p.cli_flag, dest=p.name, choices=p.choices, default=p.default, help=p.help)
        else:
            range_ = "" if p.kind == "terms" else f"; {p.range_text()}"
            group.add_argument(p.cli_flag, dest=p.name, type=_parser(p), default=p.default, metavar=p.metavar,
                               help=f"{p.help}{unit}{range_}")


def estimator_kwargs(args) -> dict:
    """SparseIdentifier keyword arguments from parsed options (every PARAMS entry, by its own name)."""
    return {p.name: getattr(args, p.name) for p in spec.PARAMS}
