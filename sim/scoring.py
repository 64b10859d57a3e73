"""Whether a discrepancy answer is right for a scenario with known truth (sim/scenarios.py): the contract's
rules, which benchmarks/explain_robustness.py counts (docs in benchmarks/README.md, "Scoring")."""
from __future__ import annotations

from identify.explain.workflow import DiscrepancyAnalysis

from .scenarios import OUT_OF_CATALOG, SURROGATE_GROUPS

#: The analysis' own none_factor, for results stored without their thresholds.
DEFAULT_NONE_FACTOR = DiscrepancyAnalysis().none_factor

#: Share of the gap (NRMSE) a single effect or an out-of-catalog surrogate must close to be right, unless it
#: takes the gap down to the noise floor (gap_closed_enough).
CLOSED_SHARE = 0.5
#: Measurement faults one record cannot tell apart. A base-excited record shows only the ratio of the two
#: accelerometers' gains: scaling both channels by one factor scales every state and the input alike,
#: which the model absorbs (its cubic coefficient by the factor squared). explain reports the gain on the
#: mass channel with the table gain as its `surrogate_for` (and the equivalent table value); naming the
#: one for the other is right, as a sensor check of either channel would find the fault.
MEASUREMENT_EQUIVALENT = {"mass_acc_gain": ("table_acc_gain",), "table_acc_gain": ("mass_acc_gain",)}


def result_effects(result: dict) -> list[dict]:
    """The `effects` list of a DiscrepancyAnalysis result; a result without one (before issue 12) is
    read as one physics entry for its `effect` (none when the effect is none or unexplained)."""
    if "effects" in result and result["effects"] is not None:
        return [{"kind": "physics", "surrogate_for": [], **e} for e in result["effects"]]
    if result.get("effect") in (None, "none", "unexplained"):
        return []
    return [{"name": result["effect"], "kind": "physics", "confidence": result.get("confidence") or 0.0,
             "surrogate_for": []}]


def wrong_physical_names(truth_effects: list[str], effects: list[dict], min_confidence: float = 0.5) -> list[str]:
    """Physics entries named with confidence >= min_confidence that are neither a truth effect, nor in a
    truth effect's surrogate group, nor flagged as standing in for one (surrogate_for naming a truth
    effect; for out-of-catalog truth any non-empty surrogate_for)."""
    allowed = set(truth_effects)
    for t in truth_effects:
        allowed |= set(SURROGATE_GROUPS.get(t, ()))
    outside = any(t in OUT_OF_CATALOG for t in truth_effects)
    wrong = []
    for e in effects:
        if e.get("kind", "physics") != "physics" or (e.get("confidence") or 0.0) < min_confidence:
            continue
        flagged = set(e.get("surrogate_for") or ())
        if e["name"] in allowed or flagged & set(truth_effects) or (outside and flagged):
            continue
        wrong.append(e["name"])
    return wrong


def is_nuisance(entry: dict, nuisances) -> bool:
    """Whether a measurement entry names one of the recording's nuisances (sim.wide.NUISANCE_NAMES kinds:
    "hum" as any name with hum or mains in it, "quantisation" as any with quanti in it)."""
    if entry.get("kind") != "measurement":
        return False
    name = entry["name"].lower()
    return (("hum" in nuisances and ("hum" in name or "mains" in name))
            or ("quantisation" in nuisances and "quanti" in name))


def spurious_measurement_names(truth_effects: list[str], effects: list[dict], nuisances=(),
                               min_confidence: float = 0.5) -> list[str]:
    """Measurement entries named with confidence >= min_confidence where no such fault exists: neither a
    truth fault (nor its MEASUREMENT_EQUIVALENT) nor one of the recording's nuisances."""
    allowed = set(truth_effects) | {q for t in truth_effects for q in MEASUREMENT_EQUIVALENT.get(t, ())}
    return [e["name"] for e in effects if e.get("kind") == "measurement"
            and (e.get("confidence") or 0.0) >= min_confidence and e["name"] not in allowed
            and not is_nuisance(e, nuisances)]


def gap_closed_enough(result: dict) -> bool:
    """Whether a single effect's or a surrogate's explanation closed the gap: CLOSED_SHARE of it at least,
    or down to the sensor-noise floor (gap_after <= noise_floor), below which no model goes: a gap within
    twice the floor cannot be halved (seed 3145012448: the right effect named, gap_closed 0.23-0.49)."""
    closed, after, floor = result.get("gap_closed"), result.get("gap_after"), result.get("noise_floor")
    return (closed is not None and closed >= CLOSED_SHARE) or (
        closed is not None and closed > 0 and after is not None and floor is not None and after <= floor)


def after_nuisances(result: dict) -> str:
    """The answer when only nuisances were named: `unexplained` if the gap they leave is still above the
    analysis' none_factor x the noise floor (something else is missing), else `none`. A result without
    its thresholds (stored before they were kept) is read with the analysis' default none_factor."""
    after, floor = result.get("gap_after"), result.get("noise_floor")
    if after is None or floor is None:
        return "none"
    factor = (result.get("thresholds") or {}).get("none_factor", DEFAULT_NONE_FACTOR)
    return "unexplained" if after > factor * floor else "none"


def score(category: str, truth_effects: list[str], result: dict, nuisances=()) -> dict:
    """Whether a result is right for the scenario (contract rules), its wrong physical names and its
    measurement names where no fault exists. `nuisances` (sim.wide: "hum", "quantisation") are measurement
    effects the recording has besides the truth: entries naming them are passed over, not judged."""
    all_effects = result_effects(result)
    effects = [e for e in all_effects if not is_nuisance(e, nuisances)]
    if result.get("effect") not in ("none", "unexplained") and all_effects and not effects:
        result = {**result, "effect": after_nuisances(result)}  # only nuisances named: judged on what is left
    names = [e["name"] for e in effects]
    closed_enough = gap_closed_enough(result)
    wrong = wrong_physical_names(truth_effects, effects)
    if category == "none":
        right = result.get("effect") == "none"
    elif category == "single":
        right = bool(names) and names[0] == truth_effects[0] and closed_enough
    elif category == "two_effects":
        right = all(t in names for t in truth_effects) and not wrong
    elif category == "sensor_fault":
        right = bool(names) and (names[0] == truth_effects[0] or (
            names[0] in MEASUREMENT_EQUIVALENT.get(truth_effects[0], ())
            and truth_effects[0] in (effects[0].get("surrogate_for") or ())))
    elif category == "out_of_catalog":
        right = result.get("effect") == "unexplained" or (bool(effects) and bool(effects[0].get("surrogate_for"))
                                                          and closed_enough)
    else:
        raise ValueError(f"unknown category {category!r}")
    return {"right": bool(right), "wrong_names": wrong, "names": names,
            "spurious_measurement": spurious_measurement_names(truth_effects, all_effects, nuisances)}
