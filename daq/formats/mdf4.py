"""ASAM MDF 4 files (automotive and many DAQ systems) through asammdf: a channel by name (a name in several
channel groups is refused, naming them), its time from the channel's own time stamps (which must be
uniform), its unit from the channel. A file its writer never finalised (UnFinMF) is refused."""
from __future__ import annotations

import gc
import re
import sys
from pathlib import Path

import numpy as np

from identify.data.channels import Channel, NotASignal, clock_from_time
from identify.errors import RecordingError

from . import FileFormat

#: The identification block's first bytes of a finalised file, and of one whose writer stopped early.
FINALISED, UNFINISHED = b"MDF     ", b"UnFinMF "


def _open(path: Path):
    """asammdf's MDF(path). On a damaged file it fails leaving a half-built object whose collection prints an
    AttributeError from MDF4.__del__ on stderr: collected here without that noise, and the failure named."""
    from asammdf import MDF

    hook = sys.unraisablehook
    sys.unraisablehook = lambda u: None if "MDF" in repr(u.object) else hook(u)
    problem = ""
    try:
        return MDF(path)
    except Exception as exc:
        problem = f"{type(exc).__name__}: {exc}"
    finally:
        if problem:
            gc.collect()
        sys.unraisablehook = hook
    raise RecordingError(f"{path}: not a readable MDF4 file, cut short or damaged ({problem})")


def channels(path: Path, wanted: set[str]) -> dict:
    with open(path, "rb") as f:
        if f.read(len(UNFINISHED)) == UNFINISHED:
            raise RecordingError(f"{path}: its writer did not finalise this MDF file (UnFinMF): the recording may be "
                                 "incomplete; finalise it in the acquisition software first")
    out: dict = {}
    with _open(path) as mdf:
        for name, where in mdf.channels_db.items():
            if len(where) > 1:
                out[name] = NotASignal(f"is in {len(where)} channel groups ({', '.join(str(g) for g, _ in where)}): "
                                       "a channel must have a unique name")
            elif name in wanted:
                group, index = where[0]
                sig = mdf.get(name, group=group, index=index)
                samples = np.asarray(sig.samples)
                if samples.dtype.kind not in "fiu" or samples.ndim != 1:
                    out[name] = NotASignal(f"holds {samples.dtype} values, not numbers")
                    continue
                clock = clock_from_time(np.asarray(sig.timestamps, dtype=float), str(path), name,
                                        f"{name}'s time stamps")
                out[name] = Channel(samples.astype(float), str(sig.unit or ""), clock)
            else:
                out[name] = None
    return out


FORMAT = FileFormat("MDF4", (".mf4", ".mdf"), channels=channels, magic=re.compile(rb"MDF     |UnFinMF "),
                    magic_words="MDF files begin with 'MDF'")
