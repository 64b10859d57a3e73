"""`shakeid identify` and `shakeid batch` on the lab's file formats: the same sweep as CSV, TDMS, UFF 58b
and MDF4 gives the same model through the command line; a UFF file's coarsely stored rate is said on
stderr with the --fs that fixes it."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from protocol.sweep import SineSweep

from ..daq.lab_writers import write_csv_exact, write_mdf, write_tdms, write_uff
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))
SHORT = SineSweep(1.0, 20.0, 25.0, 1.3)  # 25 s at 1024 Hz: identifies the Table 1 terms in ~1 s
FS_HZ = 1024.0
QUICK = ("--bias-replicates", "0", "--placements", "0")


def run(*args):
    return subprocess.run([SHAKEID, *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def files(make_run, tmp_path_factory):
    rec = make_run(sweep=SHORT, fs_hz=FS_HZ, seed=7).recording
    d = tmp_path_factory.mktemp("labcli")
    ch = {"table_acc": rec.input, "mass_acc": rec.output}
    write_csv_exact(d / "sweep.csv", FS_HZ, ch)
    write_tdms(d / "sweep.tdms", FS_HZ, ch, groups={"mass_acc": "Mass"})
    write_uff(d / "sweep.uff", FS_HZ, ch)
    write_mdf(d / "sweep.mf4", FS_HZ, ch)
    return [d / "sweep.csv", d / "sweep.tdms", d / "sweep.uff", d / "sweep.mf4"]


@pytest.mark.slow
def test_batch_gives_the_same_model_for_every_format(files):
    proc = run("batch", *files, "--fs", FS_HZ, "--workers", "1", "--json", *QUICK)
    assert proc.returncode == 0, proc.stderr
    models = json.loads(proc.stdout)["models"]
    assert set(models) == {f.name for f in files}
    first = models["sweep.csv"]["model"]
    assert all(m["model"] == first for m in models.values()), models  # the same floats, to the last bit


@pytest.mark.slow
def test_identify_says_a_uff_rate_is_stored_coarsely(files):
    uff = files[2]
    proc = run("identify", uff, "--json", *QUICK)
    assert proc.returncode == 0, proc.stderr
    warning = [ln for ln in proc.stderr.splitlines() if ln.startswith("shakeid: warning:")]
    assert len(warning) == 1 and "E13.5" in warning[0] and "give --fs 1024" in warning[0], proc.stderr
    exact = run("identify", uff, "--json", "--fs", FS_HZ, *QUICK)
    assert exact.returncode == 0 and "warning" not in exact.stderr, exact.stderr
    assert json.loads(exact.stdout)["model"] == json.loads(run("identify", files[0], "--json", *QUICK).stdout)["model"]
