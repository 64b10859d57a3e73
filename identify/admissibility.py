"""Admissibility: a candidate explanation the physics or the data rule out is not offered, however well
it fits.

1. Dissipative terms must dissipate: Coulomb friction, quadratic and cubic damping take coefficients in
   dq1/dt of the sign that opposes the motion (negative); a positive one injects energy (seen: a 1 ms
   channel delay fitted as quadratic damping with a positive coefficient, confidence 0.89). End stops
   and hysteresis must restore (pull back), on each side.
   An end stop is a contact stiffer than the spring it stops: its stiffer side's contact stiffness must
   exceed the rig's own linear stiffness -coef(q2) (both per kg). A softer one is a stiffness change
   beyond the travel, which the stiffness effects describe (seen: after a 5 % stiffness drift was named,
   a one-sided `end_stop` of 6.4 N/m per kg on a rig of 1894 took 38 % of a gap at 1.2x the noise floor,
   confidence 0.95; the suite's stops, sim.scenarios, are 2-10x the secant stiffness).
2. A fix must not flip the sign of a well-determined baseline coefficient (|value| > SIGN_Z standard
   errors of the baseline's own fit): a term that only fits by turning the hardening spring into a
   softening one (seen: q2^3 = +1.16e6 against the truth's -2.18e6 after adding Coulomb friction) is
   trading one error for another, not explaining the data.
3. Measurement parameters stay within their search bounds (identify.measurement.PARAMS) by construction.

The sign rules are statistical: a coefficient (or a side's sum of two) on the wrong side of zero is a
violation only when it is more than SIGN_Z_WRONG standard errors from zero (the candidate's own fit,
`se`). A coefficient within its uncertainty of zero is zero, not a violation (seen: end stops whose
shooting refit found the travel within 3 % and closed 95-99 % of the gap, rejected for a contact damping
of +0.02 to +0.1 that was statistically zero, or for "pushing outwards" by a hair on one side).
"""
from __future__ import annotations

import numpy as np

from .effects import CATALOG

#: A baseline coefficient is well determined when |value| exceeds this many standard errors.
SIGN_Z = 4.0
#: Relative tolerance on a restoring/dissipating sign (numerical zero).
SIGN_TOL = 1e-9
#: A coefficient of the wrong sign is a violation only beyond this many of its standard errors from zero.
SIGN_Z_WRONG = 2.0


def _wrong_side(value: float, scale: float, se: float) -> bool:
    """`value` > 0 beyond numerical zero (relative to `scale`) and beyond SIGN_Z_WRONG x `se`."""
    return value > SIGN_TOL * scale and value > SIGN_Z_WRONG * se


def _sides(coef: dict, se: dict, sym: str, asym: str):
    """Per side (upper, lower) of an end stop: (coefficient, scale, standard error) of sym +- asym."""
    c1, c2 = coef.get(sym, 0.0), coef.get(asym, 0.0)
    s = float(np.hypot(se.get(sym, 0.0), se.get(asym, 0.0)))
    return [(c1 + c2, abs(c1) + abs(c2), s), (c1 - c2, abs(c1) + abs(c2), s)]


def check(name: str, coef: dict, baseline_coef: dict, baseline_se: dict, se: dict | None = None) -> str:
    """'' when admissible, else the reason (one sentence). `se`: the candidate's standard errors (none
    given: every sign is taken at face value)."""
    se = se or {}
    effect = CATALOG.get(name)
    if effect is not None and effect.kind == "physics":
        if effect.dissipative:
            for t in effect.terms:
                if _wrong_side(coef.get(t, 0.0), 0.0, se.get(t, 0.0)):
                    return f"{t} has coefficient {coef[t]:+.4g} in dq1/dt: it injects energy instead of dissipating it"
        if name == "end_stop":
            if any(_wrong_side(*v) for v in _sides(coef, se, "stop(q2)", "sign(q2)*stop(q2)")):
                return "the end stop pushes the mass outwards on one side instead of stopping it"
            if any(_wrong_side(*v) for v in _sides(coef, se, "q1*contact(q2)", "q1*sign(q2)*contact(q2)")):
                return "the end stop's contact damping injects energy on one side instead of dissipating it"
            c1, c2 = coef.get("stop(q2)", 0.0), coef.get("sign(q2)*stop(q2)", 0.0)
            k, contact = -coef.get("q2", 0.0), max(-(c1 + c2), -(c1 - c2))
            if k > 0 and contact < k:
                return (f"its contact ({contact:.4g} N/m per kg on its stiffer side) is softer than the rig's own "
                        f"spring ({k:.4g}): a stiffness change beyond the travel, not a stop")
        if name == "hysteresis" and _wrong_side(coef.get("z", 0.0), 0.0, se.get("z", 0.0)):
            return "the hysteretic force pushes along the displacement instead of restoring"
    for t, c0 in baseline_coef.items():
        s0 = baseline_se.get(t)
        c = coef.get(t)
        if c is None or s0 is None or not s0 > 0:
            continue
        if abs(c0) > SIGN_Z * s0 and c * c0 < 0:
            return (f"it flips the sign of the baseline's {t} ({c0:+.4g}, {abs(c0) / s0:.0f} standard errors) "
                    f"to {c:+.4g}")
    return ""
