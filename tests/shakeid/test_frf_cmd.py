"""`shakeid frf`: the real command (a subprocess) on the two model documents it is given in the lab, what
`shakeid identify --json` prints / the service's model.json (a result with status, states and inputs)
and a bare model file; its JSON, human table, report folder, and one-line refusals."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from identify.frf import frequency_response
from identify.model import SparseModel
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
TABLE1 = {"q1_dot": {"q1": -3.7294, "q2": -971.0169, "q1*q2^2": 1.162e4, "q2^3": -2.5033e6, "zdd": -1.0243},
          "q2_dot": {"q1": 1.0}}


def run(*args):
    return subprocess.run([SHAKEID, *map(str, args)], capture_output=True, text=True, timeout=300)


def one_error_line(proc, message):
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shakeid: error:") and message in lines[0], proc.stderr


def result_document(status="ok"):
    """The identify result's shape (identify.identifier.SparseIdentifier.result; the service writes it as
    model.json): the model under "model", states as a {name: meaning} map, inputs as a list."""
    return {"status": status, "reason": None if status == "ok" else "the fit diverged", "model": TABLE1,
            "states": {"q1": "relative velocity", "q2": "relative displacement"}, "inputs": ["zdd"],
            "method": "admm", "validation": {}}


def test_json_of_an_identify_result(tmp_path):
    path = tmp_path / "model.json"
    path.write_text(json.dumps(result_document()))
    proc = run("frf", path, "--amplitude-mm", 0.8, 1.2, "--band", 1, 20, "--json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert [j["amplitude_mm"] for j in doc["jumps"]] == [0.8, 1.2]
    assert doc["jumps"][0]["jump_down_hz"] is None and doc["jumps"][0]["jump_up_hz"] is None
    expected = frequency_response(SparseModel(TABLE1), 1.2, (1, 20))   # tests/identify/test_frf.py: vs time integration
    assert doc["jumps"][1]["jump_down_hz"] == pytest.approx(expected.jump_down_hz, rel=1e-9)
    assert doc["jumps"][1]["jump_up_hz"] == pytest.approx(expected.jump_up_hz, rel=1e-9)
    r = doc["responses"][1]
    assert r["branches"][0]["stable"].count(False) > 0 and len(r["folds"]) == 2
    assert len(r["branches"][0]["frequency_hz"]) == len(r["branches"][0]["amplitude_mm"]) == len(r["branches"][0]["stable"])
    assert doc["backbone"]["frequency_hz"] and doc["backbone"]["frequency_hz"][0] == pytest.approx(4.96, abs=0.01)


def test_table_and_report_of_a_model_file(tmp_path):
    path = tmp_path / "table1.json"
    SparseModel(TABLE1).save(path)
    out = tmp_path / "frf"
    proc = run("frf", path, "--amplitude-mm", 1.1, 1.3, "--report", out)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    row = next(line.split() for line in lines if line.split()[:1] == ["1.1"])
    assert float(row[1]) > float(row[2]) > 5.0        # jump down (up-sweep) above jump up (down-sweep)
    row = next(line.split() for line in lines if line.split()[:1] == ["1.3"])
    assert row[1] == "-"                               # no fold before the range of validity ends...
    assert any("range of validity" in line for line in lines)   # ...and said so
    assert sorted(p.name for p in out.iterdir()) == ["frf.json", "frf.png", "index.html"]
    assert (out / "frf.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "index.html").read_text()
    assert "shakeid frf report" in page and "frf.png" in page and "range of validity" in page
    assert json.loads((out / "frf.json").read_text())["jumps"][1]["jump_down_hz"] is None
    # a second run replaces its own report; an identification report's folder is refused
    assert run("frf", path, "--amplitude-mm", 1.1, "--report", out).returncode == 0
    ident = tmp_path / "ident"
    ident.mkdir()
    (ident / "index.html").write_text("<!doctype html><meta name='generator' content='shakeid identification report'>")
    one_error_line(run("frf", path, "--amplitude-mm", 1.1, "--report", ident), "identification report")


def test_refusals(tmp_path):
    failed = tmp_path / "failed.json"
    failed.write_text(json.dumps(result_document("failed")))
    one_error_line(run("frf", failed, "--amplitude-mm", 1.0), "identification failed")
    force = tmp_path / "force.json"
    SparseModel({"q1_dot": {"q2": -100.0, "u": 1.0}, "q2_dot": {"q1": 1.0}}, inputs=("u",)).save(force)
    one_error_line(run("frf", force, "--amplitude-mm", 1.0), "base-excited")
    good = tmp_path / "good.json"
    SparseModel(TABLE1).save(good)
    one_error_line(run("frf", good, "--amplitude-mm", 1.0, "--band", 9, 3), "F_LO must be below F_HI")
    proc = run("frf", good, "--amplitude-mm", -1)
    assert proc.returncode == 2 and "amplitude" in proc.stderr
    one_error_line(run("frf", tmp_path / "missing.json", "--amplitude-mm", 1.0), "missing.json")
