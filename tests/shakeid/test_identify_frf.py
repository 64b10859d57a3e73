"""`shakeid identify` carries the frequency response beside the recording's sweep: the real command on
the paper's sweep of the Table 1 rig (1-20 Hz in 60 s at 1.3 mm). Its --json has "frf" (the recorded
table amplitude, the up-sweep's measured jump judged against the model's prediction: at 1.3 mm the upper
branch leaves the model's range of validity before it folds, so the sweep's steep passage is compared with
the model's own run over the same sweep); --report draws the overlay and writes the section; the human
output prints a line per flag."""
import json
import subprocess
import sys
from pathlib import Path

import pytest
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def test_identify_json_and_report_carry_the_side_by_side(table1_csv, tmp_path):
    proc = subprocess.run([SHAKEID, "identify", str(table1_csv), "--json", "--report", str(tmp_path / "rep")],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    frf = json.loads(proc.stdout)["frf"]
    assert frf["status"] == "ok", frf
    (entry,) = frf["amplitudes"]
    assert entry["amplitude_mm"] == pytest.approx(1.3, rel=0.02)
    predicted = entry["predicted"]["model"]
    assert predicted["jump_down_hz"] is None and any("range of validity" in n for n in predicted["notes"])
    (jump,) = frf["jumps"]
    assert jump["direction"] == "up" and jump["measured_hz"] is not None
    p = jump["predicted"]["model"]
    assert p["fold_hz"] is None and p["model_sweep_jump_hz"] is not None
    assert frf["flagged"] == (p["agrees"] is False)
    assert json.loads((tmp_path / "rep" / "model.json").read_text())["frf"] == frf
    assert (tmp_path / "rep" / "frf_overlay.png").read_bytes().startswith(b"\x89PNG")
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "Frequency response: predicted beside measured" in html and "src='frf_overlay.png'" in html
    human = subprocess.run([SHAKEID, "identify", str(table1_csv)], capture_output=True, text=True, timeout=600)
    assert human.returncode == 0, human.stderr
    assert sum(line.startswith("flagged: ") for line in human.stdout.splitlines()) == len(frf["flags"])
