"""Report of the discrepancy workflow (`shakeid explain --report DIR`): where the baseline misses, what was
named, the gap before and after. A folder with its own page:

    index.html            the answer, the gap, the named effects and every candidate as numbered tables,
                          the figures with captions under them
    residual_time.png     residual RMS along the record, with the excitation frequency
    residual_state.png    mean residual over displacement x velocity, and against velocity
    candidates.png        each effect (first round): held-out equation-error share explained, shooting gap closed
    gap.png               free-run simulation before and after on the held-out block with most error, with
                          the residuals (measured - simulated) of both
    explain.json          the `shakeid explain --json` document
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .frf_overlay import OVERLAY_FIGURE, add_side_by_side, overlay_figure
from .html import EXPLAIN_DOCUMENTS, EXPLAIN_FIGURES, Page, report_folder
from .identification import RESIDUAL, _save, plt
from .text import gap_closed_text, p_value_text

FIGURES, DOCUMENTS = EXPLAIN_FIGURES, EXPLAIN_DOCUMENTS
CLIP = -0.5  # candidates.png: shooting-gap bars below this are drawn cut here, their value written on them


def write_explain_report(analysis, out_dir, frf: dict | None = None) -> Path:
    """Write the report of a fitted DiscrepancyAnalysis into `out_dir` (created; an earlier explain
    report there is replaced, none of its files left behind; a folder holding anything else is refused:
    html.check_report_folder). Returns the folder. `frf`: the frequency response before/after beside the
    measured sweep (identify.frf.side_by_side.for_explanation), carried into explain.json and drawn."""
    out = report_folder(out_dir, "explain")
    result = analysis.result()
    if frf is not None:
        result["frf"] = frf
        if frf.get("status") == "ok":
            overlay_figure(frf, out / OVERLAY_FIGURE)
    (out / "explain.json").write_text(json.dumps(result, indent=2))
    base = analysis.layout_ == "base"
    u = "m/s²" if base else ""
    loc = analysis.localisation_

    w = loc["time"]["windows"]
    t = [0.5 * (x["t_start_s"] + x["t_end_s"]) for x in w]
    fig, ax = plt.subplots(figsize=(9, 3.4))
    lines = ax.plot(t, [x["residual_rms"] for x in w], "o-", ms=3, label="baseline residual RMS (left axis)")
    ax.set(xlabel="time (s)", ylabel=f"residual RMS ({u})" if u else "residual RMS",
           title="Where the baseline misses: along the record")
    ax2 = ax.twinx()
    lines += ax2.plot(t, [x["excitation_hz"] for x in w], color="0.6", lw=1, label="excitation frequency (right axis)")
    ax2.set_ylabel("excitation (Hz)", color="0.4")
    ax.legend(lines, [ln.get_label() for ln in lines], fontsize=8, ncol=2, loc="upper center",
              bbox_to_anchor=(0.5, -0.22), frameon=False)
    _save(fig, out / "residual_time.png")

    st = loc["state"]
    mean = np.array([[np.nan if v is None else v for v in row] for row in st["mean_residual"]])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    e2, e1 = np.array(st["q2_edges_m"]) * 1e3, np.array(st["q1_edges_ms"])
    lim = np.nanmax(np.abs(mean)) if np.isfinite(mean).any() else 1.0
    im = axes[0].pcolormesh(e1, e2, mean, cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=axes[0], label=f"mean residual ({u})" if u else "mean residual")
    axes[0].set(xlabel="velocity q1 (m/s)", ylabel="displacement q2 (mm)", title="Residual over the state space")
    sigv = st["velocity_signature"]
    axes[1].plot(sigv["q1_centres_ms"], [np.nan if v is None else v for v in sigv["mean_residual"]], "o-")
    axes[1].axhline(0, color="0.7", lw=0.8)
    axes[1].set(xlabel="velocity q1 (m/s)", ylabel=f"mean residual ({u})" if u else "mean residual",
                title="Signature against velocity (a step at 0: friction)")
    _save(fig, out / "residual_state.png")

    _candidates_figure(analysis, result, out / "candidates.png")
    _gap_figure(analysis, result, out / "gap.png", u)
    (out / "index.html").write_text(_index_html(out, analysis, result, u))
    return out


def _candidates_figure(analysis, result, path):
    cands = result["candidates"]
    fig, ax = plt.subplots(figsize=(10, 4))
    x = np.arange(len(cands))
    closed = [c.get("gap_share_closed") or 0.0 for c in cands]
    ax.bar(x - 0.2, [c["score"] for c in cands], 0.4, label="equation-error share explained (held-out)")
    bars = ax.bar(x + 0.2, [max(v, CLIP) for v in closed], 0.4, label="shooting gap closed (held-out)")
    for bar, v in zip(bars, closed):
        if v < CLIP:  # cut at the axis: its value written on it
            ax.annotate(gap_closed_text(v), (bar.get_x() + bar.get_width() / 2, CLIP), xytext=(0, 3),
                        textcoords="offset points", ha="center", fontsize=7, rotation=90, va="bottom")
    ax.set_xticks(x, [c["name"].replace("_", " ") for c in cands], fontsize=8, rotation=35, ha="right")
    ax.axhline(analysis.min_gap_closed, color="r", lw=0.8, ls="--", label="naming threshold")
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set(ylim=(CLIP - 0.05, 1.05), ylabel="share (1 = all of it)",
           title=f"Named: {result['effect']} (confidence {result['confidence']:.2f})")
    ax.set_xlabel("candidate effect (first round)")
    ax.legend(fontsize=7, loc="upper right")
    _save(fig, path)


def _gap_figure(analysis, result, path, u):
    """The held-out second around the largest baseline error: measurement, baseline and fixed model's
    free runs, and below them the residuals (measured − simulated) of both."""
    meas = analysis.gap_measured_
    held = analysis.heldout_rows_
    idx = np.flatnonzero(held)
    err = np.abs(np.nan_to_num(analysis.sim_before_qdot_, nan=np.inf) - meas)
    centre = idx[np.nanargmax(err[idx])] if idx.size else int(np.nanargmax(err))
    part = analysis.fitter_.part_of(centre)  # several recordings: the second shown is within one of them
    sig = part.sig
    v = sig.valid
    half = int(sig.fs_hz)
    z = slice(max(centre - half, part.offset), min(centre + half, part.offset + part.n))
    tt = (np.arange(v.start, v.stop) / sig.fs_hz)[z.start - part.offset:z.stop - part.offset]
    ylabel = "relative acceleration (m/s²)" if u else "y"
    after = "+ " + ", ".join(e["name"] for e in result["effects"]) if result["effects"] else None
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(10, 6), gridspec_kw={"height_ratios": [2, 1.2]})
    ax.plot(tt, meas[z], lw=1.6, color="0.2", label="measured")
    ax.plot(tt, analysis.sim_before_qdot_[z], lw=0.9, ls="--", label="baseline")
    axr.plot(tt, meas[z] - analysis.sim_before_qdot_[z], lw=0.8, ls="--", label="measured − baseline")
    if after:  # the fixed model's free run, as the analysis simulated it
        ax.plot(tt, analysis.sim_after_qdot_[z], lw=0.9, label=after)
        axr.plot(tt, meas[z] - analysis.sim_after_qdot_[z], lw=0.8, color=RESIDUAL, label=f"measured − ({after})")
    axr.axhline(0, color="0.6", lw=0.6)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.3 * (hi - lo))  # room for the legend above the data
    where = f" ({part.rec.source})" if len(analysis.fitter_.parts) > 1 else ""
    ax.set(xlabel="time (s)", ylabel=ylabel, title=f"Free run on held-out samples{where}: before and after")
    axr.set(xlabel="time (s)", ylabel=f"residual ({u})" if u else "residual", title="Residuals (own scale)")
    ax.legend(fontsize=8, loc="upper left", ncol=3)
    axr.legend(fontsize=8, loc="upper left", ncol=2)
    _save(fig, path)


def _f(v, fmt=".4f") -> str:
    return "-" if v is None else format(v, fmt)


def _index_html(out: Path, analysis, result: dict, u: str) -> str:
    """The report's index page: the answer, the gap, what was added, every candidate, where the model
    misses, the figures, and the frequency response beside the measured sweep."""
    page = Page("Discrepancy report: where the model misses the rig", "explain")
    _answer(page, result)
    _gap_table(page, result, u)
    _effects(page, result)
    _candidates(page, analysis, result)
    _where(page, result)
    _figures(page, out, u)
    if "frf" in result:  # after the figures the text numbers
        add_side_by_side(page, result["frf"], OVERLAY_FIGURE if (out / OVERLAY_FIGURE).exists() else None,
                         "Frequency response before and after, beside the measured sweep")
    page.links([("explain.json", "explain.json (the whole result)")])
    return page.render()


def _answer(page: Page, result: dict) -> None:
    """The answer in words and, for several recordings, each one's own gap."""
    effect = result["effect"]
    answer = {"none": "nothing is missing: the baseline's gap is within the sensor-noise floor",
              "unexplained": "something is missing, but no effect of the catalog closes enough of the gap"}
    page.paragraph(f"Answer: {answer.get(effect, 'missing effect: ' + effect)} (confidence "
                   f"{result['confidence']:.2f}). Baseline: {result['baseline']['source']}.")
    if len(result["recordings"]) > 1:
        page.table(["recording", "duration (s)", "sweep vs time", "gap before", "gap after", "its noise floor"],
                   [[r["source"], f"{r['duration_s']:.1f}", f"{r['sweep_rho']:+.2f}", _f(r["gap_before"]),
                     _f(r["gap_after"]), _f(r["noise_floor"])] for r in result["recordings"]],
                   "The recordings explained together: one explanation, its errors pooled over all of them. Sweep "
                   "vs time: the rank correlation of the excitation frequency with time (+1 an up-sweep, -1 a "
                   "down-sweep); each recording's own held-out gap before and after.")


