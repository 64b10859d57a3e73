"""`shakeid export`: an identified model out as FMU, C, Python and LaTeX (a real subprocess each), and its
one-line refusals, after which nothing is written."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from identify.model import SparseModel
from identify.simulation.simulate import choose_substeps, simulate
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
TABLE1 = {"q1_dot": {"q1": -3.7294, "q2": -971.0169, "q1*q2^2": 1.162e4, "q2^3": -2.5033e6, "zdd": -1.0243},
          "q2_dot": {"q1": 1.0}}


def run(*args, env=None):
    return subprocess.run([SHAKEID, *map(str, args)], capture_output=True, text=True, timeout=300, env=env)


def one_error_line(proc, message):
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("shakeid: error:") and message in lines[0], proc.stderr


@pytest.fixture
def model_json(tmp_path):
    path = tmp_path / "model.json"
    SparseModel(TABLE1).save(path)
    return path


def held_input_free_run(model, dt, u):
    """shakeid's compiled free run of an input held over each interval (as tests/identify/test_export.py)."""
    s = choose_substeps(model, dt, [0.5, 0.02])
    x, out = np.zeros(2), [np.zeros(2)]
    for uk in u[:-1]:
        x = simulate(model, dt, x, inputs_fine=np.full((2 * s + 1, 1), uk), substeps=s, n_samples=2).states[1]
        out.append(x)
    return np.array(out)


@pytest.mark.slow
def test_an_identified_model_exports_to_every_format(table1_csv, tmp_path):
    """identify --json (the document the service's model.json also is) -> every format; the FMU under FMPy at
    5 Hz against shakeid's free run of the identified model, the numpy module against its right-hand side."""
    proc = run("identify", table1_csv, "--json")
    assert proc.returncode == 0, proc.stderr
    doc_path = tmp_path / "identified.json"
    doc_path.write_text(proc.stdout)
    model = SparseModel.from_dict(json.loads(proc.stdout))
    for fmt, name in [("fmu", "rig.fmu"), ("c", "rig.c"), ("python", "rig.py"), ("latex", "rig.tex")]:
        p = run("export", doc_path, "--format", fmt, "--out", tmp_path / name)
        assert p.returncode == 0, p.stderr
        assert p.stdout.startswith(f"wrote {tmp_path / name} ({fmt}: {model.n_terms} terms")
    assert validate_fmu(str(tmp_path / "rig.fmu")) == []
    seed = np.random.SeedSequence().entropy
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    dt, n, w = 1e-3, 3001, 2 * np.pi * 5.0
    u = -rng.uniform(1.0e-3, 1.5e-3) * w**2 * np.sin(w * np.arange(n) * dt + rng.uniform(0, 2 * np.pi))
    signals = np.zeros(n, dtype=[("time", float), ("zdd", float)])
    signals["time"], signals["zdd"] = np.arange(n) * dt, u
    res = simulate_fmu(str(tmp_path / "rig.fmu"), input=signals, output=["q1", "q2"], stop_time=(n - 1) * dt,
                       output_interval=dt)
    fmu = np.column_stack([res["q1"], res["q2"]])
    ref = held_input_free_run(model, dt, u)
    err = np.sqrt(np.mean((fmu - ref) ** 2, axis=0)) / np.sqrt(np.mean(ref**2, axis=0))
    print(f"identified model's FMU vs shakeid's free run, relative RMS: {err}")
    assert np.all(err < 1e-4)
    tex = (tmp_path / "rig.tex").read_text()
    assert r"\dot{q}_{1} &=" in tex and r"q_{1} q_{2}^{2}" in tex and r"\ddot{z}" in tex
    ns: dict = {}
    exec(compile((tmp_path / "rig.py").read_text(), "rig.py", "exec"), ns)
    q = np.column_stack([rng.uniform(-0.3, 0.3, 100), rng.uniform(-0.01, 0.01, 100)])
    zdd = rng.uniform(-10, 10, 100)
    np.testing.assert_allclose(ns["rhs"](q, zdd), model.rhs(q, zdd[:, None]), rtol=1e-12, atol=1e-9)


def test_overwrite_replaces_and_the_default_refuses(model_json, tmp_path):
    out = tmp_path / "m.tex"
    assert run("export", model_json, "--format", "latex", "--out", out).returncode == 0
    first = out.read_text()
    one_error_line(run("export", model_json, "--format", "latex", "--out", out), f"{out} exists already; --overwrite")
    SparseModel({"q1_dot": {"q2": -900.0}, "q2_dot": {"q1": 1.0}}).save(model_json)
    assert run("export", model_json, "--format", "latex", "--out", out, "--overwrite").returncode == 0
    assert out.read_text() != first and r"-900\, q_{2}" in out.read_text()


def test_no_c_compiler_is_one_line_and_writes_nothing(model_json, tmp_path):
    out = tmp_path / "m.fmu"
    env = {**os.environ, "CC": str(tmp_path / "no-such-cc")}
    one_error_line(run("export", model_json, "--format", "fmu", "--out", out, env=env),
                   "no C compiler: CC=")
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env["PATH"] = str(tmp_path)  # the shakeid script is run by its path; no cc, gcc or clang on this PATH
    one_error_line(run("export", model_json, "--format", "fmu", "--out", out, env=env),
                   "no C compiler found (looked for $CC, cc, gcc, clang on PATH)")
    assert list(tmp_path.iterdir()) == [model_json]


@pytest.mark.parametrize("content, args, message", [
    (None, ["--format", "fmu", "--out", "{tmp}/m.c"], "--out {tmp}/m.c: a fmu export is a .fmu file (e.g. --out m.fmu)"),
    (None, ["--format", "python", "--out", "{tmp}/nowhere/m.py"], "no folder {tmp}/nowhere to write it in"),
    ("not json", ["--format", "c", "--out", "{tmp}/m.c"], "not a model file: a model is the JSON"),
    (json.dumps({"status": "failed", "reason": "no excitation", "model": TABLE1}), ["--format", "c", "--out", "{tmp}/m.c"],
     "its identification failed (no excitation); it is not a model of the rig (--accept-failed"),
    (json.dumps({"model": {"q1_dot": {"q3^2": 1.0}, "q2_dot": {"q1": 1.0}}}), ["--format", "c", "--out", "{tmp}/m.c"],
     "unknown term 'q3^2'"),
    (json.dumps({"model": {"q1_dot": {"q2": -900.0, "int": -1.0}, "q2_dot": {"q1": 1.0}}, "inputs": ["int"]}),
     ["--format", "c", "--out", "{tmp}/m.c"], "signal name(s) int cannot be exported as code variables"),
])
def test_bad_input_is_one_line_naming_the_problem(tmp_path, content, args, message):
    path = tmp_path / "model.json"
    path.write_text(content if content is not None else json.dumps({"model": TABLE1}))
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    one_error_line(run("export", path, *args), message.replace("{tmp}", str(tmp_path)))
    assert list(tmp_path.iterdir()) == [path]


def test_a_failed_identification_exports_when_accepted(tmp_path):
    path = tmp_path / "model.json"
    path.write_text(json.dumps({"status": "failed", "reason": "no excitation", "model": TABLE1}))
    p = run("export", path, "--format", "python", "--out", tmp_path / "m.py", "--accept-failed")
    assert p.returncode == 0, p.stderr
    assert "'q1*q2^2': 11620.0" in (tmp_path / "m.py").read_text()
