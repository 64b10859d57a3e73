"""Predicted frequency response beside the measured sweeps (identify.frf.side_by_side): the one overlay
figure and the one report section the identification report, the explain report and the service draw.

    overlay_figure(doc, "frf_overlay.png")   # one panel per table amplitude
    add_side_by_side(page, doc, "frf_overlay.png")   # heading, flags, the jump table, the figure
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .frf import COLOURS, _branch
from .html import OVERLAY_FIGURES, Page

OVERLAY_FIGURE = OVERLAY_FIGURES[0]
#: the panels show frequencies where a response exceeds this share of the panel's largest, widened
ZOOM_LEVEL, ZOOM_MARGIN = 0.25, 0.15
MEASURED_STYLE = {"up": ("^", "0.25"), "down": ("v", "0.55")}


def overlay_figure(doc: dict, path) -> None:
    """Per table amplitude a panel: each model's branches (stable solid, unstable dashed) and folds
    (circles), the band between its fold and fold + sweep-rate bias where a sweep should jump (shaded),
    each sweep's per-cycle envelope (triangles: up, down) and its measured jump (x with its uncertainty)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    amps = doc["amplitudes"]
    cols = min(len(amps), 3)
    rows = -(-len(amps) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(max(5.2 * cols, 8.0), 4.4 * rows + 0.9), dpi=110, squeeze=False)
    for ax, entry in zip(axes.flat, amps):
        _panel(ax, entry, doc)
    for ax in list(axes.flat)[len(amps):]:
        ax.set_visible(False)
    seen = {}
    for ax in axes.flat:  # one legend for all panels, below them, each entry once
        for h, label in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(label, h)
    ncol = 4 if cols > 1 else 3
    fig.tight_layout(rect=(0, (-(-len(seen) // ncol) * 0.25 + 0.1) / (4.4 * rows + 0.9), 1, 1))
    fig.legend(list(seen.values()), list(seen), fontsize=8, ncol=ncol, loc="lower center", frameon=False)
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")  # a reader (the service) sees no file or the whole PNG
    fig.savefig(tmp, format="png")
    plt.close(fig)
    os.replace(tmp, path)


def _panel(ax, entry: dict, doc: dict) -> None:
    for k, (label, r) in enumerate(entry["predicted"].items()):
        colour = COLOURS[k % len(COLOURS)]
        for b in r["branches"]:
            _branch(ax, np.array(b["frequency_hz"]), np.array(b["amplitude_mm"], float), np.array(b["stable"]), colour)
        for f in r["folds"]:
            ax.plot(f["frequency_hz"], f["amplitude_mm"], "o", mfc="none", mec=colour, ms=7)
        ax.plot([], [], "-", color=colour, label=f"predicted: {label}")
        for j in _jumps(entry, doc):
            p = j["predicted"][label]
            if p["fold_hz"] and p["bias_hz"] is not None:
                ax.axvspan(*sorted((p["fold_hz"], p["fold_hz"] + p["bias_hz"])), color=colour, alpha=0.12, lw=0)
            elif p["fold_hz"] is None and p.get("model_sweep_jump_hz") is not None:
                # no fold to start from (no jump in the steady state, or its branch ends at the validity limit):
                # the model's own run over the sweep is what the measured jump is compared with
                ax.axvline(p["model_sweep_jump_hz"], color=colour, ls="-.", lw=1.2,
                           label=f"{label}: its own run over the sweep jumps")
    limit = (next(iter(entry["predicted"].values())).get("validity") or {}).get("damping_negative_above_mm")
    if limit and limit < 1.5 * max(max(b["amplitude_mm"]) for r in entry["predicted"].values() for b in r["branches"]):
        ax.axhline(limit, color="grey", ls=":", lw=1, label="model's damping < 0 above (validity)")
    for m in entry["measured"]:
        marker, grey = MEASURED_STYLE[m["direction"]]
        ax.plot(m["frequency_hz"], m["response_mm"], marker, ms=2.5, color=grey, alpha=0.7,
                label=f"measured {m['direction']}-sweep ({m['rate_hz_per_s']:+.2g} Hz/s)")
        if m["jump"]:
            j = m["jump"]
            y = np.interp(j["frequency_hz"], *_sorted(m["frequency_hz"], m["response_mm"]))
            ax.errorbar(j["frequency_hz"], y, xerr=j["uncertainty_hz"], fmt="x", color="crimson", ms=9, mew=2,
                        capsize=4, label=f"measured jump ({m['direction']})")
    ax.plot([], [], "--", color="grey", label="unstable")
    ax.plot([], [], "o", mfc="none", mec="grey", label="fold (steady state)")
    ax.fill_between([], [], color="grey", alpha=0.2, label="fold .. fold + sweep-rate bias")
    ax.set_xlim(*_zoom(entry, _jumps(entry, doc)))
    ax.set_ylim(bottom=0)
    ax.set_title(f"table amplitude {entry['amplitude_mm']:.3g} mm", fontsize=10)
    ax.set_xlabel("excitation frequency f, Hz")
    ax.set_ylabel("response (half peak-to-peak q2), mm")
    ax.grid(alpha=0.3)


def _jumps(entry: dict, doc: dict) -> list[dict]:
    """The judged jumps of the panel's own sweeps (side_by_side grouped them: its entry lists them)."""
    own = {(m["source"], m["direction"], m["amplitude_mm"]) for m in entry["measured"]}
    return [j for j in doc["jumps"] if (j["source"], j["direction"], j["amplitude_mm"]) in own]


def _sorted(f, a):
    f, a = np.asarray(f, float), np.asarray(a, float)
    i = np.argsort(f)
    return f[i], a[i]


def _zoom(entry: dict, jumps: list) -> tuple[float, float]:
    """Frequencies where a predicted or measured response exceeds ZOOM_LEVEL of the largest, and the
    panel's jumps (measured, with their uncertainty; the models' folds + bias and own sweep runs), widened."""
    pairs = [(b["frequency_hz"], b["amplitude_mm"]) for r in entry["predicted"].values() for b in r["branches"]]
    pairs += [(m["frequency_hz"], m["response_mm"]) for m in entry["measured"]]
    peak = max(max((a for a in amps if a is not None), default=0.0) for _, amps in pairs)
    f_in = [f for fs, amps in pairs for f, a in zip(fs, amps) if a is not None and a >= ZOOM_LEVEL * peak]
    for j in jumps:
        if j["measured_hz"] is not None:
            f_in += [j["measured_hz"] - j["uncertainty_hz"], j["measured_hz"] + j["uncertainty_hz"]]
        for p in j["predicted"].values():
            f_in += [f for f in (p["fold_hz"], p.get("model_sweep_jump_hz")) if f is not None]
            if p["fold_hz"] is not None and p["bias_hz"] is not None:
                f_in.append(p["fold_hz"] + p["bias_hz"])
    lo, hi = min(f_in), max(f_in)
    span = hi - lo or lo
    return max(entry["band_hz"][0], lo - ZOOM_MARGIN * span), min(entry["band_hz"][1], hi + ZOOM_MARGIN * span)


def jump_rows(doc: dict) -> list[list[str]]:
    """The jump table's rows: per sweep, measured jump and each model's fold, bias, own sweep run's jump,
    miss, verdict."""
    rows = []
    for j in doc["jumps"]:
        measured = "none" if j["measured_hz"] is None else f"{j['measured_hz']:.3f} ± {j['uncertainty_hz']:.3f}"
        for label, p in j["predicted"].items():
            rows.append([f"{j['source']}, {j['direction']}", f"{j['amplitude_mm']:.3g}", measured, label,
                         _f(p["fold_hz"]), _f(p["bias_hz"], "+.3f"), _f(p.get("model_sweep_jump_hz")), _f(p["miss_hz"]),
                         {True: "agrees", False: "MISSES", None: "-"}[p["agrees"]]])
    return rows


def add_side_by_side(page: Page, doc: dict | None, figure: str | None, heading: str = "Frequency response: "
                     "predicted beside measured") -> None:
    """The section every report carries: why there is none, or the flags, the jump table and the figure."""
    page.heading(heading)
    if not doc or doc.get("status") != "ok":
        reason = (doc or {}).get("reason") or "not computed"
        page.paragraph(f"No side-by-side frequency response: {reason}.", "note")
        return
    for line in doc["flags"]:
        page.paragraph(f"FLAGGED: {line}")
    if not doc["flags"]:
        judged = doc["judged"] if doc["judged"].endswith("model") else f"{doc['judged']} model"
        page.paragraph(f"The {judged}'s jumps agree with every sweep's within the sweep-rate bias and "
                       "the measurement's uncertainty.")
    page.table(["sweep", "table mm", "measured jump, Hz", "model", "fold, Hz", "sweep-rate bias, Hz",
                "model's own sweep jumps, Hz", "miss, Hz", "verdict"], jump_rows(doc),
               "Each sweep's jump (up-sweep: jump-down; down-sweep: jump-up) against each model's steady-state fold at "
               "the recorded table amplitude. A sweep passes a fold at a finite rate and jumps later, by the bias (the "
               "model's own run over the same sweep, minus its fold): the measured jump agrees when it lies between "
               "the fold and the fold + bias, give or take its uncertainty (half the frequency the sweep covers "
               "during the transition). Where the model has no fold there (no jump in its steady state, or its "
               "branch ends at its validity limit first), the measured jump is compared with the model's own run "
               "over the sweep directly, within both uncertainties. docs/frf.md.")
    if figure:
        page.figure(figure, "Per table amplitude: the predicted steady-state response (stable solid, unstable dashed, "
                    "folds circled; shaded from the fold to the fold + sweep-rate bias, where the sweep should jump), "
                    "the measured response per table cycle (triangles up / down: the sweep's direction) and the "
                    "measured jump (red x, bar: its uncertainty); where a model has no fold, the jump of its own run "
                    "over the sweep (dash-dotted). A sweep's envelope lags the steady state near the "
                    "resonance: compare the jumps, not the curves point by point.")


def _f(v, fmt=".3f") -> str:
    return "-" if v is None else format(v, fmt)
