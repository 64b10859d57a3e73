"""The explain report: a folder with its own index.html, read like the identification report (tables,
captions, residuals), on a simulated rig with a known hidden effect (Coulomb friction)."""
import re

import numpy as np
import pytest

import reports.explain as exrep
import reports.identification as idrep
from identify.explain.workflow import DiscrepancyAnalysis
from reports.explain import FIGURES, write_explain_report
from sim.rig import RigParameters
from protocol.sweep import SineSweep

FRICTION_N = 0.1  # N: the hidden effect (tests/identify/test_explain.py's magnitude)


@pytest.fixture(scope="module")
def analysis(make_run):
    run = make_run(rig=RigParameters.design(effects={"coulomb_friction": FRICTION_N}),
                   sweep=SineSweep(1.0, 20.0, 30.0, 1.3), fs_hz=1000.0, seed=5)
    return DiscrepancyAnalysis().fit(run.recording)


@pytest.mark.slow
def test_explain_report_has_its_own_index(analysis, tmp_path):
    out = write_explain_report(analysis, tmp_path / "explain")
    result = analysis.result()
    assert result["effect"] == "coulomb_friction"  # the premise: the hidden effect is named
    html = (out / "index.html").read_text()
    for f in FIGURES:
        assert (out / f).read_bytes().startswith(b"\x89PNG") and f"src='{f}'" in html
    assert html.count("<figcaption>") == len(FIGURES) and html.count("<table>") >= 3
    assert "<pre>" not in html and '{"' not in html and "m/s^2" not in html
    assert "missing effect: coulomb_friction" in html
    # the effects table: the named effect with its coefficient as explain.json has it
    effects = next(t for t in re.findall(r"<table>(.*?)</table>", html, re.S) if "effects added" in t)
    coef = result["effects"][0]["coefficients"]["sign(q1)"]
    assert f"sign(q1): {coef:.4g}" in effects
    # the gap before and after, as in explain.json
    assert f"{result['gap_before']:.4f}" in html and f"{result['gap_after']:.4f}" in html
    # every candidate of the first round is a row
    assert all(c["name"] in html for c in result["candidates"])


def test_gap_figure_shows_the_residuals(analysis, tmp_path, monkeypatch):
    kept = {}
    monkeypatch.setattr(exrep, "_save", lambda fig, path: kept.__setitem__(path.name, fig))
    write_explain_report(analysis, tmp_path / "again")
    try:
        axes = kept["gap.png"].get_axes()
        residual = next(ax for ax in axes if ax.get_ylabel() == "residual (m/s²)")
        before, after = (ln.get_ydata() for ln in residual.get_lines()[:2])
        # the fixed model's residual is smaller than the baseline's over the window shown
        assert np.sqrt(np.mean(after**2)) < 0.5 * np.sqrt(np.mean(before**2))
        for name, fig in kept.items():  # every panel has an x label (a twin axis shares its panel's)
            panels: dict = {}
            for ax in fig.get_axes():
                if ax.get_label() != "<colorbar>":
                    panels.setdefault(tuple(np.round(ax.get_position().bounds, 3)), []).append(ax.get_xlabel())
            assert all(any(labels) for labels in panels.values()), name
    finally:
        for fig in kept.values():
            idrep.plt.close(fig)
