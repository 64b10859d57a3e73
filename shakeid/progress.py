"""Progress of a sweep on the operator's terminal, or in a log when there is none.

On a terminal (stderr is a TTY) one bar redrawn in place with a carriage return. Without one (CI, a
pipe, `nohup`, a service's log) a carriage return would pile every redraw into one endless line, so
plain lines are printed instead, one each time the sweep passes another `step` of its duration, e.g.
`sweep 40 % (24.0 s of 60 s)  running  8.61 Hz  table +0.42 mm`, and one when it ends.
"""
from __future__ import annotations

import os
import sys


class Progress:
    """what: the word a line starts with ("sweep"); duration_s: the sweep's length (rig seconds), for
    "12.0 s of 30 s"; stream: where to write (stderr); tty: force the bar (True) or the lines (False),
    default: ask the stream; step: the fraction between two plain lines (0.1: ten lines a sweep)."""

    def __init__(self, what: str = "sweep", duration_s: float | None = None, stream=None, tty: bool | None = None,
                 step: float = 0.1):
        self.what, self.duration_s, self.step = what, duration_s, step
        self.stream = stream if stream is not None else sys.stderr
        self.tty = tty if tty is not None else bool(getattr(self.stream, "isatty", lambda: False)())
        self._next = 0.0  # the next fraction a plain line is printed at
        self._drawn = False  # a bar is on the line (the closing newline is owed)
        self._last: tuple[float, str] | None = None
        self._printed = ""  # the last plain line written

    def update(self, frac: float, label: str = "") -> None:
        """The sweep is at `frac` (0-1) of its duration; `label` says how (state, frequency, position)."""
        frac = min(max(float(frac), 0.0), 1.0)
        if self._last is not None and frac < self._last[0] - 0.05:
            self._next = 0.0  # a new sweep (a campaign's next one): count its steps again
        self._last = (frac, label)
        if self.tty:
            bar = "#" * int(30 * frac)
            self.stream.write(f"\r[{bar:<30s}] {100 * frac:5.1f} %  {label}")
            self._drawn = True
        elif frac >= self._next:
            self._print(self._line(frac, label))
            self._next = (int(frac / self.step + 1e-9) + 1) * self.step
        self.stream.flush()

    def sweep_status(self, frac: float, status) -> None:
        """SweepRunner's on_progress(fraction, PLC status): the state, frequency and table position."""
        from protocol.plc import State

        self.update(frac, rig_label(State(status.state).name.lower(), status.frequency_hz, status.position_mm))

    def close(self, final_label: str | None = None) -> None:
        """End the display: the bar's line is ended; without a TTY, the last state is printed once more
        unless the last line said it already (`final_label`, e.g. "aborted", replaces the last label)."""
        if self.tty:
            if self._drawn:
                self.stream.write("\n")
        elif self._last is not None:
            frac, label = self._last
            line = self._line(frac, final_label if final_label is not None else label)
            if line != self._printed:  # where it ended, unless the last line said it already
                self._print(line)
        self._drawn, self._last, self._next, self._printed = False, None, 0.0, ""
        self.stream.flush()

    def _print(self, line: str) -> None:
        self.stream.write(line + "\n")
        self._printed = line

    def _line(self, frac: float, label: str) -> str:
        of = f" ({frac * self.duration_s:.1f} s of {self.duration_s:g} s)" if self.duration_s else ""
        return f"{self.what} {100 * frac:.0f} %{of}" + (f"  {label.strip()}" if label.strip() else "")


def rig_label(state: str, frequency_hz: float, position_mm: float) -> str:
    """A sweep's progress label: its state, the PLC's frequency and the table's position (local sweeps and
    sweeps through the service print the same). The frequency only while the PLC runs a sweep: done or
    idle, it reads 0, which is no frequency of the sweep."""
    if state != "running":
        return f"{state:8s}  table {position_mm:+6.2f} mm"
    return f"{state:8s} {frequency_hz:6.2f} Hz  table {position_mm:+6.2f} mm"


class SurvivesClosedReader:
    """A text stream (stdout, stderr) whose reader may go away (`shakeid campaign ... | head`, a closed
    terminal): a write that meets a broken pipe sends this and every later write to /dev/null instead of
    raising. What is displayed must never stop what the rig does: a BrokenPipeError from a progress line
    ended a sweep as "DAQ error" and left a campaign marked running."""

    def __init__(self, stream):
        self._stream = stream

    def _divert(self) -> None:
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())  # what is still buffered goes there too, at exit as well
            os.close(null)
        except (OSError, ValueError):
            pass

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._divert()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._divert()

    def __getattr__(self, name):  # isatty, fileno, encoding...: the stream's own
        return getattr(self._stream, name)


def survive_closed_readers() -> None:
    """stdout and stderr of this process as SurvivesClosedReader (once; shakeid.cli.main)."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, SurvivesClosedReader):
            setattr(sys, name, SurvivesClosedReader(stream))
