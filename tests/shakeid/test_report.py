"""The identification report: files a person opens, with the content the paper's figures carry, laid out
like a lab report (tables, not JSON; captions; residuals; units; the design k3 explained)."""
import json
import re

import numpy as np
import pytest

import reports.identification as idrep
from identify.identifier import SparseIdentifier
from identify.errors import ShakeidError
from reports.html import Page, check_report_folder, earlier_report, report_kind
from reports.identification import FIGURES, write_report
from reports.text import coefficient_table

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def report_dir(table1_run, tmp_path_factory):
    ident = SparseIdentifier().fit(table1_run.recording)
    return write_report(ident, tmp_path_factory.mktemp("report")), ident


@pytest.fixture(scope="module")
def figures(report_dir, tmp_path_factory):
    """The report drawn again with every figure kept open: {file name: matplotlib Figure}."""
    _, ident = report_dir
    kept = {}
    mp = pytest.MonkeyPatch()
    mp.setattr(idrep, "_save", lambda fig, path: kept.__setitem__(path.name, fig))
    try:
        write_report(ident, tmp_path_factory.mktemp("again"))
    finally:
        mp.undo()
    yield kept
    for fig in kept.values():
        idrep.plt.close(fig)


@pytest.mark.slow
def test_report_files(report_dir):
    out, ident = report_dir
    for fig in FIGURES:
        data = (out / fig).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, fig  # a real picture, not an empty canvas
    doc = json.loads((out / "model.json").read_text())
    assert doc["model"] == ident.result()["model"]
    html = (out / "index.html").read_text()
    assert all(f"src='{f}'" in html for f in FIGURES)


def test_the_page_carries_the_models_latex(report_dir):
    """The equations as the paper writes them, each kept term of q1_dot in its notation, escaped for HTML."""
    out, ident = report_dir
    html = (out / "index.html").read_text()
    pre = re.search(r"<pre>(.*?)</pre>", html, re.S).group(1)
    assert pre.startswith(r"\begin{align}") and r"\dot{q}_{2} &amp;= q_{1}" in pre
    for piece in (r"\, q_{1}", r"\, q_{2}", r"\, q_{2}^{3}", r"\, q_{1} q_{2}^{2}", r"\, \ddot{z}"):
        assert piece in pre, piece


def test_coefficient_table_has_table1_layout(report_dir):
    out, ident = report_dir
    table = (out / "coefficients.md").read_text()
    rows = table.strip().splitlines()[2:]
    assert [r.split("|")[1].strip() for r in rows] == ident.library_.names  # every term, in order
    q2_row = next(r for r in rows if r.split("|")[1].strip() == "q1^2")
    assert q2_row.split("|")[2].strip() == "0"
    assert "±" in next(r for r in rows if r.split("|")[1].strip() == "q2^3")
    assert coefficient_table(ident.result()) == table


def _cells(html: str, caption_start: str) -> list[list[str]]:
    """The rows (header included) of the table whose caption contains caption_start."""
    for table in re.findall(r"<table>(.*?)</table>", html, re.S):
        if caption_start in table:
            return [re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", row) for row in re.findall(r"<tr>(.*?)</tr>", table)]
    raise AssertionError(f"no table with {caption_start!r}")


def test_index_is_tables_and_captions_not_json(report_dir):
    out, ident = report_dir
    html = (out / "index.html").read_text()
    result = ident.result()
    # no JSON dumped on the page; its one preformatted block is the model's LaTeX (test_the_page_carries_...)
    assert html.count("<pre>") == 1 and "{&quot;" not in html and '{"' not in html
    assert html.count("<figcaption>") == len(FIGURES) and html.count("<caption>") >= 4
    # the validation as a table: one row per signal, the held-out fit as model.json has it
    rows = _cells(html, "Free-run simulation of the model")
    assert rows[0][:2] == ["signal", "fit, held-out"]
    by_signal = {r[0]: r for r in rows[1:]}
    for key, name in (("q1_dot", "acceleration"), ("q1", "velocity"), ("q2", "displacement")):
        assert by_signal[name][1] == f"{result['validation']['heldout'][key]['fit_percent']:.2f} %"
    assert by_signal["acceleration"][3].endswith(" m/s²") and by_signal["displacement"][3].endswith(" mm")
    # every library term is a row of the model table, with the coefficients of model.json
    model_rows = _cells(html, "in the layout of the paper")
    assert [r[0] for r in model_rows[1:]] == ident.library_.names
    q23 = next(r for r in model_rows if r[0] == "q2^3")
    assert float(q23[1].split(" ± ")[0]) == pytest.approx(result["model"]["q1_dot"]["q2^3"], rel=1e-4)
    # the design k3 beside the identified one, and said what it is
    phys = _cells(html, "moving mass")
    k3 = next(r for r in phys if r[0].startswith("cubic stiffness"))
    assert float(k3[4]) == pytest.approx(result["physical"]["design"]["cubic_stiffness_n_per_m3"], rel=1e-3)
    assert "design k3 = 4 k_l a²" in html
    # typographic units and grammar everywhere on the page
    assert "m/s^2" not in html and "N/m^3" not in html and "m/s²" in html
    assert "1 terms" not in html and re.search(r"\b1 term\b", html)  # q2_dot = q1: one term


def test_validation_figure_has_residual_panels(figures, report_dir):
    """Under each signal its residual, measured − simulated, on its own axis; every panel has an x label."""
    _, ident = report_dir
    fig = figures["validation.png"]
    axes = fig.get_axes()
    residual_axes = [ax for ax in axes if ax.get_ylabel().startswith("residual")]
    assert len(residual_axes) == 3
    sig = ident.states_
    full = residual_axes[0].get_lines()[0].get_ydata()
    assert np.allclose(full, sig.q1_dot[sig.valid] - ident.simulated_q1_dot_)
    assert all(ax.get_xlabel() == "time (s)" for ax in axes)


def test_lambda_path_figure_reads(figures):
    """Integer ticks on the term count, '1 term' / '5 terms', the legend outside the data area."""
    fig = figures["lambda_path.png"]
    fig.canvas.draw()
    main = [ax for ax in fig.get_axes() if ax.get_ylabel() == "MSE"]
    twins = [ax for ax in fig.get_axes() if ax.get_ylabel() == "terms in the model"]
    assert len(main) == len(twins) == 2
    for ax in twins:
        ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] <= t <= ax.get_ylim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks)
    labels = {ax.get_title(): [t.get_text() for t in ax.get_legend().get_texts()] for ax in main}
    assert "chosen: 5 terms" in labels["q1_dot"] and "chosen: 1 term" in labels["q2_dot"]
    for ax in main:
        assert ax.get_xlabel()
        legend, data = ax.get_legend().get_window_extent(), ax.get_window_extent()
        assert legend.y1 <= data.y0  # wholly below the axes: it covers no curve


