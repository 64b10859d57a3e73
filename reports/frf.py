"""The frequency-response report (shakeid frf --report DIR): one figure of the predicted responses,
amplitude against frequency per table amplitude (stable branches solid, unstable dashed, folds marked,
the backbone, the model's range of validity), a table of the jumps, and frf.json beside index.html."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .html import Page, report_folder

COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def write_frf_report(doc: dict, out_dir, title: str) -> Path:
    """Write index.html, frf.png and frf.json (the document `shakeid frf --json` prints) to `out_dir`."""
    out = report_folder(out_dir, "frf")
    (out / "frf.json").write_text(json.dumps(doc, indent=1))
    frf_figure(doc, out / "frf.png")
    page = Page(f"Frequency response: {title}", "frf")
    page.paragraph("Predicted periodic response of the model under the table motion z = A sin(2 pi f t), by harmonic "
                   "balance with continuation (docs/frf.md). Amplitude: half the peak-to-peak relative displacement.")
    rows = []
    for r in doc["responses"]:
        peak = max(max(b["amplitude_mm"]) for b in r["branches"])
        rows.append([f"{r['amplitude_mm']:g} mm", _hz(r["jump_down_hz"]), _hz(r["jump_up_hz"]), f"{peak:.3f}",
                     str(r["harmonics"]), "; ".join(r["notes"]) or "-"])
    page.table(["table amplitude", "jump down (up-sweep), Hz", "jump up (down-sweep), Hz", "largest response, mm",
                "harmonics", "notes"], rows,
               "The folds: an up-sweep jumps down at the first, a down-sweep up at the second (steady state; a sweep "
               "jumps later, by its sweep-rate bias). '-': no fold in the band.")
    page.figure("frf.png", "Response amplitude against excitation frequency per table amplitude: stable solid, "
                "unstable dashed, folds as circles; the backbone (free vibration of the restoring force) dash-dotted "
                "black; a grey dotted line where the model's damping turns negative (outside its range of validity).")
    page.links([("frf.json", "frf.json (branches, stability, folds, backbone)")])
    (out / "index.html").write_text(page.render())
    return out


def _hz(f) -> str:
    return "-" if f is None else f"{f:.4f}"


def frf_figure(doc: dict, path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5), dpi=110, gridspec_kw={"width_ratios": (1, 1.3)})
    for ax in axes:
        _draw(ax, doc)
    axes[0].set_xlim(*doc["band_hz"])
    axes[0].set_title("the band", fontsize=10)
    lo, hi = _resonance(doc)
    axes[1].set_xlim(lo, hi)
    axes[1].set_title("around the resonance", fontsize=10)
    axes[1].legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _resonance(doc) -> tuple[float, float]:
    """The frequencies where any response exceeds half its largest, widened by 15 % each side."""
    f_in = []
    for r in doc["responses"]:
        peak = max(max(b["amplitude_mm"]) for b in r["branches"])
        for b in r["branches"]:
            f_in += [f for f, a in zip(b["frequency_hz"], b["amplitude_mm"]) if a > 0.5 * peak]
    return 0.85 * min(f_in), 1.15 * max(f_in)


def _draw(ax, doc) -> None:
    for k, r in enumerate(doc["responses"]):
        colour = COLOURS[k % len(COLOURS)]
        for b in r["branches"]:
            _branch(ax, np.array(b["frequency_hz"]), np.array(b["amplitude_mm"]), np.array(b["stable"]), colour)
        for f in r["folds"]:
            ax.plot(f["frequency_hz"], f["amplitude_mm"], "o", mfc="none", mec=colour, ms=7)
        ax.plot([], [], "-", color=colour, label=f"A = {r['amplitude_mm']:g} mm")
    bb = doc.get("backbone") or {}
    if bb.get("frequency_hz"):
        ax.plot(bb["frequency_hz"], bb["amplitude_mm"], "-.", color="black", lw=1, label="backbone")
    limit = doc["responses"][0].get("validity") or {}
    if limit.get("damping_negative_above_mm"):
        ax.axhline(limit["damping_negative_above_mm"], color="grey", ls=":", lw=1,
                   label=f"damping < 0 above {limit['damping_negative_above_mm']:.3g} mm")
    ax.plot([], [], "--", color="grey", label="unstable")
    ax.plot([], [], "o", mfc="none", mec="grey", label="fold")
    ax.set_xlabel("excitation frequency f, Hz")
    ax.set_ylabel("response amplitude (half peak-to-peak q2), mm")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)


def _branch(ax, f, a, stable, colour) -> None:
    """Runs of equal stability, each drawn including its neighbour's first point (no gaps)."""
    start = 0
    for i in range(1, f.size + 1):
        if i == f.size or stable[i] != stable[start]:
            stop = min(i + 1, f.size)
            ax.plot(f[start:stop], a[start:stop], "-" if stable[start] else "--", color=colour, lw=1.5)
            start = i
