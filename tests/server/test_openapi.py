"""A bounded schemathesis run against the service's own OpenAPI document: no 5xx, documented status
codes, content types and response bodies. The schema cannot state the rig's combined limits (peak
velocity and acceleration), so schema-valid sweeps may still get 422: `positive_data_acceptance` is the
one check left out."""
import re
import subprocess
import sys
from pathlib import Path

from .conftest import OPERATOR

SCHEMATHESIS = str(Path(sys.executable).with_name("schemathesis"))
CHECKS = "not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance"


def _run(service, tmp_path, *extra):
    p = subprocess.run([SCHEMATHESIS, "run", f"{service.url}/openapi.json", "--checks", CHECKS,
                        "--max-examples", "15", "--seed", "7", "--generation-database", "none", "--no-color",
                        "--request-timeout", "20", *extra],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:] + service.output()[-3000:]
    m = re.search(r"(\d+) generated, (\d+) passed", p.stdout)
    assert m and m.group(1) == m.group(2) and int(m.group(1)) > 500, p.stdout[-3000:]  # every case passed


def test_no_server_errors_with_an_operator_token(service, tmp_path):
    _run(service, tmp_path, "-H", f"Authorization: Bearer {OPERATOR}")
    assert "Traceback" not in service.output()


def test_no_server_errors_without_a_token(service, tmp_path):
    _run(service, tmp_path)  # every protected operation answers 401, as documented
