"""Identification report: a folder with the model JSON, the coefficient table and figures like the paper's.

    input.png        the input (table acceleration sweep), as the paper's Fig. 5
    output.png       the output (relative acceleration), Fig. 6
    lambda_path.png  log MSE along the path per equation, tolerance line, chosen model, Fig. 7
    validation.png   free-run simulation vs measurement on held-out samples, Fig. 8
    coefficients.md  Table 1's layout: every library term, its coefficient per equation (+- std. error)
    model.json       the result document (`shakeid identify --json`)
    index.html       all of the above on one page
"""
from __future__ import annotations

import html
import json
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display on a lab server
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .text import coefficient_table  # noqa: E402

FIGURES = ("input.png", "output.png", "lambda_path.png", "validation.png")


def write_report(ident, out_dir) -> Path:
    """Write the report of a fitted SparseIdentifier into `out_dir` (created). Returns the folder."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = ident.result()
    (out / "model.json").write_text(json.dumps(result, indent=2))
    table = coefficient_table(result)
    (out / "coefficients.md").write_text(table)
    sig, rec = ident.states_, ident.recording_
    t = np.arange(rec.n_samples) / rec.fs_hz
    base = sig.input_name == "zdd"

    fig, ax = plt.subplots(figsize=(9, 3))
    ax.plot(t, rec.input, lw=0.5)
    ax.set(xlabel="time (s)", ylabel=f"{rec.input_name} ({rec.units[0] or 'units'})", title="Input")
    _save(fig, out / "input.png")

    fig, ax = plt.subplots(figsize=(9, 3))
    ax.plot(t, sig.q1_dot, lw=0.5)
    ax.set(xlabel="time (s)", ylabel="q'' (m/s²)" if base else "y''",
           title="Output: relative acceleration" if base else "Output: second derivative")
    _save(fig, out / "output.png")

    _path_figure(ident, out / "lambda_path.png")
    if ident.validation_ is not None:
        _validation_figure(ident, out / "validation.png", base)
    _index_html(out, result, table)
    return out


def _save(fig, path):
    """Write the figure under a temporary name and rename it: a reader (the HTTP service lists figures
    while a job still draws) sees no file or the whole PNG, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    fig.tight_layout()
    fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    os.replace(tmp, path)


def _path_figure(ident, path):
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for ax, (eq, s) in zip(axes, ident.selections_.items()):
        k = np.arange(1, s.path_mse.size + 1)
        floor = 1e-16 * max(float(np.max(s.path_mse)), 1e-300)  # exactly-fitting equations: keep the axis readable
        ax.semilogy(k, np.maximum(s.path_mse, floor), ".-", lw=0.8, label="training MSE (path)")
        if s.rule == "heldout":
            ax.semilogy(k, np.maximum(s.score, floor), ".-", lw=0.8, label="held-out MSE (refit)")
        if np.isfinite(s.threshold):
            ax.axhline(s.threshold, color="r", lw=1, label="tolerance")
        ax.axvline(s.index + 1, color="k", ls=":", lw=1, label=f"chosen ({int(s.support.sum())} terms)")
        ax2 = ax.twinx()
        ax2.step(k, s.path_nnz, where="mid", color="0.6", lw=0.8)
        ax2.set_ylabel("terms", color="0.5")
        ax.set(xlabel=f"path point ({ident.path_.param_name} decreasing)", ylabel="MSE", title=eq)
        ax.legend(fontsize=7, loc="lower left")
    _save(fig, path)


def _validation_figure(ident, path, base):
    sig = ident.states_
    v = sig.valid
    t = np.arange(v.start, v.stop) / sig.fs_hz
    held = ident.heldout_rows_
    meas_acc, sim_acc = sig.q1_dot[v], ident.simulated_q1_dot_
    meas_q, sim_q = sig.q2[v], ident.simulated_states_[:, 1]
    fig, axes = plt.subplots(3, 1, figsize=(10, 8))
    ax = axes[0]
    ax.plot(t, meas_acc, lw=0.5, label="measured")
    ax.plot(t, sim_acc, lw=0.5, alpha=0.8, label="free-run simulation")
    _shade(ax, t, held)
    ax.set(ylabel="q'' (m/s²)" if base else "y''", title="Validation (held-out samples shaded)")
    ax.legend(fontsize=8, loc="upper left")
    ax = axes[1]
    ax.plot(t, meas_q * (1e3 if base else 1), lw=0.5, label="measured")
    ax.plot(t, sim_q * (1e3 if base else 1), lw=0.5, alpha=0.8, label="simulated")
    _shade(ax, t, held)
    ax.set(ylabel="q (mm)" if base else "y")
    # zoom on the held-out block with the largest response: where the model is tested hardest
    ax = axes[2]
    idx = np.flatnonzero(held) if held.any() else np.arange(t.size)
    centre = idx[np.argmax(np.abs(meas_q[idx]))]
    w = int(min(0.5 * sig.fs_hz * max(1.0, 2.0 / max(sig.band_hz[0], 0.5)), t.size // 2))
    z = slice(max(centre - w, 0), min(centre + w, t.size))
    ax.plot(t[z], meas_acc[z], lw=0.8, label="measured")
    ax.plot(t[z], sim_acc[z], lw=0.8, ls="--", label="simulated")
    ax.set(xlabel="time (s)", ylabel="q'' (m/s²)" if base else "y''", title="Zoom: largest held-out response")
    ax.legend(fontsize=8)
    _save(fig, path)


def _shade(ax, t, mask):
    if not mask.any():
        return
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        ax.axvspan(t[a], t[b - 1], color="0.9", zorder=0)


def _index_html(out: Path, result: dict, table: str):
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(c.strip())}</td>" for c in ln.strip("|").split("|")) + "</tr>"
                   for ln in table.splitlines()[2:])
    eqs = "".join(f"<th>{html.escape(e.strip())}</th>" for e in table.splitlines()[0].strip("|").split("|")[1:])
    val = result.get("validation") or {}
    figs = "".join(f'<p><img src="{f}" style="max-width:100%"></p>' for f in FIGURES if (out / f).exists())
    (out / "index.html").write_text(
        "<!doctype html><meta charset='utf-8'><title>shakeid identification report</title>"
        "<h1>Identified model</h1><table border=1 cellpadding=3><tr><th>term</th>" + eqs + "</tr>" + rows +
        "</table><h2>Validation</h2><pre>" + html.escape(json.dumps(val.get("heldout", {}), indent=1)) +
        "</pre>" + figs + "<p><a href='model.json'>model.json</a></p>")