def test_a_new_report_leaves_nothing_of_the_earlier_one(report_dir, table1_run, tmp_path):
    """A report written into a folder that holds one of its kind replaces it whole: a fit without
    validation draws no validation.png, and the earlier fit's must not be left beside the new page (it
    would show another model's free run). Files that are no report's are left alone."""
    out, _ = report_dir
    folder = tmp_path / "shared"
    folder.mkdir()
    for f in (*FIGURES, "index.html", "model.json", "coefficients.md"):
        (folder / f).write_bytes((out / f).read_bytes())
    (folder / "notes.txt").write_text("the operator's notes")
    assert earlier_report(folder).startswith("the report written there at 20")
    unvalidated = SparseIdentifier(validate=False).fit(table1_run.recording)
    write_report(unvalidated, folder)
    assert not (folder / "validation.png").exists()
    assert all((folder / f).exists() for f in FIGURES if f != "validation.png")
    assert json.loads((folder / "model.json").read_text())["validation"] is None
    assert (folder / "notes.txt").read_text() == "the operator's notes"
    assert earlier_report(tmp_path / "empty") is None


def test_a_report_never_replaces_another_kind_or_the_operators_files(report_dir, tmp_path):
    """`explain --model r2/model.json --report r2/` must not delete the identification report's model.json
    (the very model it explains), nor an identify report an explain report; an index.html or model.json
    shakeid did not write is never overwritten. Each refusal names the folder and what it holds, and
    suggests a subfolder; nothing in the folder changes."""
    out, _ = report_dir
    assert report_kind(out) == "identification"
    with pytest.raises(ShakeidError, match=r"holds an identification report \(index.html, .*model.json.*\); "
                                           r"an explain report there would replace it: .*explain"):
        check_report_folder(out, "explain")
    assert check_report_folder(out, "identification") == out  # the same kind: replaced
    explain_dir = tmp_path / "explain"
    explain_dir.mkdir()
    (explain_dir / "index.html").write_text(Page("Discrepancy report: x", "explain").render())
    (explain_dir / "explain.json").write_text("{}")
    assert report_kind(explain_dir) == "explain"
    with pytest.raises(ShakeidError, match=r"holds an explain report \(index.html, explain.json\)"):
        write_report(SparseIdentifier(), explain_dir)  # refused before it reads the (unfitted) identifier
    assert sorted(p.name for p in explain_dir.iterdir()) == ["explain.json", "index.html"]
    own = tmp_path / "own"
    own.mkdir()
    (own / "index.html").write_text("<html>the lab's own page</html>")
    with pytest.raises(ShakeidError, match=r"own: holds index.html, not written by a shakeid identification "
                                           r"report; they are never overwritten"):
        check_report_folder(own, "identification")
    (own / "index.html").unlink()
    (own / "model.json").write_text('{"mine": 1}')  # `identify --json > own/model.json`
    with pytest.raises(ShakeidError, match=r"holds model.json, not written"):
        check_report_folder(own, "identification")
    assert (own / "model.json").read_text() == '{"mine": 1}'
    # a report written before pages carried the generator tag is still known by its title
    old = tmp_path / "old"
    old.mkdir()
    (old / "index.html").write_text((out / "index.html").read_text().replace(
        "<meta name='generator' content='shakeid identification report'>", ""))
    assert report_kind(old) == "identification" and report_kind(tmp_path / "none") is None