def _gap_table(page: Page, result: dict, u: str) -> None:
    """The gap before and after, beside the free-run fit and the noise floor."""
    floor = result.get("noise_floor")
    page.table(["quantity", "before (baseline)", "after"], [
        ["gap: " + result["metric"], _f(result["gap_before"]), _f(result["gap_after"])],
        ["free-run fit of the acceleration, held-out" if u else "free-run fit, held-out",
         *[_fit(result["validation"][k]) for k in ("before", "after")]],
        ["sensor-noise floor of the gap (upper bound)", _f(floor), _f(floor)],
        ["share of the gap closed", "", "-" if result["gap_closed"] is None else f"{100 * result['gap_closed']:.0f} %"],
    ], "The gap is the held-out multiple-shooting NRMSE: short free runs restarted from the measured state, "
       "error RMS over the measurement's standard deviation, on samples not used for fitting. A gap near the "
       "noise floor is all the sensors allow; the free-run fit simulates the whole record from its start.")


def _effects(page: Page, result: dict) -> None:
    """The effects added, in order, with their coefficients and confidence."""
    if result["effects"]:
        page.heading("Effects added")
        rows = [[e["name"], e["kind"], ", ".join(f"{t}: {c:.4g}" if isinstance(c, (int, float)) else f"{t}: {c}"
                                                 for t, c in e["coefficients"].items()) or e.get("note", "-"),
                 f"{e['confidence']:.2f}", _f(e["gap_after"]), ", ".join(e["surrogate_for"]) or "-"]
                for e in result["effects"]]
        page.table(["effect", "kind", "coefficients (q1_dot, SI)", "confidence", "gap after", "stands in for"],
                   rows, "The effects added to the baseline, in order, each on top of those before it. Physics "
                         "terms are forces per unit mass in the q1_dot equation; measurement effects (sensor "
                         "gain, delay, drift) change the chain instead. Confidence: (1 − p) × the bootstrap "
                         "probability that the effect beats both the runner-up and the explanation before it.")


