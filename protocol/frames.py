"""Wire format of the accelerometer stream (TCP, opened by pyserial as socket://host:port): the simulated
rig encodes it (sim/server.py), the DAQ decodes it (daq/sources.py).

Little-endian frame:

    offset size  field
    0      2     sync word 0x5AA5 (bytes A5 5A)
    2      4     sequence number, u32, +1 per frame (gaps = lost frames)
    6      8     timestamp of the first sample, u64, microseconds of rig time
    14     2     samples per channel n, u16
    16     1     channels c, u8
    17     1     flags, u8 (bit 0: a channel saturated in this frame)
    18     2nc   counts, i16, interleaved by sample (s0c0, s0c1, s1c0, ...)
    18+2nc 4     CRC-32 (zlib/IEEE 802.3) of bytes 0 .. 18+2nc-1

Counts are ADC values: acceleration = counts / sensitivity (counts per m/s^2, from the rig config).
A reader resynchronises by searching for the sync word and checking the CRC, so a corrupted or cut frame
costs that frame only, and the sequence number says how many were lost.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

SYNC = 0x5AA5
HEADER = struct.Struct("<HIQHBB")
CRC = struct.Struct("<I")
FLAG_SATURATED = 1


@dataclass
class Frame:
    seq: int
    timestamp_us: int
    counts: np.ndarray  # (n, c) int16
    flags: int = 0


def encode(seq: int, timestamp_us: int, counts: np.ndarray, flags: int = 0) -> bytes:
    counts = np.ascontiguousarray(counts, dtype="<i2")
    n, c = counts.shape
    body = HEADER.pack(SYNC, seq & 0xFFFFFFFF, timestamp_us, n, c, flags) + counts.tobytes()
    return body + CRC.pack(zlib.crc32(body))


def to_counts(acc_ms2: np.ndarray, sensitivity: float) -> tuple[np.ndarray, int]:
    """m/s^2 -> int16 counts (rounded, clipped at full scale) and the saturation flag."""
    raw = np.round(np.asarray(acc_ms2) * sensitivity)
    flags = FLAG_SATURATED if np.any(np.abs(raw) > 32767) else 0
    return np.clip(raw, -32767, 32767).astype(np.int16), flags


class FrameDecoder:
    """Incremental decoder: feed bytes, get whole valid frames; counts what it had to skip."""

    def __init__(self):
        self.buffer = bytearray()
        self.crc_errors = 0
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[Frame]:
        self.buffer += data
        frames = []
        sync = HEADER.pack(SYNC, 0, 0, 0, 0, 0)[:2]
        while True:
            i = self.buffer.find(sync)
            if i < 0:
                keep = 1 if self.buffer.endswith(sync[:1]) else 0
                self.skipped_bytes += len(self.buffer) - keep
                del self.buffer[: len(self.buffer) - keep]
                return frames
            if i:
                self.skipped_bytes += i
                del self.buffer[:i]
            if len(self.buffer) < HEADER.size:
                return frames
            _, seq, ts, n, c, flags = HEADER.unpack_from(self.buffer)
            size = HEADER.size + 2 * n * c + CRC.size
            if len(self.buffer) < size:
                return frames
            (crc,) = CRC.unpack_from(self.buffer, size - CRC.size)
            if crc != zlib.crc32(bytes(self.buffer[: size - CRC.size])):
                self.crc_errors += 1
                self.skipped_bytes += 2
                del self.buffer[:2]  # resynchronise on the next sync word
                continue
            counts = np.frombuffer(bytes(self.buffer[HEADER.size: size - CRC.size]), dtype="<i2").reshape(n, c)
            frames.append(Frame(seq, ts, counts.copy(), flags))
            del self.buffer[:size]
