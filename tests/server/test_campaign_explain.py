"""A campaign's explanation end to end over loopback: a real `shakeid serve` (its controller as a child
process, the embedded simulated rig at 10x) runs a campaign of an up and a down sweep; one explanation of
both is asked for (POST /api/campaigns/{id}/explain), run by the service's job machinery and served
(GET /api/campaigns/{id}/explanation). States are polled, never timed."""
from __future__ import annotations

import json
import subprocess

import pytest

from .conftest import OPERATOR, SHAKEID, VIEWER, Service, jobs_seen, wait_for, wait_while_moving

pytestmark = pytest.mark.slow  # two sweeps, their identifications, then the explanation

ENDED = ("completed", "paused", "aborted")


def _ended(client, cid: str) -> dict:
    return wait_for(lambda: (c := client.get(f"/api/campaigns/{cid}").json())["state"] in ENDED and c, 180,
                    f"campaign {cid} to end")


def _start(client, plan: dict) -> str:
    r = client.post("/api/campaigns", json=plan)
    assert r.status_code == 202, r.text
    return r.json()["id"]


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("campaign-explain") / "data").start()
    yield s
    s.stop()


def test_a_completed_campaign_is_explained_over_its_up_and_down_sweeps(service):
    op, viewer = service.client(), service.client(VIEWER)
    # one sweep is not a campaign's explanation: refused in the operator's words, nothing queued
    one = _start(op, {"name": "single", "sweep": {"f_start_hz": 3.0, "f_end_hz": 15.0, "duration_s": 4.0,
                                                  "settle_s": 0.5}, "amplitudes_mm": [1.0], "directions": ["up"]})
    assert _ended(viewer, one)["state"] == "completed"
    r = op.post(f"/api/campaigns/{one}/explain")
    assert r.status_code == 409 and "has 1 usable recording(s)" in r.json()["detail"], r.text

    plan = {"name": "updown", "sweep": {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 30.0, "settle_s": 1.0},
            "amplitudes_mm": [1.0], "directions": ["up", "down"], "rest_between_s": 0.2}
    cid = _start(op, plan)
    # its first sweep takes seconds of wall time: the campaign is running when asked
    r = op.post(f"/api/campaigns/{cid}/explain")
    assert r.status_code == 409 and f"campaign {cid} is running" in r.json()["detail"], r.text
    r = viewer.get(f"/api/campaigns/{cid}/explanation")
    assert r.status_code == 404 and "none was asked for" in r.json()["detail"], r.text
    c = _ended(viewer, cid)
    assert c["state"] == "completed" and len(c["recording_ids"]) == 2, c
    assert viewer.post(f"/api/campaigns/{cid}/explain").status_code == 403  # an operator's request
    assert op.post("/api/campaigns/0123456789ab/explain").status_code == 404

    # asked for from the command line (`shakeid explain --server --campaign`): queued, followed, printed
    cli = _explain_cli(service, cid)
    assert cli.returncode == 0, cli.stdout + cli.stderr
    assert "2 recordings explained together:" in cli.stdout and "missing effect:" in cli.stdout, cli.stdout
    assert "asked for: job" in cli.stdout, cli.stdout
    job = viewer.get(f"/api/campaigns/{cid}").json()["explanation"]  # in its status
    assert job["kind"] == "explain_campaign" and job["options"]["recording_ids"] == c["recording_ids"]
    assert job["options"]["campaign_id"] == cid and job["state"] == "completed", job
    assert viewer.get(f"/api/campaigns/{one}").json()["explanation"] is None
    r = viewer.get(f"/api/campaigns/{cid}/explanation")
    assert r.status_code == 200, r.text
    result = r.json()
    # one explanation naming both recordings, in plan order, each with its own sweep direction
    assert [s["source"] for s in result["recordings"]] == [f"{rid}.h5" for rid in c["recording_ids"]]
    up, down = result["recordings"]
    assert up["sweep_rho"] > 0.5 > -0.5 > down["sweep_rho"], (up["sweep_rho"], down["sweep_rho"])
    out = service.data_dir / "results" / job["id"]
    assert json.loads((out / "explain.json").read_text()) == result
    assert (out / "report" / "index.html").is_file() and not (out / "report.partial").exists()
    # the single recording's own explanation is not this one
    r = viewer.get(f"/api/recordings/{c['recording_ids'][0]}/explanation")
    assert r.status_code == 404, r.text
    # asked again: the delivered explanation, as JSON, and no new job
    again = _explain_cli(service, cid, "--json")
    assert again.returncode == 0 and json.loads(again.stdout) == result, again.stderr
    assert viewer.get(f"/api/campaigns/{cid}").json()["explanation"]["id"] == job["id"]
    # refusals in one line, exit 2: a campaign of one recording, no such campaign, a viewer asking for one
    for campaign, token, said in ((one, OPERATOR, "has 1 usable recording(s)"), ("0123456789ab", OPERATOR,
                                  "no campaign 0123456789ab"), (one, VIEWER, "403")):
        refused = _explain_cli(service, campaign, token=token)
        assert refused.returncode == 2 and said in refused.stderr and refused.stderr.count("\n") == 1, refused.stderr


def _explain_cli(service, campaign_id: str, *extra, token: str = OPERATOR) -> subprocess.CompletedProcess:
    """`shakeid explain --server --campaign`, waited for while the service's jobs move (its job runs at nice
    +10: a busy machine makes it as long as it gives it; conftest.wait_while_moving)."""
    args = [SHAKEID, "explain", "--server", service.url, "--token", token, "--campaign", campaign_id, *extra]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with service.client(VIEWER) as viewer:
            wait_while_moving(lambda: proc.poll() is not None, lambda: jobs_seen(viewer), what="shakeid explain")
    finally:
        if proc.poll() is None:
            proc.kill()
    out, err = proc.communicate()
    return subprocess.CompletedProcess(args, proc.returncode, out, err)
