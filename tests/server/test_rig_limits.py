"""Issue 10's acceptance at the rig's limits: the embedded simulated rig, the longest sweep at the largest
amplitude the limits allow. The recording is complete or ended by a named PLC fault; its quality flags
say what the data are (checked against the file's samples); a model appears only for data that carry one."""
from __future__ import annotations
import pytest

import math
import re

import h5py
import numpy as np

from protocol.plc import Limits

from .conftest import wait_for_job, wait_for_sweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def test_longest_sweep_at_the_largest_amplitude_the_limits_allow(service):
    lim = Limits()
    f_top = 20.0
    # the largest amplitude at 20 Hz: the acceleration limit binds first (40 m/s^2 -> 2.53 mm)
    amp_mm = math.floor(1e3 * min(lim.max_stroke_mm * 1e-3, lim.max_velocity_ms / (2 * math.pi * f_top),
                                  lim.max_acceleration_ms2 / (2 * math.pi * f_top) ** 2) * 100) / 100
    sweep = {"f_start_hz": 1.0, "f_end_hz": f_top, "duration_s": lim.max_duration_s, "amplitude_mm": amp_mm,
             "settle_s": 2.0}
    op = service.client()
    r = op.post("/api/sweeps", json=sweep)
    if r.status_code == 422:  # the preflight predicts the mass in the end stops: its suggestion must pass
        said = re.search(r"passes: amplitude ([0-9.]+) mm or less", r.json()["detail"])
        assert "end stops" in r.json()["detail"] and said, r.text
        amp_mm = float(said.group(1))
        sweep["amplitude_mm"] = amp_mm
        r = op.post("/api/sweeps", json=sweep)
    assert r.status_code == 202, r.text
    assert op.post("/api/sweeps", json={**sweep, "amplitude_mm": amp_mm + 0.05}).status_code in (409, 422)
    end = wait_for_sweep(op, r.json()["id"])
    rec = op.get(f"/api/recordings/{end['recording_id']}").json()
    if end["state"] != "completed":  # ended by the PLC: the fault is named
        assert "PLC fault" in (end["error"] or ""), end
    quality = rec["info"]["quality"]
    with h5py.File(service.data_dir / "recordings" / f"{rec['id']}.h5") as f:
        mass = f["entry/data/mass_acc"][()]
        assert np.all(np.isfinite(mass))
        flagged = {(fl["channel"].decode(), fl["kind"].decode()) for fl in f["entry/quality/flags"][()]}
    # flags true to the data: a second of exact zeros or of one repeated value is flagged, none is invented
    run, longest = 1, 1
    same = mass[1:] == mass[:-1]
    for s in same:
        run = run + 1 if s else 1
        longest = max(longest, run)
    assert (longest >= 2048) <= any(k in (("mass_acc", "dead"), ("mass_acc", "stuck")) for k in flagged)
    full_scale = np.abs(mass).max() >= 32767 / 655.34 - 1e-3
    assert full_scale == (("mass_acc", "clipped") in flagged)
    # a model only for data that can carry one
    jobs = [j for j in op.get("/api/jobs").json() if j["recording_id"] == rec["id"]]
    if end["state"] == "completed":
        job = wait_for_job(op, lambda: op.get(f"/api/jobs/{jobs[0]['id']}").json(), what="identification")
        model = op.get(f"/api/recordings/{rec['id']}/model")
        if not quality["usable_for_identification"]:
            assert job["state"] == "failed" and model.status_code == 404, (job, quality)
            for reason in quality["reasons"]:  # the job names the same faults at the same times of the file
                assert reason.split("(")[0] in job["error"], (reason, job["error"])
        if job["state"] == "completed":
            assert model.status_code == 200 and model.json()["status"] == "ok"
    else:
        assert not jobs  # nothing identified of an aborted recording
