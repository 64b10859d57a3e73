"""Accelerometer stream throughput: frame encoding -> TCP -> pyserial socket:// -> decoding, 4 channels.

    python benchmarks/stream_throughput.py [--seconds 3]

A producer thread sends frames (512 samples x 4 channels, the documented format) paced at each rate; the
reader opens the stream with pyserial's socket:// as the DAQ will, and counts frames, CRC errors and
sequence gaps. Target (issue 3): 4 channels x 51.2 kS/s without loss. The producer lingers before it
closes: pyserial loses the bytes of its last partial read when the peer closes (a property of
pyserial's socket:// handler, not of the stream), which would otherwise count as a lost last frame.
"""
from __future__ import annotations

import argparse
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np
import serial

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from protocol import frames  # noqa: E402
from sim.server import SENSITIVITY, free_port  # noqa: E402


def run(rate_hz: float, channels: int = 4, seconds: float = 3.0, frame_samples: int = 512) -> dict:
    port = free_port()
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", port))
    srv.listen(1)
    stats: dict = {}
    block = np.random.default_rng(0).standard_normal((frame_samples, channels)) * 5

    def producer():
        conn, _ = srv.accept()
        seq, sent, t0 = 0, 0, time.perf_counter()
        total = rate_hz * seconds
        while sent < total:
            target = (time.perf_counter() - t0) * rate_hz
            while sent < min(target, total):
                counts, flags = frames.to_counts(block, SENSITIVITY)
                conn.sendall(frames.encode(seq, int(sent / rate_hz * 1e6), counts, flags))
                seq, sent = seq + 1, sent + frame_samples
            time.sleep(0.001)
        stats["sent"] = seq
        time.sleep(1.0)
        conn.close()

    th = threading.Thread(target=producer)
    th.start()
    reader = serial.serial_for_url(f"socket://127.0.0.1:{port}", timeout=0.2)
    dec, got, t0 = frames.FrameDecoder(), [], time.perf_counter()
    while time.perf_counter() - t0 < seconds + 5 and not ("sent" in stats and len(got) >= stats["sent"]):
        try:
            got += dec.feed(reader.read(65536))
        except serial.SerialException:
            break
    th.join()
    srv.close()
    seq = np.array([f.seq for f in got])
    return {"rate_hz": rate_hz, "sent": stats.get("sent", 0), "received": len(got), "crc_errors": dec.crc_errors,
            "gaps": int(np.sum(np.diff(seq) - 1)) if seq.size > 1 else 0}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=3.0)
    args = p.parse_args(argv)
    print("samples/s per channel, 4 channels: frames sent / received, CRC errors, sequence gaps  (target 51.2 kS/s)")
    for rate in (51_200, 204_800, 819_200, 3_276_800):
        r = run(rate, seconds=args.seconds)
        print(f"{rate / 1e3:9.1f} kS/s: {r['sent']:6d} / {r['received']:6d}, CRC errors {r['crc_errors']}, "
              f"gaps {r['gaps']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
