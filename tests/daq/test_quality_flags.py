"""Quality flags of HDF5 recordings: computed while recording, stored in /entry/quality at every flush and
at close, read back by describe() and `shakeid recordings`; sweeps of a simulated rig with a stuck or a
saturated sensor injected mid-sweep carry the flags at the time range of the fault."""
import json

import h5py
import numpy as np
import pytest

from daq.plc import ModbusPLC
from daq.recorder import Recorder, describe
from daq.sources import SerialSource
from daq.sweep import SweepRequest, SweepRunner
from identify.data.quality import clip_level
from shakeid.cli import main
from protocol.plc import Limits
from sim.plc import PLCConfig
from sim.server import SENSITIVITY, SimulatedRig

SENSORS = {c: {"sensitivity": SENSITIVITY} for c in ("table_acc", "mass_acc")}


def _counts(x):
    return np.round(np.asarray(x) * SENSITIVITY) / SENSITIVITY  # what the stream delivers


def test_flags_are_stored_at_close_and_read_back(tmp_path, table1_run):
    rec = table1_run.recording
    x = _counts(np.column_stack([rec.input, rec.output]))
    k = 70000
    x[60000:k, 1] = np.clip(x[60000:k, 1] * 100, -32767 / SENSITIVITY, 32767 / SENSITIVITY)  # saturates ...
    x[k:, 1] = 0.0                                                                          # ... then dead
    r = Recorder(tmp_path / "r.h5", fs_hz=rec.fs_hz, sensors=SENSORS)
    for a in range(0, x.shape[0], 64):
        r.append(a, x[a:a + 64])
    r.close(link_stats={"frames": x.shape[0] // 64, "saturated_frames": 7})
    q = describe(tmp_path / "r.h5")["quality"]
    assert q["assessed"] and q["final"] and not q["usable_for_identification"]
    kinds = {(f["channel"], f["kind"]): f for f in q["flags"]}
    assert set(kinds) == {("mass_acc", "clipped"), ("mass_acc", "dead")}
    dead = kinds[("mass_acc", "dead")]
    assert (dead["first"], dead["count"], dead["t_start_s"]) == (k, x.shape[0] - k, pytest.approx(k / rec.fs_hz))
    clipped = kinds[("mass_acc", "clipped")]
    hits = np.flatnonzero(np.abs(x[:, 1]) >= clip_level(SENSITIVITY))
    assert (clipped["first"], clipped["first"] + clipped["count"] - 1, clipped["samples"]) == (hits[0], hits[-1], hits.size)
    assert any("reads exactly 0" in s for s in q["reasons"]) and any("clipped" in s for s in q["reasons"])
    assert q["link_saturated_frames"] == 7 and r.quality["flags"] == 2 and r.quality["usable_for_identification"] is False


def test_flags_are_on_disk_after_a_flush_without_close(tmp_path):
    """A crashed recorder leaves the flags of its last flush (the file is never closed here)."""
    rng = np.random.default_rng(0)
    x = _counts(rng.normal(0, 3, (20000, 2)))
    x[5000:, 0] = 1.5  # the table sensor sticks
    r = Recorder(tmp_path / "c.h5", fs_hz=2048.0, sensors=SENSORS)
    r.append(0, x)
    r.flush()
    with h5py.File(tmp_path / "c.h5") as f:  # opened beside the open writer, as after a SIGKILL
        q = f["entry/quality"]
        assert not q.attrs["final"] and not q.attrs["usable_for_identification"]
        (row,) = q["flags"][()]
        assert (row["channel"], row["kind"], row["first_row"], row["rows"]) == (b"table_acc", b"stuck", 5000, 15000)
    r.f.close()


def test_a_file_written_before_quality_flags_is_described_not_assessed(tmp_path, capsys):
    r = Recorder(tmp_path / "old.h5", fs_hz=100.0)
    r.append(0, np.random.default_rng(1).normal(0, 1, (500, 2)))
    r.close()
    with h5py.File(tmp_path / "old.h5", "r+") as f:
        del f["entry/quality"]  # as the recorder wrote them before this change
    assert describe(tmp_path / "old.h5")["quality"]["assessed"] is False
    assert main(["recordings", str(tmp_path / "old.h5")]) == 0
    assert "quality: not assessed" in capsys.readouterr().out


@pytest.fixture
def rig():
    r = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=3.0)), speed=10.0).start()
    yield r
    r.stop()


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["stuck", "saturate"])
def test_sweep_with_a_sensor_fault_mid_sweep_has_the_flags_at_its_time_range(rig, tmp_path, fault, capsys):
    """The simulated rig's sensors go stuck (both channels repeat one value) or saturate (the mass
    sensor beyond full scale) from 30 % to 60 % of the sweep: the flags cover exactly those samples."""
    plc = ModbusPLC(*rig.endpoints["modbus"])
    runner = SweepRunner(plc, SerialSource(rig.endpoints["stream"], 2048.0), Limits(), SENSITIVITY)
    window = {}

    def toggle(on):  # on the rig's loop: the next frame sent starts at the pending sample index
        rig.fault_injection[fault] = on
        return rig._pending_first

    def progress(frac, st):
        if frac > 0.3 and "on" not in window:
            window["on"] = rig.call(toggle, True)
        if frac > 0.6 and "off" not in window:
            window["off"] = rig.call(toggle, False)

    runner.on_progress = progress
    out = tmp_path / f"{fault}.h5"
    result = runner.run(SweepRequest(2.0, 10.0, 20.0, 1.0, settle_s=1.0), out)
    plc.close()
    assert result["status"] == "complete" and result["gaps"] == 0, result
    assert result["quality"]["usable_for_identification"] is False
    with h5py.File(out) as f:
        first_index = int(round(f["entry/data/time"][0] * 2048.0))
    a, b = window["on"] - first_index, window["off"] - first_index  # rows of the faulty samples
    q = describe(out)["quality"]
    channels = ("table_acc", "mass_acc") if fault == "stuck" else ("mass_acc",)
    kind = "stuck" if fault == "stuck" else "clipped"
    assert sorted((f["channel"], f["kind"]) for f in q["flags"]) == sorted((c, kind) for c in channels), q["flags"]
    for f in q["flags"]:
        # a stuck value may equal a neighbour by chance (one ADC count in ~50): a sample of slack
        assert abs(f["first"] - a) <= 1 and abs(f["first"] + f["count"] - b) <= 1, (f, a, b)
        assert f["t_start_s"] == pytest.approx(window["on"] / 2048.0, abs=1e-3)
    if fault == "saturate":
        assert q["flags"][0]["samples"] == b - a and q["link_saturated_frames"] == (b - a) // 64
    assert main(["recordings", str(out)]) == 0
    text = capsys.readouterr().out
    assert "NOT usable for identification" in text and f"flag: mass_acc {kind}" in text
    assert main(["recordings", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["quality"]["flags"] == q["flags"]
