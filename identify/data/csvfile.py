"""CSV recordings: a header naming the columns, then rows of numbers, streamed in chunks.

A column of words beside the signals (an operator, a note) is kept out and named if asked for. A last line
without its line break is refused: a file cut short in the middle of a line (an interrupted copy or
upload) would otherwise read as complete, its last value truncated.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .channels import TextColumn
from ..errors import RecordingError

#: CSV rows parsed at a time: memory stays near the parsed floats (8 bytes a value), whatever the file size
CSV_CHUNK_ROWS = 1 << 16


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """Streamed: rows are parsed in chunks of CSV_CHUNK_ROWS into float arrays, so a 200 MB file never
    exists as Python strings (the whole-file reader took 19x the file size in memory)."""
    try:
        with path.open(newline="") as f:
            return _parse_csv(path, f)
    except UnicodeDecodeError:
        raise RecordingError(f"{path}: not a text CSV file") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from None


def _parse_csv(path: Path, f) -> dict[str, np.ndarray]:
    lines = ((k, ln) for k, ln in enumerate(f, start=1) if ln.strip() and not ln.lstrip().startswith("#"))
    first = next(lines, None)
    if first is None:
        raise RecordingError(f"{path}: empty file")
    try:
        delim = csv.Sniffer().sniff(first[1], delimiters=",;\t ").delimiter
    except csv.Error:
        delim = ","
    header = [h.strip() for h in next(csv.reader([first[1]], delimiter=delim))]
    if any(_is_number(h) for h in header):
        raise RecordingError(f"{path}: first line must be a header naming the columns, got {first[1].strip()!r}")
    chunks, numbers, rows = [], [], []
    text: dict[str, str] = {}  # columns of words (an operator, a comment): kept out, named if asked for
    used = list(range(len(header)))
    for k, ln in lines:
        if not numbers and not chunks:  # the first data row says which columns are text
            fields = _fields(ln, delim)
            text = {header[j]: f"line {k}: {v.strip()!r}" for j, v in enumerate(fields[:len(header)])
                    if not _is_number(v)}
            used = [j for j, h in enumerate(header) if h not in text]
        numbers.append(k)
        rows.append(ln)
        if not ln.endswith(("\n", "\r")):  # only a file's last line can lack its line break
            raise RecordingError(f"{path}: line {k}, the last, does not end with a line break: the file looks cut "
                                 "short (an interrupted copy or upload), its last value may be truncated; send the "
                                 "whole file again, or end that line if it is complete")
        if len(rows) == CSV_CHUNK_ROWS:
            chunks.append(_parse_rows(path, rows, numbers, delim, len(header), used))
            numbers, rows = [], []
    if rows:
        chunks.append(_parse_rows(path, rows, numbers, delim, len(header), used))
    data = np.concatenate(chunks) if chunks else np.empty((0, len(used)))
    return {**{header[j]: data[:, i] for i, j in enumerate(used)}, **{h: TextColumn(v) for h, v in text.items()}}


def _fields(line: str, delim: str) -> list[str]:
    return line.split() if delim == " " else next(csv.reader([line], delimiter=delim))


def _parse_rows(path: Path, rows: list[str], numbers: list[int], delim: str, n_cols: int, used: list[int]) -> np.ndarray:
    """rows (text lines, file line numbers `numbers`) -> (len(rows), len(used)) floats of the columns
    `used` (the numeric ones), or the first bad line named."""
    try:
        data = np.loadtxt(rows, delimiter=None if delim == " " else delim, ndmin=2, dtype=float, comments=None,
                          usecols=used if len(used) < n_cols else None)
        if data.shape == (len(rows), len(used)):
            # loadtxt reads only `used`: a row with too few or too many fields is caught below
            if len(used) == n_cols or all(len(_fields(ln, delim)) == n_cols for ln in rows):
                return data
    except ValueError:
        pass
    for k, ln in zip(numbers, rows):  # the slow path, only to say which line is wrong
        row = _fields(ln, delim)
        if len(row) != n_cols:
            raise RecordingError(f"{path}: line {k} has {len(row)} fields, header has {n_cols}")
        try:
            [float(row[j]) for j in used]
        except ValueError:
            raise RecordingError(f"{path}: line {k} has a non-numeric value: {ln.strip()[:80]!r}") from None
    raise RecordingError(f"{path}: lines {numbers[0]}-{numbers[-1]} could not be read as numbers")


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
