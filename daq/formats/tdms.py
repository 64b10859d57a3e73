"""NI TDMS files (LabVIEW, DAQmx) through npTDMS: channels found by name whatever their group (a name in
two groups is named GROUP/NAME), the clock from each channel's wf_increment and wf_start_offset, the
unit from its unit_string. Segments are walked first: a file cut short (an interrupted copy, a crashed
writer) is refused, where npTDMS would read what is there with a logged warning."""
from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

from identify.data.channels import Channel, NotASignal, SampleClock
from identify.errors import RecordingError

from . import FileFormat

#: A segment's lead-in: tag, table-of-contents mask, version, next segment's offset, raw data's offset.
LEAD_IN = struct.Struct("<4sIIQQ")
BIG_ENDIAN_TOC_BIT = 1 << 6
#: The next-segment offset a writer leaves when it stopped before finishing the segment.
UNFINISHED_SEGMENT = 0xFFFFFFFFFFFFFFFF


def check_segments(path: Path) -> None:
    """Refuse a file whose segments run past its end, or whose writer never finished the last one."""
    size = path.stat().st_size
    pos = 0
    with open(path, "rb") as f:
        while pos < size:
            f.seek(pos)
            head = f.read(LEAD_IN.size)
            if len(head) < LEAD_IN.size or head[:4] != b"TDSm":
                raise RecordingError(f"{path}: damaged TDMS file: no segment header at byte {pos} (cut short, or "
                                     "not written by a TDMS writer)")
            toc = struct.unpack("<I", head[4:8])[0]
            order = ">" if toc & BIG_ENDIAN_TOC_BIT else "<"
            next_offset = struct.unpack(order + "Q", head[12:20])[0]
            if next_offset == UNFINISHED_SEGMENT:
                raise RecordingError(f"{path}: the TDMS writer did not finish the file (its last segment is marked "
                                     "unfinished): the recording may be incomplete")
            pos += LEAD_IN.size + next_offset
    if pos > size:
        raise RecordingError(f"{path}: cut short: its last TDMS segment announces {pos - size} bytes more than the "
                             "file holds (an interrupted copy or upload); send the whole file again")


def _channel(ch, name: str, path: Path) -> Channel | NotASignal:
    data = ch[:]
    if not isinstance(data, np.ndarray) or data.dtype.kind not in "fiu":
        return NotASignal(f"holds {getattr(data, 'dtype', type(data))} values, not numbers")
    props = ch.properties
    inc = props.get("wf_increment")
    clock = None
    if inc is not None:
        inc = float(inc)
        if not (np.isfinite(inc) and inc > 0):
            raise RecordingError(f"{path}: channel {name!r}: wf_increment is {inc:g} s; a sample step must be positive")
        clock = SampleClock(1.0 / inc, float(props.get("wf_start_offset", 0.0)), 0.0, f"{name}'s wf_increment")
    return Channel(data.astype(float), str(props.get("unit_string", "")), clock)


def channels(path: Path, wanted: set[str]) -> dict:
    from nptdms import TdmsFile

    check_segments(path)
    with TdmsFile.open(path) as f:
        places: dict[str, list] = {}
        for group in f.groups():
            for ch in group.channels():
                places.setdefault(ch.name, []).append((group.name, ch))
        out: dict = {}
        for name, where in places.items():
            named = [(name, where[0][1])] if len(where) == 1 else [(f"{g}/{name}", ch) for g, ch in where]
            if len(where) > 1:
                out[name] = NotASignal(f"is in {len(where)} groups ({', '.join(repr(g) for g, _ in where)}): name it "
                                       f"with its group, e.g. {named[0][0]!r}")
            for key, ch in named:
                out[key] = _channel(ch, key, path) if key in wanted else None
    return out


FORMAT = FileFormat("TDMS", (".tdms",), channels=channels, magic=re.compile(rb"TDSm"),
                    magic_words="TDMS files begin with 'TDSm'")
