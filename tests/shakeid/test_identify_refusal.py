"""`shakeid identify` and the service's job worker refuse data that cannot carry a model (exit 2, one
line naming the file and the reasons; --accept-faulty / accept_faulty overrides and the result says so),
and report a fitted model that does not reproduce the motion as failed (exit 1, status "failed")."""
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.recorder import Recorder
from identify.errors import ShakeidError
from identify.data.recording import Recording, write_csv
from server.worker import run_job
from shakeid.cli import main

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def _h5(path, rec, status="complete", reason=""):
    r = Recorder(path, fs_hz=rec.fs_hz)
    r.append(0, np.column_stack([rec.input, rec.output]))
    r.close(status, reason)
    return path


@pytest.fixture(scope="module")
def dead_csv(table1_run, tmp_path_factory):
    """The issue's recording: the mass accelerometer reads exactly 0 from 40 % of the record on."""
    rec = table1_run.recording
    out = rec.output.copy()
    out[int(0.4 * out.size):] = 0.0
    path = tmp_path_factory.mktemp("dead") / "dead.csv"
    write_csv(path, Recording(rec.input, out, rec.fs_hz))
    return path


@pytest.mark.parametrize("status,reason", [("fault", "PLC fault: injected"), ("aborted", "operator abort")])
def test_a_recording_that_did_not_complete_is_refused_unless_accepted(tmp_path, table1_run, capsys, status, reason):
    path = _h5(tmp_path / f"{status}.h5", table1_run.recording, status, reason)
    assert main(["identify", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0] == (f"shakeid: error: {path}: status is {status} ({reason}), not complete "
                                        "(use --accept-faulty to identify it anyway)")
    assert main(["identify", str(path), "--accept-faulty", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted_faulty"] == [f"status is {status} ({reason}), not complete"] and doc["status"] == "ok"
    assert doc["data_quality"]["flags"] == []  # the data itself is clean


@pytest.mark.slow
def test_a_dead_output_channel_is_refused_with_the_reason_and_accepted_on_request(dead_csv, table1_run):
    n = table1_run.recording.n_samples
    k = int(0.4 * n)
    proc = subprocess.run([SHAKEID, "identify", str(dead_csv)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"shakeid: error: {dead_csv}: mass_acc reads exactly 0 from "
                                                   f"t = {k / 2048:.3f} s for {n - k} samples")
    assert lines[0].endswith("(use --accept-faulty to identify it anyway)")
    proc = subprocess.run([SHAKEID, "identify", str(dead_csv), "--accept-faulty", "--json"], capture_output=True,
                          text=True, timeout=300)
    doc = json.loads(proc.stdout)
    assert len(doc["accepted_faulty"]) == 1 and "mass_acc reads exactly 0" in doc["accepted_faulty"][0]
    (flag,) = doc["data_quality"]["flags"]
    assert (flag["channel"], flag["kind"], flag["first"], flag["count"]) == ("mass_acc", "dead", k, n - k)
    assert proc.returncode == (0 if doc["status"] == "ok" else 1)  # the model's own verdict decides the exit


def test_a_file_without_quality_flags_is_assessed_on_read(tmp_path, table1_run, capsys):
    rec = table1_run.recording
    out = rec.output.copy()
    out[50000:] = 0.0
    path = _h5(tmp_path / "old.h5", Recording(rec.input, out, rec.fs_hz))
    with h5py.File(path, "r+") as f:
        del f["entry/quality"]  # written before quality flags
    assert main(["identify", str(path)]) == 2
    assert "mass_acc reads exactly 0 from t = 24.414 s" in capsys.readouterr().err
    # the good stretch before the fault identifies
    assert main(["identify", str(path), "--samples", "0", "50000", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["data_quality"]["usable_for_identification"] is True


@pytest.mark.slow
def test_a_model_that_is_not_a_model_exits_1_while_the_default_fit_is_ok(table1_csv):
    good = subprocess.run([SHAKEID, "identify", str(table1_csv), "--json"], capture_output=True, text=True, timeout=300)
    assert good.returncode == 0 and json.loads(good.stdout)["status"] == "ok" and good.stderr == ""
    bad = subprocess.run([SHAKEID, "identify", str(table1_csv), "--max-terms", "1", "--json"], capture_output=True,
                         text=True, timeout=300)
    doc = json.loads(bad.stdout)
    assert bad.returncode == 1 and doc["status"] == "failed" and "one-step fit" in doc["reason"]
    assert doc["model"]["q1_dot"].keys() == {"zdd"}
    assert bad.stderr.strip() == (f"shakeid: identification failed: {table1_csv}: {doc['reason']} "
                                  f"(`shakeid explain {table1_csv}` looks for the effect the library misses)")
    human = subprocess.run([SHAKEID, "identify", str(table1_csv), "--max-terms", "3"], capture_output=True, text=True,
                           timeout=300)
    assert human.returncode == 1 and "MODEL FAILED: held-out free-run fit of the acceleration is -4" in human.stdout


@pytest.mark.slow
def test_the_job_worker_refuses_accepts_on_request_and_fails_a_non_model(tmp_path, table1_run, dead_csv):
    path = _h5(tmp_path / "f.h5", table1_run.recording, "fault", "PLC fault: watchdog")
    with pytest.raises(ShakeidError, match=r"f.h5: status is fault \(PLC fault: watchdog\), not complete \(set "
                                           r"accept_faulty to identify it anyway\)"):
        run_job("identify", str(path), {}, str(tmp_path / "job1"))
    assert not (tmp_path / "job1" / "model.json").exists()
    summary = run_job("identify", str(path), {"accept_faulty": True}, str(tmp_path / "job2"))
    doc = json.loads((tmp_path / "job2" / "model.json").read_text())
    assert doc["accepted_faulty"] == summary["accepted_faulty"] == ["status is fault (PLC fault: watchdog), not complete"]
    with pytest.raises(ShakeidError, match="dead.csv: mass_acc reads exactly 0"):
        run_job("identify", str(dead_csv), {}, str(tmp_path / "job3"))
    with pytest.raises(ShakeidError, match="identification failed: held-out free-run fit"):
        run_job("identify", str(_h5(tmp_path / "ok.h5", table1_run.recording)), {"max_terms": 1}, str(tmp_path / "job4"))
    assert not (tmp_path / "job4" / "model.json").exists()


@pytest.mark.slow
def test_explain_refuses_the_same_data_unless_accepted(tmp_path, table1_run, dead_csv, capsys):
    """The discrepancy analysis gets the same gate as identification, in the CLI and in a job."""
    assert main(["explain", str(dead_csv)]) == 2
    err = capsys.readouterr().err.strip()
    assert "mass_acc reads exactly 0" in err and err.endswith("(use --accept-faulty to analyse it anyway)")
    path = _h5(tmp_path / "a.h5", table1_run.recording, "aborted", "operator abort")
    with pytest.raises(ShakeidError, match=r"status is aborted \(operator abort\), not complete \(set accept_faulty "
                                           r"to analyse it anyway\)"):
        run_job("explain", str(path), {}, str(tmp_path / "job"))
    run_job("explain", str(path), {"accept_faulty": True}, str(tmp_path / "job2"))
    doc = json.loads((tmp_path / "job2" / "explain.json").read_text())
    assert doc["accepted_faulty"] == ["status is aborted (operator abort), not complete"]
