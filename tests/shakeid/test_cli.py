"""The `shakeid` executable: its JSON contract and its one-line errors (a real subprocess each)."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def run(*args, cwd=None):
    return subprocess.run([SHAKEID, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.mark.slow
def test_identify_json_contract(table1_csv, table1_truth):
    proc = run("identify", table1_csv, "--json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)  # exactly one JSON object: json.loads rejects trailing text
    assert set(doc) >= {"model", "selection", "validation", "physical"}
    assert set(doc["model"]["q1_dot"]) == set(table1_truth["q1_dot"])
    assert doc["model"]["q2_dot"] == {"q1": pytest.approx(1.0, abs=1e-6)}
    assert all(c != 0 for eq in doc["model"].values() for c in eq.values())
    assert doc["validation"]["heldout"]["q1_dot"]["fit_percent"] > 98


@pytest.mark.slow
def test_identify_options_and_report(table1_csv, tmp_path):
    out = tmp_path / "rep"
    proc = run("identify", table1_csv, "--method", "stlsq", "--selection", "paper", "--lambdas", "50",
               "--degree", "3", "--holdout-samples", "30000", "--report", out)
    assert proc.returncode == 0, proc.stderr
    assert "free-run fit" in proc.stdout and "q1*q2^2" in proc.stdout
    assert (out / "model.json").exists() and (out / "lambda_path.png").exists()
    doc = json.loads((out / "model.json").read_text())
    assert doc["method"] == "stlsq" and doc["selection"]["rule"] == "paper" and len(doc["library"]["terms"]) == 11
    assert "data_quality" in doc  # the report's model.json is the whole result, as --json prints it
    chosen = doc["selection"]["q1_dot"]  # the path's threshold and the rule's tolerance, both kept
    assert chosen["threshold"] > 0 and chosen["score_tolerance"] > 0 and chosen["threshold"] != chosen["score_tolerance"]
    assert "replaces" not in proc.stdout
    # a second report into the same folder replaces the first, and the operator is told so
    again = run("identify", table1_csv, "--method", "stlsq", "--degree", "3", "--report", out)
    assert again.returncode == 0, again.stderr
    assert f"report: {out / 'index.html'} (replaces the report written there at 20" in again.stdout
    assert json.loads((out / "model.json").read_text())["selection"]["rule"] == "heldout"
    # explaining that model into the same folder would delete its model.json: refused before any work
    model = (out / "model.json").read_bytes()
    clash = run("explain", table1_csv, "--model", out / "model.json", "--report", out)
    assert clash.returncode == 2 and "holds an identification report" in clash.stderr, clash.stderr
    assert f"e.g. {out / 'explain'}" in clash.stderr and "Traceback" not in clash.stderr
    assert (out / "model.json").read_bytes() == model and (out / "index.html").exists()


@pytest.mark.slow
def test_identify_budget_option(table1_csv, table1_truth):
    """--budget reaches the identifier; the rule's support already fits the budget here, so no candidates
    are screened (tests/identify/test_budget.py runs the choice itself)."""
    proc = run("identify", table1_csv, "--max-terms", "5", "--budget", "free-run", "--budget-refit", "all", "--json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["selection"]["budget"] == "free-run" and doc["selection"]["max_terms"] == 5
    assert doc["selection"]["budget_refit"] == "all"
    assert doc["budget"] is None and set(doc["model"]["q1_dot"]) == set(table1_truth["q1_dot"])
    assert run("identify", table1_csv, "--budget", "aic").returncode == 2
    assert run("identify", table1_csv, "--budget-refit", "heldout").returncode == 2


@pytest.mark.parametrize("content,args,message", [
    (None, [], "no such file"),
    ("t,table_acc\n0,1\n", [], "missing column"),
    ("t,table_acc,mass_acc\n" + "".join(f"{i / 100},{i % 7},nan\n" for i in range(400)), [], "NaN"),
    ("t,table_acc,mass_acc\n" + "".join(f"{i * i / 1e4},{i % 7},{i % 5}\n" for i in range(400)), [],
     "not uniformly sampled"),
    ("t,table_acc,mass_acc\n" + "".join(f"{i / 100},{i % 7},{i % 5}\n" for i in range(30)), [], "too short"),
    ("\x00\x01\x02binary", [], "rec.csv"),
    ("t,u,y\n1,2,3\n", ["--lambdas", "1"], "--lambdas"),
    ("t,table_acc,mass_acc\n" + "".join(f"{i / 100},{i % 7},{i % 5}\n" for i in range(400)),
     ["--extra-terms", "cos(q1)"], "unknown term"),
    # white noise on both channels excites no band: what the data cannot give names the file too
    ("t,table_acc,mass_acc\n" + "".join(f"{i / 100},{a:.6f},{b:.6f}\n" for i, (a, b) in
                                        enumerate(np.random.default_rng(0).standard_normal((4000, 2)))), [],
     "rec.csv: the input shows no excited frequency band"),
])
@pytest.mark.slow
def test_errors_are_one_clear_line(tmp_path, content, args, message):
    path = tmp_path / "rec.csv"
    if content is not None:
        path.write_text(content)
    proc = run("identify", path, *args)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shakeid: error:") and message in lines[0], proc.stderr


@pytest.mark.parametrize("args,message", [
    (["identify", "{csv}", "--mass-kg", "0"], "argument --mass-kg: must be > 0, got 0"),
    (["identify", "{csv}", "--mass-kg", "nan"], "argument --mass-kg: must be a finite number"),
    (["identify", "{csv}", "--degree", "0"], "argument --degree: must be 1..8, got 0"),
    (["identify", "{csv}", "--max-terms", "0"], "argument --max-terms: must be 1..100, got 0"),
    (["identify", "{csv}", "--samples", "-5", "100"], "argument --samples: must be >= 0, got -5"),
    (["identify", "{csv}", "--samples", "100", "50"], "samples [100, 50) requested: need 0 <= start < stop <= "),
    (["identify", "{csv}", "--budget", "aic"], "argument --budget: invalid choice: 'aic'"),
    (["simulate", "--out", "{tmp}/s.csv", "--fs-hz", "-100"], "argument --fs-hz: must be > 0, got -100"),
    (["simulate", "--out", "{tmp}/s.csv", "--duration-s", "-5"], "argument --duration-s: must be > 0, got -5"),
    (["explain", "{csv}", "--model", "{csv}"], "not a model file: a model is the JSON `shakeid identify --json` "
                                               "prints or a report's model.json (this is not JSON"),
    # options are taken whole: --out is not read as --output (the output channel "x"); told by the subcommand
    (["explain", "{csv}", "--output", "mass_acc", "--out", "x"], "unrecognized arguments: --out x (`shakeid explain --help`"),
])
@pytest.mark.slow
def test_an_impossible_option_is_named_in_one_line(table1_csv, tmp_path, args, message):
    """A value no rig has (a zero mass, a negative sample rate) is refused while the command line is read,
    naming the option, in one line pointing at --help (not a ZeroDivisionError's traceback, not numpy's
    "negative dimensions are not allowed", not argparse's 16-line usage); nothing is written."""
    proc = run(*(a.format(csv=table1_csv, tmp=tmp_path) for a in args))
    assert proc.returncode == 2 and proc.stdout == "" and "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shakeid: error:") and message in lines[0], proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command,name,content,message", [
    (command, name, content, message)
    for command in ("identify", "recordings")
    for name, content, message in [
        ("nosuch.h5", None, "nosuch.h5: no such file"),
        ("notes.h5", "not an HDF5 file at all\n", "notes.h5: not an HDF5 file (shakeid's recordings are the HDF5"),
    ]
] + [("identify", "rec.dat", "t,table_acc,mass_acc\n0,1,2\n", "rec.dat: unsupported file type '.dat' (HDF5 .h5")])
@pytest.mark.slow
def test_a_wrong_file_is_named_in_words_not_in_hdf5s(tmp_path, command, name, content, message):
    """A mistyped path, a text file named .h5, an unknown extension: one line saying which, without h5py's
    errno and library wording ("Unable to synchronously open file ... errno = 2")."""
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    proc = run(command, path)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shakeid: error:"), proc.stderr
    assert message in lines[0] and "errno" not in lines[0] and "Unable to" not in lines[0], lines[0]


