"""No delivered result is lost: `shakeid sweep --server --wait-model` returns with the model, the service
gets a normal stop (SIGTERM) at once, and is started again; three rounds on one data directory, real
processes. Every model the operator saw is served after each restart, with its report, and no job fails."""
import pytest
import re
import signal
import subprocess

from .conftest import OPERATOR, Service, wait_for
from .test_remote_cli import SHAKEID
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

ARGS = ["--f-start-hz", "1", "--f-end-hz", "20", "--duration-s", "20", "--amplitude-mm", "1.3", "--settle-s", "1"]


def test_a_model_seen_before_a_stop_is_served_after_the_restart(tmp_path):
    service = Service(tmp_path / "data")
    seen: dict[str, dict] = {}
    try:
        service.start()
        for _ in range(3):
            p = subprocess.run([SHAKEID, "sweep", "--server", service.url, "--token", OPERATOR, *ARGS, "--wait-model"],
                               capture_output=True, text=True, timeout=300)
            assert p.returncode == 0, p.stdout + p.stderr
            rec_id = re.search(r"recording ([0-9a-f]{12})", p.stdout).group(1)
            with service.client() as op:
                seen[rec_id] = op.get(f"/api/recordings/{rec_id}/model").json()
            service.stop(signal.SIGTERM)  # right after the model was delivered
            assert "Traceback" not in service.output(), service.output()[-3000:]
            service.start()
            with service.client() as op:
                for rid, model in seen.items():  # at once, not after a re-run: every model seen so far
                    r = op.get(f"/api/recordings/{rid}/model")
                    assert r.status_code == 200 and r.json() == model, (rid, r.text)
                jobs = wait_for(lambda: (js := op.get("/api/jobs").json())
                                and all(j["state"] in ("completed", "failed") for j in js) and js, 120, "jobs settled")
                assert [j for j in jobs if j["state"] == "failed"] == []
                for rid in seen:
                    assert "input.png" in op.get(f"/api/recordings/{rid}/plots").json()
    finally:
        service.stop()
