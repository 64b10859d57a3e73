"""Accelerometer sources: one small interface, one class per transport.

    source = SerialSource("socket://127.0.0.1:5021", fs_hz=2048)     # or a device path, /dev/ttyUSB0
    source = CanSource("remote", "ws://127.0.0.1:54701/", fs_hz=2048) # any python-can interface
    for first_index, counts in source.read(): ...                     # counts: (n, channels) ADC counts

`read()` returns the blocks received since the last call, each with the sample index of its first row;
a lost or corrupted frame shows as a jump of the index (the recorder lists it as a gap, never splices).
`stats` counts frames received, frames lost (from sequence numbers) and frames rejected as corrupt, so a
recording can say how clean its link was. A sensor with another format is one more class like these
(with `from_config(section, fs_hz)`) and one line in SOURCES.
"""
from __future__ import annotations

import numpy as np

from protocol import ACCELEROMETER_SOURCES, can_frames
from protocol.frames import FrameDecoder

from .devices import DeviceError


class AccelerometerSource:
    """Interface. fs_hz: sample rate (Hz); url: where the samples come from, for messages."""

    fs_hz: float
    url: str

    def __init__(self):
        self.stats = {"frames": 0, "frames_lost": 0, "frames_corrupt": 0, "saturated_frames": 0}
        self.backlog = False  # the last read() stopped at its size limit: more was already waiting

    def read(self) -> list[tuple[int, np.ndarray]]: ...
    def close(self) -> None: ...

    def reset_stats(self) -> None:
        """Start counting afresh (a sweep counts its own recording's frames, not the preflight's)."""
        self.stats = dict.fromkeys(self.stats, 0)


class SerialSource(AccelerometerSource):
    """Framed stream (protocol.frames: sync, sequence number, timestamp, CRC-32) from any pyserial URL.
    The sample index comes from the frame's timestamp, so lost frames leave exact gaps."""

    READ_BYTES = 65536

    def __init__(self, url: str, fs_hz: float, timeout_s: float = 0.05):
        import serial

        super().__init__()
        self.serial_mod = serial
        try:
            self.port = serial.serial_for_url(url, timeout=timeout_s)
        except (serial.SerialException, ValueError) as exc:
            raise DeviceError(f"accelerometers at {url}: {exc}") from None
        self.fs_hz, self.url = fs_hz, url
        self.decoder = FrameDecoder()
        self._last_seq: int | None = None
        self._crc_seen = 0

    @classmethod
    def from_config(cls, section: dict, fs_hz: float) -> SerialSource:
        """[stream] url."""
        return cls(section["url"], fs_hz)

    def read(self) -> list[tuple[int, np.ndarray]]:
        try:
            data = self.port.read(self.READ_BYTES)
        except self.serial_mod.SerialException as exc:
            raise DeviceError(f"accelerometer stream {self.url} lost: {exc}") from None
        self.backlog = len(data) == self.READ_BYTES  # a caught-up read returns less, after its timeout
        frames = self.decoder.feed(data)
        for f in frames:
            if self._last_seq is not None:
                self.stats["frames_lost"] += (f.seq - self._last_seq - 1) & 0xFFFFFFFF
            self._last_seq = f.seq
            self.stats["saturated_frames"] += bool(f.flags & 1)
        self.stats["frames"] += len(frames)
        self.stats["frames_corrupt"] += self.decoder.crc_errors - self._crc_seen
        self._crc_seen = self.decoder.crc_errors
        return [(int(round(f.timestamp_us * self.fs_hz / 1e6)), f.counts) for f in frames]

    def close(self) -> None:
        self.port.close()


class CanSource(AccelerometerSource):
    """One CAN frame per sample instant (protocol.can_frames: 16-bit counter, two channels' counts, flags) on
    any python-can bus. The counter is unwrapped to a running sample index; a jump of the counter is a
    lost stretch (CAN's own CRC rejects corrupt frames on the wire, so they arrive as losses too).
    The first index is the counter of the first frame heard (the bus carries no absolute time)."""

    MAX_FRAMES_PER_READ = 20000  # bounds one read() so a flooded bus cannot starve the caller

    def __init__(self, interface: str, channel: str, fs_hz: float, node: int = 0, timeout_s: float = 0.05):
        import can

        super().__init__()
        self.fs_hz, self.url = fs_hz, f"CAN {interface} {channel} node {node}"
        self.arbitration_id = can_frames.BASE_ID + node
        self.timeout_s = timeout_s
        try:
            self.bus = can.Bus(interface=interface, channel=channel,
                               can_filters=[{"can_id": self.arbitration_id, "can_mask": 0x7FF, "extended": False}])
        except Exception as exc:  # python-can raises CanError, OSError or ValueError by interface
            raise DeviceError(f"accelerometers on {self.url}: {exc}") from None
        self._can_error = can.CanError
        self._next: int | None = None  # sample index the next frame should carry

    @classmethod
    def from_config(cls, section: dict, fs_hz: float) -> CanSource:
        """[can] interface, channel, node (default 0)."""
        if not section.get("interface"):
            raise DeviceError("[sampling] source = \"can\" needs a [can] section with interface and channel")
        return cls(section["interface"], section.get("channel"), fs_hz, int(section.get("node", 0)))

    def read(self) -> list[tuple[int, np.ndarray]]:
        rows, blocks = [], []
        first = None
        taken = 0
        try:
            msg = self.bus.recv(self.timeout_s)
            while msg is not None:
                if msg.arbitration_id == self.arbitration_id and not msg.is_error_frame and len(msg.data) == 8:
                    counter, c0, c1, flags = can_frames.decode(msg.data)
                    index = counter if self._next is None else self._next + ((counter - self._next) & 0xFFFF)
                    if self._next is not None and index != self._next:  # a lost stretch: close the block
                        self.stats["frames_lost"] += index - self._next
                        if rows:
                            blocks.append((first, np.array(rows, dtype=np.int16)))
                        rows = []
                    if not rows:
                        first = index
                    rows.append((c0, c1))
                    self.stats["saturated_frames"] += bool(flags & 1)
                    self._next = index + 1
                elif msg.is_error_frame:
                    self.stats["frames_corrupt"] += 1
                taken += 1
                if taken >= self.MAX_FRAMES_PER_READ:  # checked before the next recv: no frame taken is dropped
                    break
                msg = self.bus.recv(0)
        except self._can_error as exc:
            raise DeviceError(f"accelerometer bus {self.url} lost: {exc}") from None
        self.backlog = taken >= self.MAX_FRAMES_PER_READ  # more were probably queued behind the limit
        if rows:
            blocks.append((first, np.array(rows, dtype=np.int16)))
        self.stats["frames"] += sum(b.shape[0] for _, b in blocks)
        return blocks

    def close(self) -> None:
        self.bus.shutdown()


#: [sampling] source of a rig configuration -> the class that reads it (one per protocol.ACCELEROMETER_SOURCES)
SOURCES: dict[str, type[AccelerometerSource]] = {
    "stream": SerialSource,
    "can": CanSource,
}


def open_source(stream: dict, can: dict, fs_hz: float, kind: str = ACCELEROMETER_SOURCES[0]) -> AccelerometerSource:
    """The accelerometer source a rig configuration names ([sampling] source), opened from its own section."""
    if kind not in SOURCES:
        raise DeviceError(f"[sampling] source {kind!r} is not one the DAQ reads: {', '.join(SOURCES)}")
    return SOURCES[kind].from_config({"stream": stream, "can": can}[kind], fs_hz)
