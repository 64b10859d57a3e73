"""`shakeid identify A.h5 B.h5 [C.csv] [--json]`: one model of several recordings (issue 13), on simulated
recordings of the Table 1 rig with known coefficients."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daq.recorder import Recorder
from identify.data.recording import write_csv
from shakeid.cli import main
from sim.rig import RigParameters
from sim.sensors import Accelerometer
from sim.synth import run_sweep
from protocol.sweep import SineSweep

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def _recording(amplitude_mm, seed):
    s = Accelerometer(noise_fraction=0.005)
    return run_sweep(RigParameters.paper_table1(), SineSweep(1, 20, 30, amplitude_mm), fs_hz=1024, seed=seed,
                     table_sensor=s, mass_sensor=s).recording


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("joint")
    out = []
    for name, amp, seed in (("a.h5", 1.3, 1), ("b.h5", 1.2, 2)):
        rec = _recording(amp, seed)
        r = Recorder(d / name, fs_hz=rec.fs_hz)
        r.append(0, np.column_stack([rec.input, rec.output]))
        r.close("complete", "")
        out.append(d / name)
    write_csv(d / "c.csv", _recording(1.1, 3))
    return out + [d / "c.csv"]


@pytest.mark.slow
def test_identify_two_h5_files_prints_one_joint_json_document(files):
    a, b = str(files[0]), str(files[1])
    proc = subprocess.run([SHAKEID, "identify", a, b, "--json", "--placements", "4"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    truth = RigParameters.paper_table1().model().equations["q1_dot"]
    assert set(res["model"]["q1_dot"]) == set(truth)
    for term, true in truth.items():
        assert res["model"]["q1_dot"][term] == pytest.approx(true, rel=0.02), term
    assert set(res["standard_errors"]["q1_dot"]) == set(truth) and res["inclusion_probability"]
    assert res["status"] == "ok" and res["validation"]["heldout"]["q2"]["fit_percent"] > 90
    assert [r["source"] for r in res["recordings"]] == [a, b]
    for r in res["recordings"]:
        assert r["status"] == "ok" and r["data_quality"]["usable_for_identification"]
        assert r["validation"]["heldout"]["q2"]["fit_percent"] > 90


def test_identify_three_files_prints_the_joint_table_and_one_line_per_recording(files, capsys):
    assert main(["identify", *map(str, files), "--placements", "0", "--bias-replicates", "0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("identified 3 recordings jointly")
    assert "| q1*q2^2 |" in out
    rows = [line for line in out.splitlines() if any(line.startswith(f"| {f}") for f in map(str, files))]
    assert len(rows) == 3 and all(line.rstrip().endswith("| ok |") for line in rows)


def test_a_joint_report_has_a_row_and_a_panel_per_recording_and_every_sweep_beside_the_model(files, capsys, tmp_path):
    """`--report` of a joint fit (it was refused): the recordings' table, the joint model, the pooled and the
    per-recording validation, input and output figures with a panel per recording, and the predicted
    frequency response beside every sweep (the three sweeps' 1.1-1.3 mm: two amplitude groups, one table
    row per sweep); model.json is the --json document. A folder holding the operator's own index.html is
    refused before any file is read."""
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "index.html").write_text("my notes")
    assert main(["identify", *map(str, files), "--report", str(tmp_path / "mine")]) == 2
    assert "not written by a shakeid identification report" in capsys.readouterr().err
    report = tmp_path / "r"
    assert main(["identify", *map(str, files), "--placements", "0", "--bias-replicates", "0",
                 "--report", str(report)]) == 0
    assert f"report: {report / 'index.html'}" in capsys.readouterr().out
    assert {"index.html", "model.json", "coefficients.md", "input.png", "output.png", "lambda_path.png",
            "frf_overlay.png"} <= {p.name for p in report.iterdir()}
    assert not (report / "validation.png").exists()  # a single recording's time plot: the table says it per recording
    doc = json.loads((report / "model.json").read_text())
    assert [r["source"] for r in doc["recordings"]] == list(map(str, files))
    assert doc["frf"]["status"] == "ok" and len(doc["frf"]["jumps"]) == 3
    page = (report / "index.html").read_text()
    assert "Identification report: a.h5, b.h5, c.csv (joint)" in page
    for f in files:  # in the recordings' table and in the per-recording validation table
        assert page.count(f"<td>{f.name}</td>") == 2, f.name
    import matplotlib.image as mpimg
    one = mpimg.imread(report / "input.png")
    assert one.shape[0] > 1.8 * one.shape[1] * 3 / 9  # three panels: taller than one 9 x 3 panel


def test_one_recording_twice_is_refused(files, capsys, tmp_path):
    """The same file twice (by any path to it) would count its evidence twice: every standard error
    shrunk by sqrt(2), as if a second recording had been made. Refused before anything is read."""
    twin = tmp_path / "same.h5"
    twin.symlink_to(files[0])
    for second in (str(files[0]), str(twin)):
        assert main(["identify", str(files[0]), str(files[1]), second]) == 2
        err = capsys.readouterr().err
        assert f"{second}: the same recording as {files[0]}" in err and "standard errors" in err, err
    # a copy of the file, by another name: the same samples, refused as well (identify.joint)
    copy = tmp_path / "copy.h5"
    copy.write_bytes(files[0].read_bytes())
    assert main(["identify", str(files[0]), str(copy)]) == 2
    err = capsys.readouterr().err
    assert f"{copy} holds the same samples as {files[0]} (a copy?)" in err and "standard errors" in err, err


def test_chunked_is_refused_for_several_files(files, capsys):
    """--chunked bounds memory for one recording; a joint fit reads all into memory: refused, not ignored."""
    assert main(["identify", str(files[0]), str(files[1]), "--chunked"]) == 2
    assert "--chunked identifies one recording out of core" in capsys.readouterr().err


@pytest.mark.slow
def test_each_file_can_be_cut_to_its_own_samples(files, capsys):
    """FILE[START:STOP] cuts that file alone (--samples cuts every file alike): two files, the first cut to
    its second half, fitted jointly; the recording is named with its range, and the cut file's rows are
    those of --samples on it alone. Overlapping ranges of one file, a range beside a whole file, and a range
    given twice are refused before anything is read; disjoint ranges of one file are two recordings."""
    a, b = str(files[0]), str(files[2])
    cut = f"{a}[15000:30000]"
    assert main(["identify", cut, b, "--json", "--placements", "0", "--bias-replicates", "0"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["source"] for r in res["recordings"]] == [cut, b]
    assert res["recordings"][0]["samples"] == 15000 and res["status"] == "ok"
    assert main(["identify", cut, "--json", "--placements", "0", "--bias-replicates", "0"]) == 0
    single = json.loads(capsys.readouterr().out)
    assert main(["identify", a, "--samples", "15000", "30000", "--json", "--placements", "0",
                 "--bias-replicates", "0"]) == 0
    assert json.loads(capsys.readouterr().out)["model"] == single["model"]  # the same rows as --samples
    assert main(["explain", cut, "--json"]) == 0  # explain takes the notation too, as its help says
    by_name = json.loads(capsys.readouterr().out)
    assert main(["explain", a, "--samples", "15000", "30000", "--json"]) == 0
    by_option = json.loads(capsys.readouterr().out)
    assert by_name["effect"] == by_option["effect"] and by_name["effects"] == by_option["effects"]
    for bad, why in (([f"{a}[0:16000]", cut], "overlapping samples"), ([a, cut], f"{cut}: the same recording as {a}"),
                     ([cut, "--samples", "0", "100"], "samples given twice"), ([f"{a}[5:5]"], "empty sample range")):
        assert main(["identify", *bad]) == 2
        assert why in capsys.readouterr().err
    assert main(["identify", f"{a}[0:15000]", cut, "--placements", "0", "--bias-replicates", "0"]) == 0
    assert "identified 2 recordings jointly" in capsys.readouterr().out
