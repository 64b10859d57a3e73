"""Identification report: a folder a person opens, laid out like a lab report of the paper's experiment.

    index.html       the page: the data used, the model, validation, physical parameters and selection as
                     numbered tables, the figures with captions under them
    input.png        the input (table acceleration sweep), as the paper's Fig. 5
    output.png       the output (relative acceleration), Fig. 6
    lambda_path.png  log MSE along the path per equation, tolerance line, chosen model, Fig. 7
    validation.png   free-run simulation vs measurement, each with its residual (measured - simulated), Fig. 8
    coefficients.md  Table 1's layout: every library term, its coefficient per equation (+- std. error)
    model.json       the result document (`shakeid identify --json`)
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display on a lab server
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from identify.export.latex import latex_equations  # noqa: E402

from .frf_overlay import OVERLAY_FIGURE, add_side_by_side, overlay_figure  # noqa: E402
from .joint import joint_data_section, joint_validation_table  # noqa: E402
from .html import IDENTIFICATION_DOCUMENTS, IDENTIFICATION_FIGURES, Page, report_folder  # noqa: E402
from .text import (DESIGN_K3_NOTE, coefficient_rows, coefficient_table, fit_text, mass_text,  # noqa: E402
                   physical_rows, plural, unit, unsettled_lines)

FIGURES, DOCUMENTS = IDENTIFICATION_FIGURES, IDENTIFICATION_DOCUMENTS
RESIDUAL = "#c0392b"  # the residual traces' colour, the same in every panel
MEASURED, SIMULATED = "#9ecae1", "#08306b"  # validation: the measurement light and broad, the simulation dark and thin


def write_report(ident, out_dir, result: dict | None = None) -> Path:
    """Write the report of a fitted SparseIdentifier into `out_dir` (created; an earlier identification
    report there is replaced, none of its files left behind; a folder holding anything else is refused:
    html.check_report_folder). Returns the folder. `result`: the document
    to write as model.json, when the caller has more than ident.result() (the CLI's data_quality)."""
    out = report_folder(out_dir, "identification")
    result = ident.result() if result is None else result
    (out / "model.json").write_text(json.dumps(result, indent=2))
    (out / "coefficients.md").write_text(coefficient_table(result))
    labels = _labels(ident)
    _signal_figure(ident, out / "input.png", labels["input"], "Input", lambda rec, sig: rec.input)
    _signal_figure(ident, out / "output.png", labels["acc"], labels["output_title"], lambda rec, sig: sig.q1_dot)
    _path_figure(ident, out / "lambda_path.png")
    if (result.get("frf") or {}).get("status") == "ok":
        overlay_figure(result["frf"], out / OVERLAY_FIGURE)
    if ident.validation_ is not None and ident.recording_ is not None:  # a joint fit's: its table per recording
        _validation_figure(ident, out / "validation.png", labels)
    (out / "index.html").write_text(_index_html(out, ident, result))
    return out


def recordings(ident) -> list:
    """(recording, its chain states) per recording fitted: one, or a joint fit's several."""
    return [(rec, source.sig) for rec, source in zip(ident.recordings_, ident.sources_)]


def _signal_figure(ident, path, ylabel: str, title: str, signal) -> None:
    """signal(recording, states) against time, a panel per recording (a joint fit's, each titled by it)."""
    recs = recordings(ident)
    fig, axes = plt.subplots(len(recs), 1, figsize=(9, 3 if len(recs) == 1 else 2.2 * len(recs)), squeeze=False)
    for ax, (rec, sig) in zip(axes[:, 0], recs):
        ax.plot(np.arange(rec.n_samples) / rec.fs_hz, signal(rec, sig), lw=0.5)
        ax.set(xlabel="time (s)", ylabel=ylabel, title=title if len(recs) == 1 else f"{title}: {_name(rec)}")
    _save(fig, path)


def _name(rec) -> str:
    """A recording as the page names it: its file's name, not its path (a report the service wrote would
    show the server's folders)."""
    return Path(str(rec.source)).name


def _labels(ident) -> dict:
    """Axis labels with units: the base layout's accelerations (m/s²) and displacement (mm); a force
    layout's input u and output y in the recording's own units (often volts, unnamed)."""
    rec = recordings(ident)[0][0]  # a joint fit's recordings share one layout
    if ident.states_.input_name == "zdd":
        return {"input": f"table acceleration ({unit(rec.units[0] or 'm/s^2')})", "acc": "relative acceleration (m/s²)",
                "disp": "relative displacement (mm)", "disp_scale": 1e3, "acc_unit": "m/s²", "vel_unit": "m/s",
                "disp_unit": "mm", "output_title": "Output: relative acceleration (mass − table)",
                "acc_word": "relative acceleration", "disp_word": "relative displacement"}
    u_in, u_out = unit(rec.units[0]), unit(rec.units[1])
    return {"input": f"{rec.input_name}" + (f" ({u_in})" if u_in else " (as recorded)"),
            "acc": "y''" + (f" ({u_out}/s²)" if u_out else ""), "disp": "y" + (f" ({u_out})" if u_out else ""),
            "disp_scale": 1.0, "acc_unit": f"{u_out}/s²" if u_out else "", "vel_unit": f"{u_out}/s" if u_out else "",
            "disp_unit": u_out, "output_title": "Output: second derivative of y",
            "acc_word": "output's second derivative y''", "disp_word": "output y"}


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
    """Per equation: MSE along the path (left axis, log), terms in the model (right axis, integers); the
    legend below the axes, where it covers no data."""
    # one panel per row at a width the page shows near its own size, text at PATH_FONT_PT: the figure is
    # read at page scale (the dashboard shows it at most 900 px wide), not zoomed into
    n = len(ident.selections_)
    with plt.rc_context({"font.size": PATH_FONT_PT}):
        fig, axes = plt.subplots(n, 1, figsize=(8, 3.6 * n + 0.8), squeeze=False)
        _path_panels(ident, axes[:, 0])
    _save(fig, path)


#: the lambda-path figure's text size, pt (at 110 dpi and 8 in wide it reads as 11 pt at 880 px)
PATH_FONT_PT = 11


def _path_panels(ident, axes):
    for ax, (eq, s) in zip(axes, ident.selections_.items()):
        k = np.arange(1, s.path_mse.size + 1)
        floor = 1e-16 * max(float(np.max(s.path_mse)), 1e-300)  # exactly-fitting equations: keep the axis readable
        lines = ax.semilogy(k, np.maximum(s.path_mse, floor), ".-", lw=0.8, ms=3, label="training MSE (path)")
        if s.rule == "heldout":
            lines += ax.semilogy(k, np.maximum(s.score, floor), ".-", lw=0.8, ms=3, label="held-out MSE (refit)")
        if np.isfinite(s.threshold):
            lines.append(ax.axhline(s.threshold, color="r", lw=1, label="tolerance"))
        n = int(s.support.sum())
        lines.append(ax.axvline(s.index + 1, color="k", ls=":", lw=1, label=f"chosen: {plural(n, 'term')}"))
        ax2 = ax.twinx()
        lines += ax2.step(k, s.path_nnz, where="mid", color="0.6", lw=0.8, label="terms in the model (right axis)")
        ax2.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax2.set_ylim(0, max(int(np.max(s.path_nnz)), 1) + 0.5)
        ax2.set_ylabel("terms in the model", color="0.4")
        ax.set(xlabel=f"path point ({ident.path_.param_name} decreasing)", ylabel="MSE", title=eq)
        ax.legend(lines, [ln.get_label() for ln in lines], fontsize=PATH_FONT_PT - 1, ncol=3, loc="upper center",
                  bbox_to_anchor=(0.5, -0.22), frameon=False)


def _validation_figure(ident, path, labels):
    """Measurement and free-run simulation, each signal with its residual (measured − simulated) in the
    panel below on its own scale: the two curves overlap where the model is right, the residual shows
    where it is not."""
    sig = ident.states_
    v = sig.valid
    t = np.arange(v.start, v.stop) / sig.fs_hz
    held = ident.heldout_rows_
    scale = labels["disp_scale"]
    meas_acc, sim_acc = sig.q1_dot[v], ident.simulated_q1_dot_
    meas_q, sim_q = sig.q2[v] * scale, ident.simulated_states_[:, 1] * scale
    # zoom on the held-out block with the largest response: where the model is tested hardest
    idx = np.flatnonzero(held) if held.any() else np.arange(t.size)
    centre = idx[np.argmax(np.abs(meas_q[idx]))]
    w = int(min(0.5 * sig.fs_hz * max(1.0, 2.0 / max(sig.band_hz[0], 0.5)), t.size // 2))
    z = slice(max(centre - w, 0), min(centre + w, t.size))
    fig, axes = plt.subplots(6, 1, figsize=(10, 14), gridspec_kw={"height_ratios": [2, 1, 2, 1, 2, 1]})
    panels = [(f"{labels['acc_word']}, whole record (held-out samples shaded)", slice(None), meas_acc, sim_acc,
               labels["acc"], labels["acc_unit"], True),
              (f"{labels['disp_word']}, whole record (held-out samples shaded)", slice(None), meas_q, sim_q,
               labels["disp"], labels["disp_unit"], True),
              ("zoom: the held-out block with the largest response", z, meas_acc, sim_acc, labels["acc"],
               labels["acc_unit"], False)]
    for i, (title, sl, meas, sim, ylabel, u, shade) in enumerate(panels):
        ax, axr = axes[2 * i], axes[2 * i + 1]
        # the measurement broad and light underneath, the simulation thin and dark on top: where they agree
        # the thin line runs inside the broad one, and neither hides the other
        ax.plot(t[sl], meas[sl], lw=2.2 if shade else 3.0, color=MEASURED, label="measured", zorder=2)
        ax.plot(t[sl], sim[sl], lw=0.5 if shade else 1.0, color=SIMULATED, label="free-run simulation", zorder=3)
        axr.plot(t[sl], meas[sl] - sim[sl], lw=0.5, color=RESIDUAL)
        axr.axhline(0, color="0.6", lw=0.6)
        if shade:
            _shade(ax, t, held)
            _shade(axr, t, held)
        ax.set(xlabel="time (s)", ylabel=ylabel, title=title[0].upper() + title[1:])
        axr.set(xlabel="time (s)", ylabel=f"residual ({u})" if u else "residual",
                title="Residual: measured − simulated (own scale)")
        if not shade:  # the zoom fills the width: room above the data for the legend
            lo, hi = ax.get_ylim()
            ax.set_ylim(lo, hi + 0.3 * (hi - lo))
        ax.legend(fontsize=8, loc="upper left", ncol=2)
    _save(fig, path)


def _shade(ax, t, mask):
    if not mask.any():
        return
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        ax.axvspan(t[a], t[b - 1], color="0.9", zorder=0)


def _index_html(out: Path, ident, result: dict) -> str:
    names = [_name(rec) for rec, _ in recordings(ident)]
    page = Page(f"Identification report: {', '.join(names)}" + (" (joint)" if len(names) > 1 else ""),
                "identification")
    if result.get("status") == "failed":
        page.paragraph(f"MODEL FAILED its validation: {result['reason']}")
    if ident.recording_ is not None:
        _data_section(page, ident, result)
    else:
        joint_data_section(page, result, names)
    _model_section(page, ident, result)
    _validation_section(page, ident, result)
    if ident.recording_ is None:
        joint_validation_table(page, result, names)
    _physical_section(page, ident, result)
    _selection_section(page, ident, result)
    _figures_section(page, out, ident)
    if "frf" in result:  # after the figures the text numbers (Figure 3, ...)
        add_side_by_side(page, result["frf"], OVERLAY_FIGURE if (out / OVERLAY_FIGURE).exists() else None)
    page.links([("model.json", "model.json (the whole result)"), ("coefficients.md", "coefficients.md")])
    return page.render()


def _data_section(page: Page, ident, result: dict) -> None:
    """The recording and the part of it the identification used."""
    rec, sig = ident.recording_, ident.states_
    base = sig.input_name == "zdd"
    chain = result.get("chain") or {}
    band = chain.get("band_hz") or list(sig.band_hz)
    page.heading("Data")
    page.table(["quantity", "value"], [
        ["recording", Path(str(rec.source)).name],
        ["layout", "base: table and mass accelerations (m/s²)" if base else
         f"force: input {rec.input_name}, output {rec.output_name}"],
        ["samples", f"{rec.n_samples} at {rec.fs_hz:g} Hz ({rec.n_samples / rec.fs_hz:.1f} s)"],
        ["integration band", f"{band[0]:.3g}-{band[1]:.3g} Hz"],
        ["samples used", f"{sig.valid.stop - sig.valid.start} (samples {sig.valid.start} to {sig.valid.stop}: "
                         "the integration filter's edges are cut)"],
        ["fitted on / held out", f"{chain.get('fit_samples', '-')} / {chain.get('heldout_samples', '-')} samples "
                                 f"({chain.get('holdout', 'held out')})"],
    ], "The recording and the part of it the identification used. Held-out samples are never used for "
       "fitting; the validation below is on them.")


def _model_section(page: Page, ident, result: dict) -> None:
    """The coefficients with their standard errors and P(kept), what was left out, the LaTeX."""
    base = ident.states_.input_name == "zdd"
    page.heading("Identified model")
    n_place = (result.get("uncertainty") or {}).get("placements")
    headers, rows = coefficient_rows(result)
    page.table(headers, rows,
               "Coefficient of every library term in each equation, in the layout of the paper's Table 1 "
               "(0: the term was not selected), ± one standard error. "
               + ("q1_dot is the relative acceleration (m/s²) and q2_dot = q1; q1 is the relative velocity (m/s), "
                  "q2 the relative displacement (m), zdd the table acceleration (m/s²). " if base else "")
               + "P(kept): the share of random held-out placements"
               + (f" ({n_place})" if n_place else "") + " whose selection kept the term.")
    for line in unsettled_lines(result):  # uncertain terms left out, an unsettled selection, a budget's drops
        page.paragraph(line)
    page.code(latex_equations(ident.model_), "The model's equations in the paper's notation, LaTeX for a paper "
              "(amsmath's align; `shakeid export model.json --format latex` writes the same as a file):")


def _validation_section(page: Page, ident, result: dict) -> None:
    """The free run against the measurement, held out and on all samples."""
    labels = _labels(ident)
    val = result.get("validation")
    if val:
        page.heading("Validation")
        names = {"q1_dot": ("acceleration", labels["acc_unit"], 1.0), "q1": ("velocity", labels["vel_unit"], 1.0),
                 "q2": ("displacement", labels["disp_unit"], labels["disp_scale"])}
        vrows = []
        for key, (name, u, scale) in names.items():
            h, a = val["heldout"][key], val["all"][key]
            rmse = "-" if h.get("rmse") is None else f"{h['rmse'] * scale:.3g} {u}".strip()
            nrmse = "-" if h.get("nrmse") is None else f"{h['nrmse']:.4f}"
            vrows.append([name, fit_text(h), nrmse, rmse, fit_text(a)])
        one_step = (val.get("equation_error") or {}).get("q1_dot")
        page.table(["signal", "fit, held-out", "NRMSE, held-out", "RMSE, held-out", "fit, all samples"], vrows,
                   f"Free-run simulation of the model, driven by the measured input from the first sample on, "
                   f"against the measurement: NRMSE = RMS error / standard deviation of the measurement, "
                   f"fit = 100 (1 − NRMSE) %. Held-out: {val['heldout_samples']} samples not used for fitting."
                   + (f" One-step equation error of the acceleration (not simulated): fit {fit_text(one_step)}."
                      if one_step else "") + (" The simulation diverged." if val.get("diverged") else ""))


def _physical_section(page: Page, ident, result: dict) -> None:
    """Damping, stiffness, cubic stiffness from the q1_dot equation (base layout)."""
    base = ident.states_.input_name == "zdd"
    phys = result.get("physical")
    if phys and base:
        page.heading("Physical parameters")
        design = phys["design"]["cubic_stiffness_n_per_m3"]
        prow = [[n, v, s or "-", u, f"{design:.4g}" if n.startswith("cubic") else ""]
                for n, v, s, u in physical_rows(phys)]
        page.table(["parameter", "identified", "standard error", "unit", "design"], prow,
                   f"Physical parameters from the q1_dot equation with the moving mass {mass_text(phys)} "
                   f"(c = −m·coef(q1), k = −m·coef(q2), k3 = −m·coef(q2³); b from k). The design column: "
                   + DESIGN_K3_NOTE + ".")


def _selection_section(page: Page, ident, result: dict) -> None:
    """Where on the path each equation's model was chosen."""
    sel = result.get("selection") or {}
    srows = []
    for e, (eq, s) in enumerate(ident.selections_.items()):  # the path's own parameter (lambda or threshold)
        srows.append([eq, str(s.index + 1), f"{ident.path_.params[s.index, e]:.3g}", plural(int(s.support.sum()), "term"),
                      # an exactly fitting equation's MSE is rounding, which can fall below 0
                      f"{max(s.score[s.index], 0.0):.3g}", "-" if np.isnan(s.threshold) else f"{s.threshold:.3g}"])
    if srows:
        page.heading("Selection")
        n_path = ident.path_.params.shape[0]
        page.table(["equation", "chosen path point", f"{ident.path_.param_name} there", "model", "score (MSE)",
                    "tolerance (MSE)"],
                   srows, f"Where on the path each equation's model was chosen, by the {sel.get('rule')} rule "
                          f"({result.get('method')}, {plural(n_path, 'path point')}): the sparsest point whose score is "
                          "within the tolerance (Figure 3). Points are counted from 1 (the JSON's index from 0).")


def _figures_section(page: Page, out: Path, ident) -> None:
    """The figures written beside the page, with their captions."""
    rec, base = recordings(ident)[0][0], ident.states_.input_name == "zdd"
    page.heading("Figures")
    several = " One panel per recording." if ident.recording_ is None else ""
    captions = {
        "input.png": "Input: " + ("the table acceleration over the whole record, as the accelerometer on the table "
                                  "measured it (the paper's Fig. 5)." if base else f"{rec.input_name} as recorded.")
                     + several,
        "output.png": ("Output: the relative acceleration (mass − table) after the measurement chain, the left side "
                       "of the q1_dot equation (the paper's Fig. 6)." if base else "Output: the second derivative of "
                       f"{rec.output_name}, the left side of the q1_dot equation.") + several,
        "lambda_path.png": "Selection along the path, one panel per equation (the paper's Fig. 7): training MSE of "
                           "each path point, held-out MSE of its least-squares refit, the tolerance, the chosen point "
                           "(dotted) and the number of terms at each point (grey, right axis). Lambda decreases to "
                           "the right, so terms are added from left to right. An equation fitted exactly (q2_dot = q1) has its MSE "
                           "drawn at the plot's floor, 10⁻¹⁶ of its largest value.",
        "validation.png": "Validation (the paper's Fig. 8): the model's free-run simulation against the measurement "
                          "for the acceleration and the displacement over the whole record, and a zoom on the "
                          "held-out block with the largest response. Under each, the residual (measured − "
                          "simulated) on its own scale: where the curves overlap, the residual shows what is "
                          "left. Shaded: held-out samples.",
    }
    for f in FIGURES:
        if (out / f).exists():
            page.figure(f, captions[f])
