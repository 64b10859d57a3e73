"""`shakeid batch`: one model per file, each naming where it was computed, on a real Dask cluster
(`dask scheduler` + two `dask worker` processes on loopback) and in the local pool; refusals as
`shakeid identify`'s (the bad file is named, the others are still identified, the exit status says so)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daq.recorder import Recorder
from identify.data.recording import write_csv
from shakeid.cli import main
from sim.server import free_port
from protocol.sweep import SineSweep

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
SHORT = SineSweep(1.0, 20.0, 25.0, 1.3)  # 25 s at 1024 Hz: identifies the Table 1 terms in ~1 s


@pytest.fixture(scope="module")
def recordings(make_run, tmp_path_factory):
    """Three short sweeps of the Table 1 rig (two CSV, one DAQ HDF5; different noise seeds) and a CSV
    without the mass accelerometer column."""
    d = tmp_path_factory.mktemp("batch")
    paths = []
    for seed in range(3):
        rec = make_run(sweep=SHORT, fs_hz=1024.0, seed=seed).recording
        if seed < 2:
            write_csv(d / f"sweep{seed}.csv", rec)
            paths.append(d / f"sweep{seed}.csv")
        else:
            r = Recorder(d / "sweep2.h5", fs_hz=rec.fs_hz)
            r.append(0, np.column_stack([rec.input, rec.output]))
            r.close("complete")
            paths.append(d / "sweep2.h5")
    bad = d / "bad.csv"
    bad.write_text("t,table_acc\n0,1\n0.001,2\n")
    return paths, bad


def _support(model: dict) -> set[str]:
    return {t for t, c in model["model"]["q1_dot"].items() if c}


@pytest.mark.slow
def test_batch_on_a_dask_cluster_gives_one_model_per_file_each_naming_its_worker(dask_cluster, recordings, tmp_path,
                                                                                  true_q1_terms, capsys):
    from distributed import Client

    good, bad = recordings
    with Client(dask_cluster, timeout=30) as client:
        workers = set(client.scheduler_info()["workers"])
    out = tmp_path / "models"
    proc = subprocess.run([SHAKEID, "batch", *map(str, good), str(bad), "--scheduler", dask_cluster, "--json",
                           "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr  # one file refused: as `shakeid identify` on it
    reason = f"{bad}: missing column(s) 'mass_acc'; found 't', 'table_acc'"
    assert proc.stderr.strip().splitlines() == [f"shakeid: error: {reason}"]
    doc = json.loads(proc.stdout)
    assert list(doc["models"]) == [p.name for p in good] and doc["scheduler"] == dask_cluster
    for name, model in doc["models"].items():
        assert model["computed_on"] in workers, (name, model["computed_on"], workers)
        assert model["status"] == "ok" and _support(model) == true_q1_terms
        assert json.loads((out / f"{name}.model.json").read_text()) == model
    assert doc["failed"] == {"bad.csv": {"reason": reason, "computed_on": doc["failed"]["bad.csv"]["computed_on"]}}
    assert doc["failed"]["bad.csv"]["computed_on"] in workers
    assert json.loads((out / "batch.json").read_text()) == doc
    # the same code path as `shakeid identify`: the same model, coefficient for coefficient
    assert main(["identify", str(good[0]), "--json"]) == 0
    alone = json.loads(capsys.readouterr().out)
    batch = doc["models"][good[0].name]
    assert batch["model"] == alone["model"] and batch["validation"] == alone["validation"]


@pytest.mark.slow
def test_batch_in_the_local_pool_names_the_worker_process(recordings, capsys, true_q1_terms):
    good, _ = recordings
    assert main(["batch", str(good[0]), str(good[2]), "--workers", "2"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1] == "2 of 2 file(s) identified on local"
    per_file = {line.split(":", 1)[0]: line for line in lines[:-1]}
    assert set(per_file) == {good[0].name, good[2].name}
    for line in per_file.values():
        assert line.split(": ", 1)[1].startswith("ok, held-out fit ")
        assert "q1_dot: " + " ".join(sorted(true_q1_terms)) + ";" in line
        pid = int(line.rsplit("(computed on local:", 1)[1].rstrip(")"))
        assert pid != os.getpid()  # a pool process, not this one


@pytest.mark.slow
def test_files_differing_only_in_extension_keep_one_model_each(recordings, tmp_path, capsys):
    """sweep0.csv and sweep0.h5 are two recordings: each model is written under the whole file name (the
    name without its extension had written both to sweep0.model.json, and the last to finish won)."""
    good, _ = recordings
    twin = tmp_path / "in" / "sweep0.h5"
    twin.parent.mkdir()
    twin.write_bytes(good[2].read_bytes())  # another recording (sweep2's), named like sweep0.csv but .h5
    out = tmp_path / "models"
    assert main(["batch", str(good[0]), str(twin), "--workers", "2", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == f"2 of 2 file(s) identified on local; models in {out}"
    assert sorted(p.name for p in out.iterdir()) == ["batch.json", "sweep0.csv.model.json", "sweep0.h5.model.json"]
    doc = json.loads((out / "batch.json").read_text())
    for name in ("sweep0.csv", "sweep0.h5"):
        assert json.loads((out / f"{name}.model.json").read_text()) == doc["models"][name]
    assert doc["models"]["sweep0.csv"]["model"] != doc["models"]["sweep0.h5"]["model"]  # two fits, two models


@pytest.mark.slow
def test_a_second_batch_into_the_same_folder_keeps_the_first_in_its_index(recordings, tmp_path, capsys):
    """batch.json indexes every model in the folder: a later batch adds its files (and replaces the entries
    of files it identifies again) instead of rewriting the index with its own files alone."""
    good, bad = recordings
    out = tmp_path / "models"
    assert main(["batch", str(good[0]), str(bad), "--workers", "1", "--out", str(out)]) == 2
    capsys.readouterr()
    assert main(["batch", str(good[1]), str(bad), "--workers", "1", "--out", str(out)]) == 2
    assert "(batch.json also lists 1 file(s) of earlier batches there)" in capsys.readouterr().out
    doc = json.loads((out / "batch.json").read_text())
    assert sorted(doc["models"]) == ["sweep0.csv", "sweep1.csv"] and sorted(doc["failed"]) == ["bad.csv"]
    assert sorted(p.name for p in out.iterdir()) == ["batch.json", "sweep0.csv.model.json", "sweep1.csv.model.json"]


def test_option_errors_refuse_before_any_work(recordings, tmp_path, capsys):
    good, _ = recordings
    twin = tmp_path / good[0].name
    twin.write_bytes(good[0].read_bytes())
    cases = [(["--workers", "0"], "argument --workers: must be >= 1, got 0"),
             (["--lambdas", "1"], "argument --lambdas: must be 2..1000, got 1"),
             ([str(twin)], f"two files named {good[0].name!r}"),
             (["--scheduler", f"tcp://127.0.0.1:{free_port()}", "--connect-timeout", "1"],
              "cannot reach the Dask scheduler tcp://127.0.0.1:")]
    for extra, message in cases:
        assert main(["batch", str(good[0]), *extra]) == 2, extra
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.startswith(f"shakeid: error: {message}"), (extra, captured.err)
