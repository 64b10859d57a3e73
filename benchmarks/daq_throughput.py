"""DAQ recorder ingest next to a raw h5py append of the same blocks, in one process.

    python benchmarks/daq_throughput.py [--seconds 60] [--channels 4] [--fs 51200]

Both write the same float32 blocks (time column + channels) into resizable chunked datasets; the raw
anchor does resize+write per block and nothing else, the recorder also keeps the NeXus metadata, the
gap bookkeeping and a flush at least every second. Target (issue 4): recorder >= 0.8x raw.
Stream rates over TCP are measured by benchmarks/stream_throughput.py.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from daq.recorder import CHUNK_ROWS, Recorder  # noqa: E402


def raw(path, blocks, fs):
    with h5py.File(path, "w") as f:
        c = blocks[0].shape[1]
        t = f.create_dataset("time", (0,), maxshape=(None,), dtype="f8", chunks=(CHUNK_ROWS,))
        ds = [f.create_dataset(f"ch{j}", (0,), maxshape=(None,), dtype="f4", chunks=(CHUNK_ROWS,)) for j in range(c)]
        n = 0
        for b in blocks:
            m = b.shape[0]
            t.resize((n + m,))
            t[n:] = (n + np.arange(m)) / fs
            for j, d in enumerate(ds):
                d.resize((n + m,))
                d[n:] = b[:, j]
            n += m


def recorder(path, blocks, fs):
    r = Recorder(path, tuple(f"ch{j}" for j in range(blocks[0].shape[1])), fs)
    k = 0
    for b in blocks:
        r.append(k, b)
        k += b.shape[0]
    r.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--channels", type=int, default=4)
    p.add_argument("--fs", type=float, default=51200.0)
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args(argv)
    n = int(args.seconds * args.fs)
    print(f"{n} samples x {args.channels} channels ({args.seconds:g} s at {args.fs:g} Hz), best of {args.repeat}")
    print(f"{'block':>6s} {'raw h5py s':>11s} {'recorder s':>11s} {'ratio raw/rec':>14s} {'recorder MS/s':>14s}")
    for block in (1024, 4096, 16384):
        data = np.random.default_rng(0).standard_normal((n, args.channels)).astype(np.float32)
        blocks = [data[a:a + block] for a in range(0, n, block)]
        best = {}
        with tempfile.TemporaryDirectory() as d:
            for name, fn in (("raw", raw), ("recorder", recorder)):
                times = []
                for i in range(args.repeat):
                    path = Path(d) / f"{name}{block}_{i}.h5"
                    t0 = time.perf_counter()
                    fn(path, blocks, args.fs)
                    times.append(time.perf_counter() - t0)
                best[name] = min(times)
        print(f"{block:6d} {best['raw']:11.3f} {best['recorder']:11.3f} {best['raw'] / best['recorder']:14.2f} "
              f"{n / best['recorder'] / 1e6:14.2f}", flush=True)
    print("target: recorder >= 0.8x raw (ratio raw/rec >= 0.8); real time needs >= "
          f"{args.fs / 1e6:.3f} MS/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
