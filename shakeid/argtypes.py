"""Option types that refuse an impossible value while the command line is parsed, naming the option:
`shakeid: error: argument --mass-kg: must be > 0, got 0` rather than a traceback or a message from deep
inside a calculation that names no option (a zero mass divided by, a negative sample rate's array)."""
from __future__ import annotations

import argparse
import math
import os
import re

from identify.errors import ShakeidError

#: FILE[START:STOP], the notation a cut recording's source is printed in (Recording.slice)
_RANGE = re.compile(r"^(?P<path>.+)\[(?P<start>\d+):(?P<stop>\d+)\]$")


def _number(kind, text: str):
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, "
                                         f"got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def positive(text: str) -> float:
    """A number > 0 (a mass, a sample rate, a duration)."""
    value = _number(float, text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def non_negative(text: str) -> float:
    """A number >= 0 (an amplitude, a noise level)."""
    value = _number(float, text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def int_in(low: int, high: int | None = None):
    """An integer in [low, high] (high None: no upper bound), e.g. a library degree 1..8."""
    def parse(text: str) -> int:
        value = _number(int, text)
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {low}..{high}, got {text}" if high is not None
                                             else f"must be >= {low}, got {text}")
        return value
    parse.__name__ = "integer"  # argparse names the type in its own messages
    return parse


def file_and_samples(name: str, samples) -> tuple[str, tuple[int, int] | None]:
    """A FILE argument and --samples -> (path, (start, stop) or None). FILE[START:STOP] cuts that file
    alone to samples [START, STOP) (0-based): how each recording of a joint fit gets its own range
    (`shakeid identify A.mat[40650:105712] B.mat`), where --samples cuts every file alike. A file whose
    own name ends in brackets is read as named."""
    m = _RANGE.match(name)
    if m is None or os.path.exists(name):
        return name, (tuple(samples) if samples else None)
    if samples:
        raise ShakeidError(f"{name}: samples given twice, in the file name and with --samples; give one")
    start, stop = int(m["start"]), int(m["stop"])
    if stop <= start:
        raise ShakeidError(f"{name}: empty sample range [{start}, {stop}): STOP must exceed START")
    return m["path"], (start, stop)
