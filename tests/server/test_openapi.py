"""A bounded schemathesis run against the service's own OpenAPI document: no 5xx, documented status
codes, content types and response bodies. The schema cannot state the rig's combined limits (peak
velocity and acceleration), so schema-valid sweeps may still get 422: `positive_data_acceptance` is the
one check left out."""
import pytest
import os
import re
import subprocess
import sys
from pathlib import Path

from .conftest import OPERATOR
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SCHEMATHESIS = str(Path(sys.executable).with_name("schemathesis"))
CHECKS = "not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance"


def _run(service, tmp_path, *extra, env=None):
    p = subprocess.run([SCHEMATHESIS, "run", f"{service.url}/openapi.json", "--checks", CHECKS,
                        "--max-examples", "15", "--seed", "7", "--generation-database", "none", "--no-color",
                        "--request-timeout", "20", *extra],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path, env=env)
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:] + service.output()[-3000:]
    m = re.search(r"(\d+) generated, (\d+) passed", p.stdout)
    assert m and m.group(1) == m.group(2) and int(m.group(1)) > 500, p.stdout[-3000:]  # every case passed
    return p.stdout


def test_no_server_errors_with_an_operator_token(service, tmp_path):
    _run(service, tmp_path, "-H", f"Authorization: Bearer {OPERATOR}")
    assert "Traceback" not in service.output()


def test_no_server_errors_without_a_token(service, tmp_path):
    _run(service, tmp_path)  # every protected operation answers 401, as documented


def test_no_server_errors_with_non_finite_numbers_in_bodies(service, tmp_path):
    """NaN, Infinity, -Infinity and 1e400 in every numeric field of every JSON body (a hook rewrites the
    generated bodies): 422 naming the field, never a 5xx (the 422 handler used to crash on them)."""
    sent = tmp_path / "nonfinite-bodies.txt"
    env = {**os.environ, "SCHEMATHESIS_HOOKS": "nonfinite_hooks", "NONFINITE_COUNT_FILE": str(sent),
           "PYTHONPATH": str(Path(__file__).parent)}
    _run(service, tmp_path, "-H", f"Authorization: Bearer {OPERATOR}", "--include-method", "POST", env=env)
    bodies = sent.read_text().splitlines()
    assert len(bodies) > 20 and any("1e400" in b for b in bodies) and any("NaN" in b for b in bodies)
    assert "Traceback" not in service.output()
    with service.client() as op:  # and the connection is still served afterwards: one example by hand
        r = op.post("/api/sweeps", content=b'{"f_start_hz": NaN, "f_end_hz": 20, "duration_s": 1e400, '
                                           b'"amplitude_mm": 1.3}', headers={"Content-Type": "application/json"})
        assert r.status_code == 422
        fields = {tuple(e["loc"]) for e in r.json()["detail"]}
        assert fields == {("body", "f_start_hz"), ("body", "duration_s")}
        assert op.get("/api/rig").status_code == 200
