"""Report of the discrepancy workflow: where the baseline misses, what was named, before and after.

    residual_time.png     residual RMS along the record, with the excitation frequency
    residual_state.png    mean residual over displacement x velocity, and against velocity
    candidates.png        each effect (first round): held-out equation-error share explained, shooting gap closed
    gap.png               free-run simulation before and after, on the held-out block with most error
    explain.json          the `shakeid explain --json` document
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .identification import _save, plt

FIGURES = ("residual_time.png", "residual_state.png", "candidates.png", "gap.png")


def write_explain_report(analysis, out_dir) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = analysis.result()
    (out / "explain.json").write_text(json.dumps(result, indent=2))
    loc = analysis.localisation_
    sig = analysis.states_

    w = loc["time"]["windows"]
    t = [0.5 * (x["t_start_s"] + x["t_end_s"]) for x in w]
    fig, ax = plt.subplots(figsize=(9, 3.2))
    ax.plot(t, [x["residual_rms"] for x in w], "o-", ms=3, label="residual RMS (m/s²)")
    ax.set(xlabel="time (s)", ylabel="baseline residual RMS", title="Where the baseline misses: along the record")
    ax2 = ax.twinx()
    ax2.plot(t, [x["excitation_hz"] for x in w], color="0.6", lw=1)
    ax2.set_ylabel("excitation (Hz)", color="0.5")
    _save(fig, out / "residual_time.png")

    st = loc["state"]
    mean = np.array([[np.nan if v is None else v for v in row] for row in st["mean_residual"]])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    e2, e1 = np.array(st["q2_edges_m"]) * 1e3, np.array(st["q1_edges_ms"])
    lim = np.nanmax(np.abs(mean)) if np.isfinite(mean).any() else 1.0
    im = axes[0].pcolormesh(e1, e2, mean, cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=axes[0], label="mean residual (m/s²)")
    axes[0].set(xlabel="velocity q1 (m/s)", ylabel="displacement q2 (mm)", title="Residual over the state space")
    sigv = st["velocity_signature"]
    axes[1].plot(sigv["q1_centres_ms"], [np.nan if v is None else v for v in sigv["mean_residual"]], "o-")
    axes[1].axhline(0, color="0.7", lw=0.8)
    axes[1].set(xlabel="velocity q1 (m/s)", ylabel="mean residual (m/s²)",
                title="Signature against velocity (step: friction)")
    _save(fig, out / "residual_state.png")

    cands = result["candidates"]
    fig, ax = plt.subplots(figsize=(8, 3.2))
    x = np.arange(len(cands))
    ax.bar(x - 0.2, [c["score"] for c in cands], 0.4, label="equation-error share explained (held-out)")
    ax.bar(x + 0.2, [max(c.get("gap_share_closed") or 0, -0.5) for c in cands], 0.4,
           label="shooting gap closed (held-out)")
    ax.set_xticks(x, [c["name"].replace("_", "\n") for c in cands], fontsize=7)
    ax.axhline(analysis.min_gap_closed, color="r", lw=0.8, ls="--", label="naming threshold")
    ax.set(ylim=(min(0, ax.get_ylim()[0]), 1.05), title=f"Named: {result['effect']} (confidence {result['confidence']:.2f})")
    ax.legend(fontsize=7)
    _save(fig, out / "candidates.png")

    v = sig.valid
    meas = analysis.gap_measured_
    held = analysis.heldout_rows_
    idx = np.flatnonzero(held)
    err = np.abs(np.nan_to_num(analysis.sim_before_qdot_, nan=np.inf) - meas)
    centre = idx[np.nanargmax(err[idx])] if idx.size else int(np.nanargmax(err))
    half = int(sig.fs_hz)
    z = slice(max(centre - half, 0), min(centre + half, meas.size))
    tt = (np.arange(v.start, v.stop) / sig.fs_hz)[z]
    fig, ax = plt.subplots(figsize=(10, 3.4))
    ax.plot(tt, meas[z], lw=1, label="measured")
    ax.plot(tt, analysis.sim_before_qdot_[z], lw=0.9, ls="--", label="baseline")
    if result["effects"]:  # the fixed model's free run, as the analysis simulated it
        ax.plot(tt, analysis.sim_after_qdot_[z], lw=0.9, label="+ " + ", ".join(e["name"] for e in result["effects"]))
    ax.set(xlabel="time (s)", ylabel="q'' (m/s²)" if analysis.layout_ == "base" else "y",
           title="Free run on held-out samples: before and after")
    ax.legend(fontsize=8)
    _save(fig, out / "gap.png")
    return out
