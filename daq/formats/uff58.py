"""Universal File Format type 58 (ASCII and binary 58b) through pyuff: Siemens Testlab, ME'scope and most
modal software exchange time histories this way. A channel is a dataset, named by its id1 line, in any
order; the clock is the abscissa (even: minimum and increment; uneven: the stamps), the unit the ordinate's
units label.

UFF prints the abscissa increment as E13.5, six significant digits: 1/2048 s is stored as 4.88281e-04, a
sample rate of 2048.00105 Hz (5.1e-7 high). The clock carries that resolution, so a --fs within it gives
the exact rate, and without --fs the recording's warnings say so (docs/recordings.md: the effect on a model).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from identify.data.channels import Channel, NotASignal, SampleClock, clock_from_time
from identify.errors import RecordingError

from . import FileFormat

#: The line that closes every UFF dataset ("%6i" % -1): a file not ending with it was cut short.
DATASET_END = b"    -1"
#: Significant digits of UFF's E13.5 header numbers (abscissa minimum and increment).
E13_5_DIGITS = 6
#: UFF function types (record 6, field 1) that are time histories: 0 general, 1 time response.
TIME_FUNCTION_TYPES = (0, 1)
TAIL_BYTES = 64


def e13_5_resolution(x: float) -> float:
    """The relative uncertainty of a positive number printed as E13.5: half a unit of its sixth digit."""
    mantissa = x / 10.0 ** math.floor(math.log10(x))
    return 0.5 * 10.0 ** (1 - E13_5_DIGITS) / mantissa


def check_complete(path: Path) -> None:
    with open(path, "rb") as f:
        f.seek(max(0, path.stat().st_size - TAIL_BYTES))
        tail = f.read()
    if not tail.rstrip(b"\r\n").endswith(DATASET_END):
        raise RecordingError(f"{path}: cut short: the last UFF dataset is not closed by its '-1' line (an "
                             "interrupted copy or upload); send the whole file again")


def _channel(s: dict, name: str, path: Path) -> Channel | NotASignal:
    if s.get("func_type") not in TIME_FUNCTION_TYPES:
        return NotASignal(f"is UFF function type {s.get('func_type')}, not a time history (type 0 or 1)")
    data = np.asarray(s["data"])
    if np.iscomplexobj(data):
        return NotASignal("holds complex values (a spectrum or FRF), not a time history")
    if data.size != s.get("num_pts", data.size):
        raise RecordingError(f"{path}: dataset {name!r} holds {data.size} of the {s['num_pts']} samples its header "
                             "announces: the file is cut short or damaged")
    if s.get("abscissa_spacing") == 1:
        inc = float(s["abscissa_inc"])
        if not (np.isfinite(inc) and inc > 0):
            raise RecordingError(f"{path}: dataset {name!r}: abscissa increment {inc:g} s; a sample step must be positive")
        clock = SampleClock(1.0 / inc, float(s.get("abscissa_min", 0.0)), e13_5_resolution(inc),
                            f"{name}'s abscissa increment ({inc:.5e} s, E13.5)")
    else:
        clock = clock_from_time(np.asarray(s["x"], dtype=float), str(path), name, f"{name}'s abscissa values")
    unit = str(s.get("ordinate_axis_units_lab", "")).strip()
    return Channel(data.astype(float), unit, clock)


def channels(path: Path, wanted: set[str]) -> dict:
    import pyuff

    check_complete(path)
    sets = pyuff.UFF(str(path)).read_sets()
    sets = [sets] if isinstance(sets, dict) else sets
    series = [s for s in sets if s.get("type") == 58]
    if not series:
        raise RecordingError(f"{path}: no type 58 datasets (time histories) in this UFF file")
    places: dict[str, list] = {}
    for s in series:
        places.setdefault(str(s.get("id1", "")).strip(), []).append(s)
    out: dict = {}
    for name, found in places.items():
        if len(found) > 1:
            out[name] = NotASignal(f"names {len(found)} datasets (id1 lines): each channel's id1 must be unique")
        else:
            out[name] = _channel(found[0], name, path) if name in wanted else None
    return out


FORMAT = FileFormat("UFF58", (".uff", ".unv"), channels=channels, magic=re.compile(rb"\s*-1\r?\n\s*\d+"),
                    magic_words="UFF files begin with a '-1' line and a dataset type", noun="dataset")
