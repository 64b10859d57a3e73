"""The DAQ's own HDF5 recordings (daq.recorder's layout): read by daq.recorder, which keeps gaps, quality
flags and the status, and reads only the rows asked for; the upload check reads only the metadata."""
import re

from identify.errors import RecordingError
from identify.data.recording import H5_SUFFIXES

from . import FileFormat, ReadRequest


def _open(path, request: ReadRequest, samples):
    from daq.recorder import DEFAULT_CHANNELS, read_h5_recording

    return read_h5_recording(path, request.input or DEFAULT_CHANNELS[0], request.output or DEFAULT_CHANNELS[1],
                             samples)


def _check(path, request: ReadRequest) -> dict:
    """The channels a job will read (the request's, else identify's pair) checked now, not at the job."""
    from daq.recorder import DEFAULT_CHANNELS, describe

    d = describe(path)
    wanted = [request.input or DEFAULT_CHANNELS[0], request.output or DEFAULT_CHANNELS[1]]
    missing = [c for c in wanted if c not in d["channels"]]
    if missing:
        raise RecordingError(f"{path}: missing channel(s) {missing}; found {d['channels']}")
    return {"samples": d["samples"], "fs_hz": d["fs_hz"], "gaps": len(d["gaps"]), "status_in_file": d["status"]}


FORMAT = FileFormat("HDF5", H5_SUFFIXES, magic=re.compile(rb"\x89HDF\r\n\x1a\n"),
                    magic_words="HDF5 files begin with the HDF5 signature", open=_open, check=_check)