@pytest.mark.slow
def test_simulate_writes_recording_and_truth(tmp_path):
    out = tmp_path / "s.csv"
    proc = run("simulate", "--out", out, "--duration-s", "10", "--effect", "coulomb_friction=0.1",
               "--bias-ms2", "0.05", "--lsb-ms2", "0.01")
    assert proc.returncode == 0, proc.stderr
    truth = json.loads(out.with_suffix(".truth.json").read_text())
    assert truth["rig"]["effects"] == {"displacement_dependent_damping": pytest.approx(-0.49 * 1.162e4),
                                       "coulomb_friction": 0.1}
    lines = out.read_text().splitlines()
    assert lines[0] == "t,table_acc,mass_acc"
    table = [float(ln.split(",")[1]) for ln in lines[1:200]]  # at rest before the sweep: bias, quantised
    assert all(abs(round(v / 0.01) * 0.01 - v) < 1e-9 for v in table) and abs(sum(table) / len(table) - 0.05) < 0.01
    bad = run("simulate", "--out", out, "--effect", "warp_drive=1", "--overwrite")
    assert bad.returncode == 2 and "unknown effect" in bad.stderr
    # an existing --out is a recording: refused before anything runs, the file kept byte for byte
    before = out.read_bytes()
    again = run("simulate", "--out", out, "--duration-s", "10")
    assert again.returncode == 2 and "never overwritten" in again.stderr and "--overwrite" in again.stderr
    assert out.read_bytes() == before
    assert run("simulate", "--out", out, "--duration-s", "10", "--overwrite").returncode == 0
    assert out.read_bytes() != before  # the default rig without friction: another recording


