"""Identification results as plain text: the coefficient table (Markdown, the paper's Table 1 layout),
the physical parameters and the summary `shakeid identify` prints. No plotting here, so the terminal
summary does not import matplotlib."""
from __future__ import annotations

#: what the design value of k3 is, said wherever it is printed beside the identified one
DESIGN_K3_NOTE = ("design k3 = 4 k_l a²: what the rig's linear springs (k_l each) on the cam profile "
                  "f(x) = a x² + b give on paper (identify/physical.py); the identified k3 is what the rig "
                  "has, so a difference means the springs or the profile differ from the drawing")


def gap_closed_text(share: float | None) -> str:
    """An effect's "shooting gap closed" (1 - gap_after^2 / gap_before^2) as a person reads it: the share
    while it is one (+0.98, -0.84), and past -1, where the candidate made the gap itself several times
    larger (a short record's diverging fit gave -112290.81), by that factor: "worse: gap x335"."""
    if share is None:
        return "n/a"
    if share >= -1.0:
        return f"{share:+.2f}"
    return f"worse: gap x{(1.0 - share) ** 0.5:.3g}"


#: Below this a Wald p is printed as a bound: its tail rests on the Gaussian approximation, so "p = 0.0e+00"
#: (an underflow) or 1e-200 would claim a precision no test has.
P_FLOOR = 1e-10


def p_value_text(p: float | None) -> str:
    """A Wald p as printed: 3.2e-02, or "< 1e-10" for anything smaller (0 included)."""
    if p is None:
        return "n/a"
    return f"< {P_FLOOR:.0e}" if p < P_FLOOR else f"{p:.1e}"


def mass_text(phys: dict) -> str:
    """The moving mass the physical parameters are scaled by, and where it came from: every force is the
    mass times a fitted acceleration, so an assumed mass that is not the rig's scales them all."""
    m = phys.get("mass_kg")
    where = {"given": "given, --mass-kg", "recording": "the recording's rig configuration",
             "assumed": "assumed: the default; give the rig's with --mass-kg"}.get(phys.get("mass_source"), "given")
    return f"m = {m:g} kg, {where}"


def unit(text: str) -> str:
    """A unit as printed: 'm/s^2' -> 'm/s²', 'N/m^3' -> 'N/m³' (the recordings store ASCII units)."""
    return text.replace("^2", "²").replace("^3", "³")


def plural(n: int, word: str) -> str:
    """'1 term', '5 terms', '0 terms'."""
    return f"{n} {word}" + ("" if n == 1 else "s")


def coefficient_rows(result: dict) -> tuple[list[str], list[list[str]]]:
    """(headers, rows) in the layout of the paper's Table 1: every library term, its coefficient per
    equation (0 when not selected) ± its standard error ("(exact)" for an equation that holds by
    construction, q2_dot = q1), then per equation the term's inclusion
    probability: the share of random held-out placements whose selection kept it."""
    model, se = result["model"], result.get("standard_errors", {})
    exact = (result.get("uncertainty") or {}).get("exact") or {}  # equations that hold by construction
    p_in = result.get("inclusion_probability") or {}
    eqs = list(model)
    headers = ["term"] + eqs + [f"P(kept) {eq}" for eq in eqs if eq in p_in]
    rows = []
    for term in result["library"]["terms"]:
        cells = [term]
        for eq in eqs:
            c = model[eq].get(term)
            if c is None:
                cells.append("0")
            else:
                s = se.get(eq, {}).get(term)
                cells.append(f"{c:.5g}" + (" (exact)" if eq in exact and s == 0 else f" ± {s:.2g}" if s else ""))
        cells += [f"{p_in[eq].get(term, 0.0):.2f}" for eq in eqs if eq in p_in]
        rows.append(cells)
    return headers, rows


