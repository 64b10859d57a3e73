"""Channels as a file holds them, before they become a Recording: samples, the unit written beside them,
and the sample clock the format keeps (a time column, TDMS wf_increment, a UFF abscissa increment, MDF
time stamps), with how finely the file stores that clock.

identify.data.recording turns the channels a reader found into a Recording (one path for every format); this
module holds what that needs and what the readers share: units, clocks, and names that are not signals.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import RecordingError

#: Standard gravity g_n, m/s^2: exact by definition (3rd CGPM, 1901), so a channel in g converts losslessly.
STANDARD_GRAVITY_M_S2 = 9.80665
#: Units an acceleration channel may carry (spaces dropped, lower case) and their factor to m/s^2. A channel
#: in g is converted (NI DAQmx and most IEPE set-ups record in g, and g_n is exact); any other unit (V, m/s,
#: m, N ...) is refused: turning it into an acceleration needs a sensitivity the file cannot vouch for.
ACCELERATION_UNITS_TO_M_S2 = {"m/s^2": 1.0, "m/s²": 1.0, "m/s2": 1.0, "m/s/s": 1.0, "ms^-2": 1.0, "m*s^-2": 1.0,
                              "ms-2": 1.0, "g": STANDARD_GRAVITY_M_S2, "gn": STANDARD_GRAVITY_M_S2,
                              "mm/s^2": 1e-3, "mm/s²": 1e-3}
#: Units a time column may carry, and their factor to s.
TIME_UNITS_TO_S = {"s": 1.0, "sec": 1.0, "ms": 1e-3}
#: What files write where they mean "no unit given" (pyuff writes NONE): read as the layout's own unit.
NO_UNIT = {"", "none", "-", "1"}
#: Decimal grids a time column may be printed on, coarsest first: 1 s down to 1 ns (%.6f prints to 1 us).
TIME_GRIDS_S = tuple(10.0 ** -k for k in range(10))


class NotASignal(str):
    """A name the file has that cannot be read as a signal; the text says why (named if one is asked of it)."""


class TextColumn(NotASignal):
    """A CSV column of words, not numbers (where its first value is, e.g. "line 2: 'alice'")."""

    def why(self) -> str:
        return f"holds text, not numbers ({self})"


@dataclass(frozen=True)
class SampleClock:
    """A uniform sample clock: rate, first sample's time, and the relative uncertainty of the rate as the
    file stores it (0 for float64; UFF's E13.5 increment: up to 5e-6). `what` says where it came from."""

    fs_hz: float
    start_s: float = 0.0
    rel_resolution: float = 0.0
    what: str = ""


@dataclass
class Channel:
    """One named channel: samples, its unit as written ('' when the file gives none), its own clock if the
    format keeps one per channel (None: a time column or --fs gives the rate)."""

    values: np.ndarray
    unit: str = ""
    clock: SampleClock | None = None


def unit_factor(unit: str, table: dict[str, float]) -> float | None:
    """The factor from `unit` to the table's unit; 1 when the file gives no unit; None when not in the table."""
    key = unit.replace(" ", "").lower()
    if key in NO_UNIT:
        return 1.0
    return table.get(key)


def clock_from_time(t: np.ndarray, source: str, name: str, what: str | None = None) -> SampleClock:
    """The clock of a time column. Steps may differ by the printed resolution of the time stamps (the coarsest
    decimal grid all stamps lie on, if finer than half a step: %.6f at 2048 Hz steps 488 or 489 us), and by
    1e-3 of a step; a dropped or doubled sample differs by a whole step and is refused. `what`: the stamps'
    name in messages (default: time column NAME)."""
    what = what or f"time column {name!r}"
    if t.size < 2:
        raise RecordingError(f"{source}: {what} needs at least two samples")
    d = np.diff(t)
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise RecordingError(f"{source}: {what} is not strictly increasing")
    span = t[-1] - t[0]
    dt = span / (t.size - 1)  # the mean step: rounding of single stamps cancels over the span
    grid = printed_grid_s(t)
    # stamps on a grid as coarse as the step are exact multiples of it (k / 100 s at 100 Hz): no allowance
    allowance = grid if grid <= dt / 2 else 0.0
    worst = np.abs(d - dt)
    k = int(np.argmax(worst))
    if worst[k] > allowance * (1 + 1e-6) + 1e-3 * dt:
        printed = f"; its stamps are printed to {grid:g} s" if grid else ""
        raise RecordingError(f"{source}: {what} is not uniformly sampled: step {d[k]:.6g} s at "
                             f"sample {k + 1}, mean step {dt:.6g} s{printed} (gaps must be repaired, not spliced)")
    return SampleClock((t.size - 1) / span, float(t[0]), allowance / span, what)


def printed_grid_s(t: np.ndarray) -> float:
    """The coarsest of TIME_GRIDS_S that every stamp lies on (to 1e-3 of the grid), 0 if none: stamps of
    float64 arithmetic (k / 2048) lie on no decimal grid coarser than 1 ns. The first stamps pick the
    candidate, the whole column confirms it (one pass, not ten, over a long recording)."""
    def on(grid, x):
        return np.max(np.abs(x / grid - np.round(x / grid))) <= 1e-3

    head = t[:1000]
    return next((grid for grid in TIME_GRIDS_S if on(grid, head) and on(grid, t)), 0.0)
