"""An identification job whose frequency response cannot be made still delivers its model: the worker
(server.worker.run_job, in this process, on a real CSV) writes frf.json with the reason beside model.json,
and no overlay figure."""
import pytest
import json

import numpy as np

from identify.data.recording import write_csv
from server.worker import FRF_FILE, run_job
from sim.synth import noise_input_recording
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def test_a_recording_that_is_not_a_sweep_is_identified_and_its_frf_says_why(tmp_path):
    seed = int(np.random.SeedSequence().entropy % 2**31)
    print(f"seed {seed}")
    path = tmp_path / "random.csv"
    write_csv(path, noise_input_recording(seed))
    summary = run_job("identify", str(path), {}, str(tmp_path / "job"))
    assert "q2^3" in summary["terms"]["q1_dot"]
    frf = json.loads((tmp_path / "job" / FRF_FILE).read_text())
    assert frf["status"] == "not_applicable" and "random.csv: not a sine sweep" in frf["reason"], frf
    assert str(tmp_path) not in json.dumps(frf)  # the operator's name for the recording, not the server's path
    assert json.loads((tmp_path / "job" / "model.json").read_text())["frf"] == frf
    assert not (tmp_path / "job" / "report" / "frf_overlay.png").exists()
    assert "No side-by-side frequency response: no sweep to compare with: random.csv: not a sine sweep" in \
        (tmp_path / "job" / "report" / "index.html").read_text()