def _candidates(page: Page, analysis, result: dict) -> None:
    """Every candidate of the first round and why it was not named."""
    page.heading("Every candidate (first round)")
    crow = [[c["name"], c["kind"], f"{c['score']:+.3f}",
             p_value_text(c["p_value"]),
             "-" if c.get("gap_share_closed") is None else gap_closed_text(c["gap_share_closed"]),
             c.get("rejected") or ("named" if c["name"] in {e["name"] for e in result["effects"]} else "")]
            for c in result["candidates"]]
    page.table(["candidate", "kind", "equation-error share", "p", "shooting gap closed", "rejected because"],
               crow, f"Each catalog effect fitted on top of the baseline: the share of the held-out equation error "
                     f"it explains, p: the Wald p of its terms (a measurement fault: its own test), and "
                     f"the share of the held-out squared shooting error it removes; an effect is named when that "
                     f"share is at least {analysis.min_gap_closed:g} and no rule (energy, direction, "
                     f"significance) rejects it.")


def _where(page: Page, result: dict) -> None:
    """Where along the record the model misses most, before and after."""
    worst = result["localisation"]["time"]["worst_window"]
    rows = [["largest misfit, baseline", f"t = {worst['t_start_s']:.1f}-{worst['t_end_s']:.1f} s",
             f"excitation {worst['excitation_hz']:.1f} Hz"]]
    if result.get("remaining"):
        top = result["remaining"]["segments"][0]
        rows.append(["largest misfit, after", f"t = {top['t_start_s']:.1f}-{top['t_end_s']:.1f} s",
                     f"excitation {top['excitation_hz']:.1f} Hz, {100 * top['share_of_error']:.0f} % of the error"])
    page.table(["where", "time", "what the table did"], rows,
               "Where along the record the model misses most (Figure 1).")


def _figures(page: Page, out: Path, u: str) -> None:
    """The figures written to `out`, each with its caption."""
    page.heading("Figures")
    captions = {
        "residual_time.png": "The baseline's equation residual RMS in windows along the record (left axis"
                             + (", m/s²" if u else "") + ") and the sweep's excitation frequency in each window "
                             "(right axis): a misfit at one frequency points to a resonance, one growing with "
                             "amplitude to a stiffness or damping term.",
        "residual_state.png": "Left: the baseline's mean residual over the state space (velocity × displacement). "
                              "Right: the mean residual against velocity alone; a step at zero velocity is the "
                              "signature of dry (Coulomb) friction, a curve growing with |velocity| of nonlinear "
                              "damping.",
        "candidates.png": "Each candidate of the first round: the held-out equation-error share it explains (blue) "
                          "and the share of the held-out shooting gap it closes (orange); red dashed: the share "
                          f"needed to name it. Bars below {CLIP:g} are cut there, their value written on them.",
        "gap.png": "Free runs on the held-out second around the baseline's largest error: the measurement, the "
                   "baseline and the baseline with the named effects; below, each one's residual (measured − "
                   "simulated) on its own scale.",
    }
    for f in FIGURES:
        if (out / f).exists():
            page.figure(f, captions[f])


def _fit(validation: dict | None) -> str:
    q = ((validation or {}).get("heldout") or {}).get("q1_dot") or {}
    return "-" if q.get("fit_percent") is None else f"{q['fit_percent']:.2f} %"
