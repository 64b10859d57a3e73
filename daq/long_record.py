"""Long recordings in the DAQ's HDF5 layout, with fresh sensor noise on every sample: what out-of-core
identification is measured and tested on (benchmarks/out_of_core.py,
tests/identify/test_out_of_core_coverage.py).

The rig's motion is the caller's: one noise-free record that starts and ends at rest (the simulated
Table 1 sweep, sim.synth.noise_free_sweep), so records placed end to end are the rig's motion over a
repeated sweep, repeated up to n samples. The sensor noise is not repeated: white noise of NOISE_FRACTION
of each channel's std (the Accelerometer's rule) is drawn afresh for every block written. Repeating a few
noisy sweeps instead (as the benchmark once did) repeats their noise too: a 1e7-sample record then holds
the noise of four minutes, and standard errors computed as if its blocks were independent are too small
by the square root of the repeats. The motion comes in as a recording, so the DAQ never runs the simulator.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from identify.data.recording import Recording

#: Rows written at a time.
BLOCK_ROWS = 1 << 20
#: Sensor noise std as a fraction of each channel's std (0.5 %, the acceptance sweep's).
NOISE_FRACTION = 0.005


def write_long_record(path, n: int, clean: Recording, seed: int | None = None,
                      noise_fraction: float = NOISE_FRACTION) -> None:
    """Write n samples to `path`: `clean` (table and mass acceleration, noise-free, at its fs_hz)
    repeated, with fresh noise on every sample (module doc)."""
    fs_hz = clean.fs_hz
    channels = (clean.input, clean.output)
    std = [noise_fraction * float(np.std(x)) for x in channels]
    rng = np.random.default_rng(seed)
    with h5py.File(Path(path), "w") as f:
        e = f.create_group("entry")
        e.attrs.update(NX_class="NXentry", status="complete", status_reason="", fs_hz=fs_hz, samples_written=n)
        e.create_group("sweep")
        inst = e.create_group("instrument")
        d = e.create_group("data")
        ds = {"time": d.create_dataset("time", (n,), dtype="f8", chunks=(4096,))}
        for ch in ("table_acc", "mass_acc"):
            inst.create_group(ch).attrs.update(units="m/s^2", sensitivity=1.0)
            ds[ch] = d.create_dataset(ch, (n,), dtype="f4", chunks=(4096,))
            ds[ch].attrs["units"] = "m/s^2"
        e.create_dataset("gaps", (0, 2), dtype="i8")
        for a in range(0, n, BLOCK_ROWS):
            b = min(a + BLOCK_ROWS, n)
            idx = np.arange(a, b) % channels[0].size
            ds["time"][a:b] = np.arange(a, b) / fs_hz
            for ch, x, s in zip(("table_acc", "mass_acc"), channels, std):
                ds[ch][a:b] = (x[idx] + s * rng.standard_normal(b - a)).astype("f4")
