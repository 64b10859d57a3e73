"""Uploads of the lab's file formats through a real service: TDMS, UFF 58 (binary and ASCII) and MDF4
accepted and read as a job reads them; a damaged file of each refused with 422 naming the problem, and
not stored."""
from __future__ import annotations

import httpx
import pytest

from ..daq.lab_writers import write_mdf, write_tdms, write_uff
from .conftest import OPERATOR, VIEWER, wait_for
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

FS_HZ = 2048.0


@pytest.fixture(scope="module")
def lab_files(table1_run, tmp_path_factory):
    d = tmp_path_factory.mktemp("uploads")
    ch = {"table_acc": table1_run.recording.input, "mass_acc": table1_run.recording.output}
    files = {"sweep.tdms": d / "sweep.tdms", "sweep.uff": d / "sweep.uff", "sweep.unv": d / "sweep.unv",
             "sweep.mf4": d / "sweep.mf4"}
    write_tdms(files["sweep.tdms"], FS_HZ, ch)
    write_uff(files["sweep.uff"], FS_HZ, ch, binary=True)
    write_uff(files["sweep.unv"], FS_HZ, ch, binary=False)
    write_mdf(files["sweep.mf4"], FS_HZ, ch)
    return files


@pytest.mark.slow
def test_each_lab_format_is_accepted_and_a_damaged_one_refused(service, lab_files, table1_run):
    # the check reads each file in a process of its own: importing asammdf alone took 12 s at load 15
    op = httpx.Client(base_url=service.url, headers={"Authorization": f"Bearer {OPERATOR}"}, timeout=180)
    n = table1_run.recording.n_samples
    ids = {}
    for name, path in lab_files.items():
        params = {"filename": name, **({"fs_hz": FS_HZ} if name != "sweep.uff" else {})}
        r = op.post("/api/recordings", params=params, content=path.read_bytes())
        assert r.status_code == 201, (name, r.text)
        info = r.json()["info"]
        assert info["samples"] == n, info
        ids[name] = r.json()["id"]
        if name == "sweep.uff":  # no --fs: the E13.5 increment's rate, and the recording says so
            assert info["fs_hz"] == pytest.approx(1 / 4.88281e-04, rel=1e-12)
            assert "give --fs 2048" in info["warnings"][0]
        else:
            assert info["fs_hz"] == FS_HZ and "warnings" not in info
    before = len(op.get("/api/recordings", params={"limit": 500}).json())
    damaged = {
        "cut.tdms": (lab_files["sweep.tdms"].read_bytes()[:200_000], "cut short: its last TDMS segment announces"),
        "junk.tdms": (b"hello\n" * 100, "not in TDMS format (TDMS files begin with 'TDSm')"),
        "cut.uff": (lab_files["sweep.uff"].read_bytes()[:300_000], "cut short: the last UFF dataset is not closed"),
        "cut.unv": (lab_files["sweep.unv"].read_bytes()[:300_000], "cut short: the last UFF dataset is not closed"),
        "cut.mf4": (lab_files["sweep.mf4"].read_bytes()[:300_000], "not a readable MDF4 file, cut short or damaged"),
        "named.mf4": (lab_files["sweep.tdms"].read_bytes(), "it looks like a TDMS file, whose names end in .tdms"),
    }
    for name, (content, problem) in damaged.items():
        r = op.post("/api/recordings", params={"filename": name, "fs_hz": FS_HZ}, content=content)
        assert r.status_code == 422, (name, r.text)
        detail = r.json()["detail"]
        assert detail.startswith(f"{name}: ") and problem in detail and str(service.data_dir) not in detail, detail
    assert len(op.get("/api/recordings", params={"limit": 500}).json()) == before  # nothing stored
    # a job reads the stored file as the check did
    job = op.post(f"/api/recordings/{ids['sweep.tdms']}/identify", json={"bias_replicates": 0, "placements": 0}).json()
    done = wait_for(lambda: (j := op.get(f"/api/jobs/{job['id']}").json())["state"] in ("completed", "failed") and j,
                    120, "job")
    assert done["state"] == "completed", done.get("error")
    model = service.client(VIEWER).get(f"/api/recordings/{ids['sweep.tdms']}/model").json()
    assert {"q1", "q2", "q2^3", "zdd"} <= set(model["model"]["q1_dot"])
