"""The accelerometer samples as CAN frames, for rigs whose sensors sit on a CAN bus: the simulated rig
sends them (sim/server.py, python-can), the DAQ reads them (daq/sources.py).

One classic CAN frame (11-bit id, 8 data bytes) per sample instant, little-endian:

    id 0x180 + node  (default node 0)
    bytes 0-1  u16   sample counter, +1 per sample, wraps at 65536 (gaps = lost frames)
    bytes 2-3  i16   channel 0 counts (table acceleration)
    bytes 4-5  i16   channel 1 counts (mass acceleration)
    bytes 6-7  u16   flags: bit 0 saturated

Integrity is CAN's own (15-bit CRC, acknowledgement, error frames), so no software CRC is added.
Counts convert with the same sensitivity as the TCP stream.
"""
from __future__ import annotations

import struct

import numpy as np

BASE_ID = 0x180
PAYLOAD = struct.Struct("<HhhH")


def encode(counter: int, counts: np.ndarray, flags: int = 0) -> list[bytes]:
    """Payloads of consecutive frames for counts (n, 2) starting at `counter`."""
    return [PAYLOAD.pack((counter + i) & 0xFFFF, int(c[0]), int(c[1]), flags) for i, c in enumerate(counts)]


def decode(data: bytes) -> tuple[int, int, int, int]:
    """(counter, channel 0 counts, channel 1 counts, flags) of one frame's payload."""
    return PAYLOAD.unpack(bytes(data))
