"""Known truth for the frequency-response tests: the model integrated in time (the project's compiled
RK4, identify.simulation.simulate) at a sequence of fixed frequencies, each held until its response is periodic,
the state carried from one frequency to the next (a stepped sine, up or down)."""
from __future__ import annotations

import numpy as np

from identify.simulation.simulate import simulate

#: Output samples per period; RK4 steps per sample (h w = 2 pi / 256: error ~1e-8 of the response).
SAMPLES, SUBSTEPS = 64, 2
#: Periods per block; a frequency is held until two blocks' last periods agree to STEADY of the amplitude.
BLOCK, STEADY, MAX_BLOCKS = 10, 1e-8, 400


def _fine_input(table_m: float, w: float) -> np.ndarray:
    n_fine = BLOCK * SAMPLES * 2 * SUBSTEPS + 1
    t = np.arange(n_fine) * (2 * np.pi / w) / (SAMPLES * 2 * SUBSTEPS)
    return (-table_m * w * w * np.sin(w * t))[:, None]


def half_peak_to_peak(x: np.ndarray, fine: int = 4096) -> float:
    """Half the peak-to-peak of one period of samples, band-limited-interpolated between them."""
    y = np.fft.irfft(np.fft.rfft(x), fine) * (fine / x.size)
    return 0.5 * float(y.max() - y.min())


def stepped(model, table_m: float, freqs_hz, x0=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state amplitude (half peak-to-peak of q2, m) at each frequency in order, and whether it
    settled within MAX_BLOCKS blocks. Each frequency starts at the table's phase 0, where the previous
    one ended (whole periods), so the drive's phase is continuous."""
    x = np.array(x0, float)
    amps, settled = [], []
    for f in freqs_hz:
        w = 2 * np.pi * f
        u = _fine_input(table_m, w)
        dt = 2 * np.pi / w / SAMPLES
        prev, ok = None, False
        for _ in range(MAX_BLOCKS):
            res = simulate(model, dt, x, inputs_fine=u, substeps=SUBSTEPS, n_samples=BLOCK * SAMPLES + 1, bound=10.0)
            assert not res.diverged, f"time integration diverged at {f} Hz"
            x = res.states[-1].copy()
            amp = half_peak_to_peak(res.states[-SAMPLES - 1:-1, 1])
            if prev is not None and abs(amp - prev) < STEADY * amp:
                ok = True
                break
            prev = amp
        amps.append(amp)
        settled.append(ok)
    return np.array(amps), np.array(settled)


def jump_between(freqs_hz, amps) -> tuple[float, float] | None:
    """The two frequencies between which the stepped response jumps (its amplitude changes by more than
    a factor 1.3 from one step to the next), or None."""
    ratio = np.asarray(amps[1:]) / np.asarray(amps[:-1])
    i = np.flatnonzero((ratio > 1.3) | (ratio < 1 / 1.3))
    return None if i.size == 0 else (float(freqs_hz[i[0]]), float(freqs_hz[i[0] + 1]))