def coefficient_table(result: dict) -> str:
    """coefficient_rows as a Markdown table (coefficients.md, the terminal summary)."""
    headers, rows = coefficient_rows(result)
    lines = ["| " + " | ".join(headers) + " |", "|---|" + "---:|" * (len(headers) - 1)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


#: (key in result["physical"], name, unit, scale from SI to the unit shown)
PHYSICAL = (("damping_ns_per_m", "damping c", "N s/m", 1.0), ("stiffness_n_per_m", "stiffness k", "N/m", 1.0),
            ("cubic_stiffness_n_per_m3", "cubic stiffness k3", "N/m³", 1.0),
            ("prestress_b_m", "spring pre-stress b", "mm", 1e3))


def physical_rows(phys: dict) -> list[tuple[str, str, str, str]]:
    """(name, value, standard error, unit) per physical parameter, as text; 'term not in model' when the
    term that carries it was not kept."""
    rows = []
    for key, name, u, scale in PHYSICAL:
        v, s = phys[key]["value"], phys[key].get("std_error")
        rows.append((name, "term not in model" if v is None else f"{v * scale:.5g}",
                     "" if v is None or s is None else f"{s * scale:.2g}", u))
    return rows


def fit_text(metric: dict) -> str:
    """A free-run fit as printed: '99.80 %', or 'diverged' when the simulation left the data's range."""
    return "diverged" if metric.get("fit_percent") is None else f"{metric['fit_percent']:.2f} %"


def summary(result: dict, source: str) -> str:
    """What `shakeid identify` prints: the coefficient table, the held-out fit, the physical parameters."""
    lines = [f"identified {source}: method {result['method']}, selection {result['selection']['rule']}", ""]
    failed = result.get("status") == "failed"
    if failed:  # first, before any figure of the fit is read as the rig's
        lines += [f"MODEL FAILED: {result['reason']}",
                  "  (what follows is the fit that failed, not a model of the rig)", ""]
    if result.get("accepted_faulty"):
        lines += ["accepted faulty data (--accept-faulty): " + "; ".join(result["accepted_faulty"]), ""]
    lines.append(coefficient_table(result))
    lines += unsettled_lines(result)
    val = result.get("validation")
    if val:
        h = val["heldout"]
        how = (result.get("chain") or {}).get("holdout")
        lines.append(f"free-run fit on {val['heldout_samples']} held-out samples" + (f" ({how})" if how else "")
                     + f": acceleration {fit_text(h['q1_dot'])}, velocity {fit_text(h['q1'])}, displacement {fit_text(h['q2'])}")
    offset = result.get("chain", {}).get("displacement_below_band") or {}
    if offset.get("carried"):
        lines.append(f"displacement below the band carried (an even force rectifies it; the terms are those of the "
                     f"true displacement): rms {offset['rms_mm']:.3g} mm, {offset['min_mm']:.3g} to {offset['max_mm']:.3g} mm, "
                     f"{offset['passes']} passes{'' if offset['converged'] else ', NOT converged'}")
    phys = result.get("physical")
    if phys:
        lines.append(f"physical ({mass_text(phys)}): " + "; ".join(f"{name}: {v}" if v == "term not in model" else f"{name} = {v} {u}"
                                              for name, v, _, u in physical_rows(phys)))
        lines.append(f"  design k3 = {phys['design']['cubic_stiffness_n_per_m3']:.4g} N/m³, for comparison: what the "
                     "rig's springs and cam profile give on paper (identify/physical.py)")
    if failed:
        lines.append(f"MODEL FAILED: {result['reason']}")
    return "\n".join(lines)


def term_rules(result: dict) -> dict:
    """The bounds the result's terms were judged by, as the result states them (result["uncertainty"]
    ["term_rules"]: significant_z, min_inclusion_probability); a result written before it stated them gets
    identify.trust.uncertainty's constants, read when needed (this module loads no engine)."""
    rules = (result.get("uncertainty") or {}).get("term_rules")
    if rules:
        return rules
    from identify.trust import uncertainty

    return uncertainty.term_rules()


def _min_inclusion(result: dict) -> float:
    """The inclusion probability under which a kept term is unsettled (term_rules)."""
    return float(term_rules(result)["min_inclusion_probability"])


def _p_kept(p: float | None) -> str:
    """", P(kept) 0.58", or nothing where the inclusion probabilities were not computed (placements=0)."""
    return "" if p is None else f", P(kept) {p:.2f}"


def unsettled_lines(result: dict) -> list[str]:
    """The lines under the coefficient table of one recording's and of a joint fit's summary: the uncertain
    terms left out of the model (uncertain_terms), the terms the selection decided against most held-out
    placements (unsettled_terms), and the terms a free-run budget dropped (budget_dropped); or none."""
    lines = []
    uncertain = [(eq, term, u) for eq, terms in (result.get("uncertain_terms") or {}).items()
                 for term, u in terms.items()]
    if uncertain:
        lines.append(f"uncertain terms, left out of the model (within {term_rules(result)['significant_z']:g} "
                     "standard errors of zero): " + "; ".join(
                         f"{term} ({eq}) {u['coefficient']:.4g} ± {u['standard_error']:.2g}"
                         + _p_kept(u['inclusion_probability']) for eq, term, u in uncertain))
    unsettled = unsettled_terms(result)
    if unsettled:
        lines.append("unsettled selection: " + "; ".join(
            f"{term} ({eq}) {'kept' if kept else 'left out'} though P(kept) {p:.2f}" for eq, term, kept, p in unsettled)
            + ": the held-out placements disagree on these terms, so the model is not settled by this record "
              "(a longer sweep, or a stronger one, carries more of them)")
    dropped = budget_dropped(result)
    if dropped:
        lines.append(f"left out by the term budget (at most {result['selection']['max_terms']} terms, chosen by "
                     "free-run error): " + "; ".join(f"{term} (q1_dot, P(kept) {p:.2f} by the selection rule alone)"
                                                     for term, p in dropped))
    return lines


def _dropped_by_budget(result: dict) -> set:
    """q1_dot's terms a free-run budget left out: in the selection rule's support it chose from (its pool),
    not in the model. Empty without a free-run budget."""
    budget = result.get("budget") or {}
    return set(budget.get("pool", ())) - set(result["model"].get("q1_dot", {}))


def budget_dropped(result: dict) -> list[tuple[str, float]]:
    """(term, inclusion probability) of q1_dot's terms the selection rule keeps in most held-out placements
    but a free-run budget left out (the placements rerun the rule, not the budget, which runs once)."""
    probs = (result.get("inclusion_probability") or {}).get("q1_dot", {})
    dropped = _dropped_by_budget(result)
    return [(term, float(p)) for term, p in probs.items() if term in dropped and p >= _min_inclusion(result)]


def unsettled_terms(result: dict) -> list[tuple[str, str, bool, float]]:
    """(equation, term, kept, inclusion probability) of every term the selection decided against most of
    its held-out placements: kept with P(kept) < MIN_INCLUSION_PROBABILITY (0.5; kept since its coefficient is
    beyond SIGNIFICANT_Z standard errors, else it is an uncertain term, left out), or left out with P(kept) >= it
    (not a q1_dot term a free-run budget left out of the rule's choice: budget_dropped; not an uncertain term)."""
    out, dropped, p_min = [], _dropped_by_budget(result), _min_inclusion(result)
    uncertain = result.get("uncertain_terms") or {}
    for eq, probs in (result.get("inclusion_probability") or {}).items():
        model = result["model"].get(eq, {})
        for term, p in probs.items():
            kept = term in model
            if term in uncertain.get(eq, {}):
                continue
            if (kept and p < p_min) or (not kept and p >= p_min and not (eq == "q1_dot" and term in dropped)):
                out.append((eq, term, kept, float(p)))
    return out


def model_text(model: dict) -> str:
    """A model's equations on one line, coefficients to 5 significant digits: "q1_dot = -3.7291 q1 - 971.03
    q2 + ...; q2_dot = q1" (the JSON carries them in full)."""
    def term(k: int, name: str, c: float) -> str:
        sign = ("-" if c < 0 else "") if k == 0 else (" - " if c < 0 else " + ")
        return f"{sign}{name}" if abs(c) == 1 else f"{sign}{abs(c):.5g} {name}"
    return "; ".join(f"{eq} = " + ("".join(term(k, n, c) for k, (n, c) in enumerate(terms.items())) or "0")
                     for eq, terms in model.items())
