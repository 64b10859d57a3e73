"""`shakeid sweep --server`: the CLI driving a sweep through a running service (two real processes)."""
import pytest
import re
import subprocess
import sys
from pathlib import Path

from daq.recorder import describe

from .conftest import OPERATOR, VIEWER
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
ARGS = ["--f-start-hz", "1", "--f-end-hz", "20", "--duration-s", "30", "--amplitude-mm", "1.3", "--settle-s", "1"]


def _sweep(service, *extra, token=OPERATOR):
    return subprocess.run([SHAKEID, "sweep", "--server", service.url, "--token", token, *ARGS, *extra],
                          capture_output=True, text=True, timeout=180)


def test_sweep_through_the_service_downloads_the_file_and_prints_the_model(service, tmp_path):
    out = tmp_path / "copy.h5"
    p = _sweep(service, "--out", str(out), "--wait-model")
    assert p.returncode == 0, p.stdout + p.stderr
    assert "completed" in p.stdout and "downloaded" in p.stdout
    # no terminal here: plain progress lines (shakeid/progress.py), the last one where the sweep ended
    assert "\r" not in p.stderr and p.stderr.splitlines()[-1] == "sweep 100 % (30.0 s of 30 s)  completed"
    info = describe(out)
    assert info["status"] == "complete" and info["gaps"] == [] and info["samples"] > 30 * 2048
    assert "q1*q2^2" in p.stdout and "free-run fit" in p.stdout  # the model table, as `shakeid identify`
    # the progress lines say what a local sweep's say: the frequency and the table's position
    assert re.search(r"^sweep \d+ % \(.* s of 30 s\)  running +\d+\.\d\d Hz  table +[+-]\d+\.\d\d mm$", p.stderr, re.M), \
        p.stderr
    # the PLC is done a poll or two before the service closes the recording: those lines say so, not
    # "running 0.00 Hz" (which the PLC's frequency after its sweep would give; seen whenever a poll fell there)
    assert not re.search(r"running +0\.00 Hz", p.stderr), p.stderr
    rec_id = re.search(r"recording ([0-9a-f]{12})", p.stdout).group(1)
    assert f"plots and report: {service.url}/#/recording/{rec_id}" in p.stdout


def test_refusals_arrive_as_one_line_errors(service):
    unsafe = _sweep(service, "--amplitude-mm", "9")
    assert unsafe.returncode == 2 and "422 sweep refused: amplitude 9 mm above the stroke limit" in unsafe.stderr
    # beyond any rig: still the rig's limit that refuses it, in its words (not the schema's bound)
    far = _sweep(service, "--amplitude-mm", "2000")
    assert far.returncode == 2 and "422 sweep refused: amplitude 2000 mm above the stroke limit 5 mm" in far.stderr
    # what no rig has is refused by the command line itself, naming the option
    negative = _sweep(service, "--amplitude-mm", "-1")
    assert negative.returncode == 2 and "Traceback" not in negative.stderr
    assert "argument --amplitude-mm: must be > 0, got -1" in negative.stderr, negative.stderr
    # what the request schema refuses, field by field in words, not as FastAPI's JSON list
    long_settle = _sweep(service, "--settle-s", "100")
    assert long_settle.returncode == 2 and "Traceback" not in long_settle.stderr
    assert "422 settle_s: Input should be less than or equal to 60 (got 100.0)" in long_settle.stderr, long_settle.stderr
    assert '"loc"' not in long_settle.stderr and "[{" not in long_settle.stderr
    viewer = _sweep(service, token=VIEWER)
    assert viewer.returncode == 2 and "403" in viewer.stderr and "operator role" in viewer.stderr
    nobody = subprocess.run([SHAKEID, "sweep", "--server", "http://127.0.0.1:9", "--token", OPERATOR, *ARGS],
                            capture_output=True, text=True, timeout=60)
    assert nobody.returncode == 2 and "does not answer" in nobody.stderr and "Traceback" not in nobody.stderr


def test_the_progress_label_between_the_plcs_end_and_the_recordings_close(service):
    """What the remote progress line says while the sweep's record still reads running but the PLC has
    finished (the window the test above may or may not poll in): read from the real service with the
    PLC idle, it says the sweep is finishing, not "running 0.00 Hz"; a queued sweep shows its state alone."""
    from shakeid.remote import ServiceClient, _rig_label

    client = ServiceClient(service.url, OPERATOR)
    assert client.request("GET", "/api/rig")["plc"]["state"] in ("idle", "done")
    assert _rig_label(client, "running").startswith("finishing: the PLC is ")
    assert _rig_label(client, "queued") == "queued"
