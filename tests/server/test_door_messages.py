"""Refusals at the door in the operator's words: the field, the rule, no regex, no server path."""
import pytest
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def test_campaign_name_and_non_finite_upload_rate_are_refused_in_words(service):
    with service.client() as op:
        r = op.post("/api/campaigns", json={"name": "bad name!", "sweep": {"f_start_hz": 1, "f_end_hz": 20,
                                                                            "duration_s": 30}, "amplitudes_mm": [1]})
        assert r.status_code == 422
        err = r.json()["detail"][0]
        assert err["loc"] == ["body", "name"] and err["msg"].startswith("should be a campaign name: 1-64 letters"), err
        assert ".png" not in err["msg"]
        for rate in ("NaN", "inf", "-Infinity"):
            r = op.post(f"/api/recordings?filename=r.csv&fs_hz={rate}", content=b"t,zdd,xdd\n0,0,0\n")
            assert r.status_code == 422
            err = r.json()["detail"][0]
            assert err["loc"] == ["query", "fs_hz"] and "finite number" in err["msg"] and "10000000" not in err["msg"]
        # a plot's name keeps its own words
        r = op.get("/api/recordings/0123456789ab/plots/BAD.png")
        assert r.status_code == 422 and "a plot's file name" in r.json()["detail"][0]["msg"]
        assert op.get("/api/recordings").json() == []  # nothing stored


def test_sweeps_and_jobs_beyond_what_the_rig_or_the_recording_allow_are_refused_at_the_request(service, tmp_path,
                                                                                              table1_run):
    from identify.data.recording import write_csv

    with service.client() as op:
        # a duration the PLC's float32 setpoint reads as 0: refused by the limits, the rig stays ready
        r = op.post("/api/sweeps", json={"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 1e-300, "amplitude_mm": 1.0})
        assert r.status_code == 422 and "duration 1e-300 s outside the limit 1-600 s" in r.text, r.text
        assert op.get("/api/rig").json()["plc"]["state"] not in ("fault", "estop")
        csv = tmp_path / "r.csv"
        write_csv(csv, table1_run.recording)
        rec = op.post("/api/recordings?filename=r.csv", content=csv.read_bytes())
        assert rec.status_code == 201, rec.text
        rec_id, fs = rec.json()["id"], table1_run.recording.fs_hz
        r = op.post(f"/api/recordings/{rec_id}/identify", json={"band_hz": [1.0, fs]})
        assert r.status_code == 422
        err = r.json()["detail"][0]
        assert err["loc"] == ["body", "band_hz"] and f"Nyquist frequency {fs / 2:g} Hz" in err["msg"], err
        r = op.post(f"/api/recordings/{rec_id}/identify", json={"extra_terms": ["*".join(["q1"] * 5000)]})
        assert r.status_code == 422, r.text[:300]
        assert "degree 5000" in r.text or "extra_terms" in r.text
        assert op.get("/api/jobs").json() == []  # nothing queued