@pytest.mark.slow
def test_version_is_the_packages():
    import tomllib

    declared = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"]["version"]
    out = run("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"shakeid {declared}"


@pytest.mark.slow
def test_paths_that_cannot_be_written_are_one_line_errors(table1_csv, tmp_path):
    """A report folder that is a file, a folder that cannot be made, a recording into a folder that does
    not exist: one line naming the path, exit 2, no traceback (they were FileExistsError and
    FileNotFoundError tracebacks)."""
    a_file = tmp_path / "notes.json"
    a_file.write_text("{}")
    for target, words in ((a_file, "is a file, not a folder"), ("/proc/shakeid-report/", "cannot create the report")):
        proc = run("identify", table1_csv, "--report", target)
        assert proc.returncode == 2 and words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
    assert a_file.read_text() == "{}"
    proc = run("simulate", "--out", tmp_path / "nodir" / "x.csv", "--duration-s", "5")
    assert proc.returncode == 2 and "no folder" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


@pytest.mark.slow
def test_a_reader_that_goes_away_stops_nothing(tmp_path):
    """`shakeid campaign ... | head -3`: once the reader has gone, a write met a broken pipe, which ended a
    sweep as "DAQ error: BrokenPipeError" and left the campaign marked running. The command now finishes
    its work, writes nothing more, and exits as it would have (here: a simulated recording, written)."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line
    out = tmp_path / "s.csv"
    try:
        proc = subprocess.run([SHAKEID, "simulate", "--out", str(out), "--duration-s", "5"], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert out.exists() and out.with_suffix(".truth.json").exists()


def test_progress_lines_to_a_closed_pipe_raise_nothing():
    """The progress display of a sweep (its on_progress callback, inside the DAQ loop) writing into a pipe
    whose reader has gone: nothing raised, so nothing reaches the sweep as a DAQ error."""
    import os

    from shakeid.progress import Progress, SurvivesClosedReader

    read_end, write_end = os.pipe()
    os.close(read_end)
    stream = SurvivesClosedReader(os.fdopen(write_end, "w", buffering=1))
    progress = Progress("sweep", 10.0, stream=stream, tty=False)
    for k in range(11):
        progress.update(k / 10, "running")
    progress.close("complete")
    stream.close()
