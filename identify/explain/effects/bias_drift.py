"""Bias drift: a sensor bias that drifts linearly over the record (m/s^2 from start to end).

The band-limited chain removes it before any gap is measured, so as a round's candidate it could only fit
something else (in_rounds False; its channel search stays for a catalog that asks for it). It is looked
for in the raw channels below the band (identify.explain.drift) after the rounds, listed after whatever closed
the gap, and is the answer when nothing else was (`none` becomes `bias_drift`). The simulator makes it
with sim.sensors.Accelerometer(bias_drift_ms2=...).
"""
from __future__ import annotations

from ..drift import T_REPORT, bias_trends
from .faults import ChannelFault


class BiasDrift(ChannelFault):
    name, unit = "bias_drift", "m/s^2"
    description = "a sensor bias drifting linearly over the record (change from start to end)"
    params = ("bias_drift_mass", "bias_drift_table")
    in_rounds = False

    def after_rounds(self, analysis, recording, sig) -> list[dict]:
        """Report entries of the drifts found in the raw channels (none when one was named in a round)."""
        analysis.bias_trends_ = bias_trends(recording, sig)
        if any(e["name"] == self.name for e in analysis.effects_):
            return []
        return [{"name": self.name, "kind": self.kind, "terms": [],
                 "coefficients": {f"bias_drift_{d['channel']}": d["change_ms2"]},
                 "confidence": float(1 - d["p_value"]), "gap_after": analysis.gap_after_,
                 "gap_closed": 0.0, "gap_share_closed": 0.0, "surrogate_for": [], "p_value": d["p_value"],
                 "evidence": (f"the {d['channel']} accelerometer's mean below the band moves by "
                              f"{d['change_ms2']:+.4f} +- {d['se_ms2']:.4f} m/s^2 over the record "
                              f"(t = {d['t']:.1f}); the chain removes it, so the gap does not show it")}
                for d in analysis.bias_trends_ if abs(d["t"]) >= T_REPORT]
