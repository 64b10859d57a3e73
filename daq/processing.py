"""Processed signals added to a finished recording: the mass's motion relative to the table.

    add_processed("sweep.h5")          # or: shakeid recordings sweep.h5 --process

writes /entry/processed (NXdata) next to the raw data, never touching it:

    relative_acc   (m/s^2)  q'' = mass_acc - table_acc, band-limited
    relative_vel   (m/s)    q'  by band-limited FFT integration (identify.chain.states, the identification's
    relative_disp  (m)      q   own measurement chain, so what an operator plots is what is fitted)
    valid          (1/0)    0 where a segment's edge taper and guard make the integrals unreliable
    @band_hz, @segments

Each gap-free segment is integrated on its own (integrating across a gap would splice the record);
a segment too short for the band is left NaN and valid = 0. The group is written under a temporary
name and renamed when complete, so a crash never leaves a half-written `processed` behind.
"""
from __future__ import annotations

import h5py
import numpy as np

from identify.chain.states import reconstruct_states
from identify.errors import IdentificationError, RecordingError
from identify.data.recording import Recording

from .recorder import DEFAULT_CHANNELS, describe, segments

SIGNALS = (("relative_acc", "m/s^2"), ("relative_vel", "m/s"), ("relative_disp", "m"))


def add_processed(path, input: str = DEFAULT_CHANNELS[0], output: str = DEFAULT_CHANNELS[1],
                  band_hz: tuple[float, float] | None = None) -> dict:
    """Compute and store the processed signals; returns {band_hz, segments, valid_fraction}.
    band_hz: integration band (Hz); default from the recording's own spectrum (as `identify`)."""
    info = describe(path)
    if info["status"] == "running":
        raise RecordingError(f"{path}: still recording (status running); process it once it is closed, or run "
                             "`shakeid recordings --recover` if its recorder crashed")
    with h5py.File(path, "r") as f:
        d = f["entry/data"]
        missing = [c for c in (input, output) if c not in d]
        if missing:
            raise RecordingError(f"{path}: missing channel(s) {missing}; found {info['channels']}")
        u, y, t = d[input][()].astype(float), d[output][()].astype(float), d["time"][()]
    fs = float(info["fs_hz"])
    n = t.size
    out = {name: np.full(n, np.nan) for name, _ in SIGNALS}
    valid = np.zeros(n, dtype=np.uint8)
    bands = []
    for a, b in segments(t, fs):
        try:
            s = reconstruct_states(Recording(u[a:b], y[a:b], fs, "base", input, output, source=str(path)),
                                   band_hz=band_hz)
        except (IdentificationError, RecordingError):
            continue  # too short or without excitation: stays NaN, valid 0
        out["relative_acc"][a:b], out["relative_vel"][a:b], out["relative_disp"][a:b] = s.q1_dot, s.q1, s.q2
        valid[a + s.valid.start: a + s.valid.stop] = 1
        bands.append(s.band_hz)
    if not bands:
        raise RecordingError(f"{path}: no gap-free stretch long enough to integrate")
    with h5py.File(path, "r+") as f:
        e = f["entry"]
        if "processed.tmp" in e:
            del e["processed.tmp"]  # left by a crash during an earlier run
        g = e.create_group("processed.tmp")
        g.attrs.update(NX_class="NXdata", signal="relative_disp", axes="time", input=input, output=output,
                       method="band-limited FFT integration of mass_acc - table_acc (identify.chain.states)",
                       band_hz=np.array(bands[0]), segments=len(bands))
        g["time"] = h5py.SoftLink("/entry/data/time")
        for name, units in SIGNALS:
            ds = g.create_dataset(name, data=out[name].astype(np.float32))
            ds.attrs["units"] = units
        g.create_dataset("valid", data=valid).attrs["units"] = ""
        f.flush()
        if "processed" in e:
            del e["processed"]
        e.move("processed.tmp", "processed")
    return {"band_hz": bands[0], "segments": len(bands), "valid_fraction": float(valid.mean())}
