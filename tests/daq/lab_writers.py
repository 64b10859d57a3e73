"""Recordings written by each format's own library (float64 where the format allows it), for the readers'
tests (tests/daq/test_formats.py) and the service's upload tests."""
from __future__ import annotations

import numpy as np


def write_csv_exact(path, fs_hz: float, channels: dict) -> None:
    """CSV with a time column, every value printed to 17 significant digits (float64 round-trips)."""
    n = next(iter(channels.values())).size
    cols = {"t": np.arange(n) / fs_hz, **channels}
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.17g")


def write_tdms(path, fs_hz: float, channels: dict, groups: dict | None = None, units: dict | None = None,
               segments: int = 1) -> None:
    """npTDMS's TdmsWriter as LabVIEW writes waveforms: wf_increment, wf_start_offset, unit_string; the
    samples in `segments` segments (a DAQ appends one per write); groups: {channel: group} (default 'acc')."""
    from nptdms import ChannelObject, TdmsWriter

    groups, units = groups or {}, units or {}
    with TdmsWriter(str(path)) as w:
        for part in range(segments):
            w.write_segment([
                ChannelObject(groups.get(name, "acc"), name.split("/")[-1], np.array_split(x, segments)[part],
                              properties={"wf_increment": 1.0 / fs_hz, "wf_start_offset": 0.0,
                                          "unit_string": units.get(name, "m/s^2")})
                for name, x in channels.items()])


def write_uff(path, fs_hz: float, channels: dict, binary: bool = True, units: dict | None = None) -> None:
    """pyuff's writer: one type 58 dataset per channel (id1 = its name), in the order given; binary 58b holds
    float64, ASCII prints 12 significant digits (%20.11e); the increment is E13.5 either way."""
    import pyuff

    units = units or {}
    uff = pyuff.UFF(str(path))
    for node, (name, x) in enumerate(channels.items(), start=1):
        x = np.asarray(x, dtype=float)
        uff.write_sets(pyuff.prepare_58(
            binary=int(binary), id1=name, func_type=1, rsp_node=node, rsp_dir=1, ref_node=0, ref_dir=0,
            ord_data_type=4, num_pts=x.size, abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1.0 / fs_hz,
            data=x, x=np.arange(x.size) / fs_hz, abscissa_spec_data_type=17, ordinate_spec_data_type=12,
            orddenom_spec_data_type=0, ordinate_axis_units_lab=units.get(name, "m/s^2"), abscissa_axis_units_lab="s"),
            mode="add")


def write_mdf(path, fs_hz: float, channels: dict, units: dict | None = None) -> None:
    """asammdf's MDF 4.10 writer: one channel group, the time stamps k / fs_hz as its master channel."""
    from asammdf import MDF, Signal

    units = units or {}
    mdf = MDF(version="4.10")
    t = np.arange(next(iter(channels.values())).size) / fs_hz
    mdf.append([Signal(np.asarray(x, dtype=float), t, name=name, unit=units.get(name, "m/s^2"))
                for name, x in channels.items()])
    mdf.save(str(path), overwrite=True)
    mdf.close()
