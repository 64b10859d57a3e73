"""The identification report: files a person opens, with the content the paper's figures carry."""
import json

import pytest

from identify.identifier import SparseIdentifier
from reports.identification import FIGURES, write_report
from reports.text import coefficient_table

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def report_dir(table1_run, tmp_path_factory):
    ident = SparseIdentifier().fit(table1_run.recording)
    return write_report(ident, tmp_path_factory.mktemp("report")), ident


def test_report_files(report_dir):
    out, ident = report_dir
    for fig in FIGURES:
        data = (out / fig).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, fig  # a real picture, not an empty canvas
    doc = json.loads((out / "model.json").read_text())
    assert doc["model"] == ident.result()["model"]
    html = (out / "index.html").read_text()
    assert all(f'src="{f}"' in html for f in FIGURES)


def test_coefficient_table_has_table1_layout(report_dir):
    out, ident = report_dir
    table = (out / "coefficients.md").read_text()
    rows = table.strip().splitlines()[2:]
    assert [r.split("|")[1].strip() for r in rows] == ident.library_.names  # every term, in order
    q2_row = next(r for r in rows if r.split("|")[1].strip() == "q1^2")
    assert q2_row.split("|")[2].strip() == "0"
    assert "±" in next(r for r in rows if r.split("|")[1].strip() == "q2^3")
    assert coefficient_table(ident.result()) == table
