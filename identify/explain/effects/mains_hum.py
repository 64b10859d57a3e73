"""Mains hum: the supply's 50 or 60 Hz picked up by a channel, a_x = x'' + a cos(2 pi f t) + b sin(2 pi f t).

Inside the band of a fast-sampled sweep it reads as a misfit at f that no force on the mass can make
(the issue saw `unexplained`, gap 8-16x the floor, at 1-5 % of a channel). Each channel's amplitude at
f is its least-squares projection over the whole record (the sweep's own harmonics pass f for a moment,
the hum is there all the time), the channels corrected (identify.explain.measurement.ChannelChain.hum) and the
corrected model compared on the shooting error like any candidate. The evidence asked of it is a
physical name's: a test of its own (is there more power at f than at the frequencies around it: an F
test of the 2 x channels projection coefficients against REFERENCE_OFFSETS_HZ neighbours, its p held
to the analysis' alpha as a Wald p is), then the same share of the gap closed and the same bootstrap.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import stats

from .base import Candidate, Effect

#: The mains frequencies looked at.
MAINS_HZ = (50.0, 60.0)
#: Neighbours a hum frequency's power is compared with (Hz from it, both sides): clear of it by more than
#: the resolution of any record of a few seconds, close enough to see the same sweep harmonics.
REFERENCE_OFFSETS_HZ = tuple(0.5 * k for k in range(2, 12))


def _projection(x: np.ndarray, t: np.ndarray, hz: float) -> np.ndarray:
    """(cos, sin) least-squares amplitudes of x at hz over the record."""
    A = np.column_stack([np.cos(2 * np.pi * hz * t), np.sin(2 * np.pi * hz * t)])
    return np.linalg.lstsq(A, x, rcond=None)[0]


class MainsHum(Effect):
    name, unit = "mains_hum", "m/s^2"
    description = "mains hum: the supply's 50 or 60 Hz picked up by an accelerometer channel"
    kind, plain = "measurement", False

    def evidence(self, rec) -> dict:
        """The mains frequency with the most power in the channels: its amplitudes and the p-value of its
        power against the neighbours' (F test)."""
        t = np.arange(rec.n_samples) / rec.fs_hz
        chans = {"mass": rec.output - rec.output.mean(), "table": rec.input - rec.input.mean()}
        best = None
        for hz in MAINS_HZ:
            if not hz < 0.5 * rec.fs_hz - max(REFERENCE_OFFSETS_HZ):
                continue
            amp = {c: _projection(x, t, hz) for c, x in chans.items()}
            power = sum(float(a @ a) for a in amp.values())
            ref = [sum(float(np.sum(_projection(x, t, hz + s * d) ** 2)) for x in chans.values())
                   for d in REFERENCE_OFFSETS_HZ for s in (-1, 1)]
            dof = 2 * len(chans)
            f_stat = (power / dof) / (np.mean(ref) / dof) if np.mean(ref) > 0 else np.inf
            p = float(stats.f.sf(f_stat, dof, dof * len(ref)))
            if best is None or power > best["power"]:
                best = {"hz": hz, "amp": amp, "power": power, "p_value": p}
        return best

    def propose(self, fitter, cur):
        """Over one recording only: the hum's phase is each recording's own (its clock starts anywhere in
        the supply's cycle), while a structure's fault parameters are one set for all recordings."""
        if self.name in cur.effects or fitter.chain is None or len(fitter.parts) > 1:
            return None
        ev = fitter.memo.get(self.name, fitter.memo)  # the memo itself: not looked at yet (None: no hum)
        if ev is fitter.memo:  # (read once: the rounds' proposals run in threads, identify.threads.map_runs)
            ev = fitter.memo[self.name] = self.evidence(fitter.parts[0].rec)
        if ev is None:
            return None
        p = dict(cur.meas)
        p["hum_hz"] = ev["hz"]
        for c, (a, b) in ev["amp"].items():
            p[f"hum_{c}_cos"], p[f"hum_{c}_sin"] = float(a), float(b)
        st = cur.adding(self.name, (), meas=tuple(sorted(p.items())))
        fit = fitter.equation_fit(st)
        extra = {"hum_hz": ev["hz"], **{f"hum_{c}_ms2": float(np.hypot(*a)) for c, a in ev["amp"].items()}}
        return Candidate(self.name, "measurement", [], replace(st, coef=tuple(fit.coef.items())), fit, None,
                         ev["p_value"], extra)
