"""`shakeid identify BIG.h5` out of core: chosen by size or by option, the same model as in core, progress on
stderr, gaps and unfinished recordings refused as in core, chunks on a real Dask cluster's workers."""
import json
import os

import numpy as np
import pytest

from daq.h5source import H5ChunkSource
from daq.recorder import Recorder
from identify.errors import RecordingError
from shakeid import ooc_cmd
from shakeid.cli import main
from protocol.sweep import SineSweep


@pytest.fixture(scope="module")
def h5(make_run, tmp_path_factory):
    """A 60 s sweep of the Table 1 rig at 1024 Hz as the DAQ writes it (61 k samples)."""
    rec = make_run(sweep=SineSweep(1.0, 20.0, 60.0, 1.3), fs_hz=1024.0, seed=4).recording
    path = tmp_path_factory.mktemp("ooc") / "long.h5"
    r = Recorder(path, fs_hz=rec.fs_hz)
    r.append(0, np.column_stack([rec.input, rec.output]))
    r.close("complete")
    return path


def _identify(capsys, *argv):
    code = main(["identify", *map(str, argv), "--json", "--bias-replicates", "0", "--placements", "4"])
    out = capsys.readouterr()
    assert out.out, out.err
    return code, json.loads(out.out), out.err


def test_chunked_cli_gives_the_in_core_model(h5, capsys, true_q1_terms):
    code, chunked, err = _identify(capsys, h5, "--chunk-samples", "16384")
    assert code == 0 and chunked["status"] == "ok"
    assert chunked["out_of_core"]["chunks"] == 4 and "gram 100 % (4/4)" in err
    assert {t for t, c in chunked["model"]["q1_dot"].items() if c} == true_q1_terms
    assert chunked["data_quality"]["usable_for_identification"]
    code, incore, _ = _identify(capsys, h5)
    assert code == 0 and "out_of_core" not in incore
    for t, c in incore["model"]["q1_dot"].items():
        assert chunked["model"]["q1_dot"][t] == pytest.approx(c, rel=1e-6), t


def test_out_of_core_is_chosen_above_the_size_threshold(h5, capsys, monkeypatch):
    monkeypatch.setattr(ooc_cmd, "AUTO_CHUNKED_SAMPLES", 50_000)  # the file has 61 k samples
    code, res, err = _identify(capsys, h5)
    assert code == 0 and res["out_of_core"]["chunk_samples"] == 1 << 20 and "out of core" in err
    monkeypatch.setattr(ooc_cmd, "AUTO_CHUNKED_SAMPLES", 70_000)
    code, res, _ = _identify(capsys, h5)
    assert code == 0 and "out_of_core" not in res


def test_gaps_and_unfinished_recordings_are_refused(tmp_path, capsys):
    path = tmp_path / "gap.h5"
    r = Recorder(path, fs_hz=100.0)
    x = np.sin(np.arange(700) / 5.0)
    r.append(0, np.column_stack([x[:300], x[:300]]))
    r.append(364, np.column_stack([x[300:], x[300:]]))  # 64 samples lost
    r.close("aborted", "sensor link lost")
    with pytest.raises(RecordingError, match="span a gap.*longest: rows 300 700"):
        H5ChunkSource(path)
    assert H5ChunkSource(path, samples=(300, 700)).n_samples == 400
    assert main(["identify", str(path), "--chunked", "--samples", "300", "700"]) == 2
    assert "status is aborted" in capsys.readouterr().err


def test_chunks_spread_over_dask_workers(h5, dask_cluster, capsys):
    """Eight chunks on the two-worker cluster: computed in both worker processes, none in this one; the
    model is the one computed locally."""
    code, res, _ = _identify(capsys, h5, "--chunk-samples", "8192", "--scheduler", dask_cluster)
    assert code == 0 and res["status"] == "ok"
    where = res["out_of_core"]["computed_on"]
    assert sum(where.values()) == res["out_of_core"]["chunks"] == 8
    assert len(where) == 2 and not any(k.endswith(f":{os.getpid()}") for k in where), where
    _, local, _ = _identify(capsys, h5, "--chunk-samples", "8192")
    assert set(local["out_of_core"]["computed_on"]) == {k for k in local["out_of_core"]["computed_on"]
                                                        if k.endswith(f":{os.getpid()}")}
    for t, c in local["model"]["q1_dot"].items():
        assert res["model"]["q1_dot"][t] == pytest.approx(c, rel=1e-12), t
