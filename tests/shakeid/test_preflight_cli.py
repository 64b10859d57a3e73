"""`shakeid sweep --config` (the DAQ without the service) predicts the sweep from the rig configuration's
nominal parameters before anything is written to the PLC (daq/preflight.py through SweepRunner.preflight)."""
from __future__ import annotations
import pytest

import dataclasses
import subprocess
import sys
from pathlib import Path

from daq.preflight import WARN_SHARE, nominal_response, predict
from daq.sweep import SineSweep
from sim.config import load_config
from sim.plc import PLCConfig
from sim.server import SimulatedRig
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SHAKEID = str(Path(sys.executable).with_name("shakeid"))


def _sweep(cfg: Path, out: Path, duration_s: float, amplitude_mm: float):
    return subprocess.run([SHAKEID, "sweep", "--config", str(cfg), "--f-start-hz", "1", "--f-end-hz", "20",
                           "--duration-s", str(duration_s), "--amplitude-mm", str(amplitude_mm), "--settle-s", "0.5",
                           "--out", str(out)], capture_output=True, text=True, timeout=300)


def test_a_direct_sweep_that_would_clip_is_refused_and_one_near_the_travel_warned(tmp_path):
    plc = PLCConfig()
    # 10x: the DAQ's 50 ms heartbeat is 0.5 s of rig time
    rig = SimulatedRig(dataclasses.replace(plc, limits=dataclasses.replace(plc.limits, watchdog_s=2.0)), speed=10.0)
    rig.start()
    try:
        host, port = rig.endpoints["modbus"]
        cfg = tmp_path / "rig.toml"
        cfg.write_text(f'[plc]\nhost = "{host}"\nport = {port}\n[stream]\nurl = "{rig.endpoints["stream"]}"\n')
        before = dict(rig.plc.setpoints)
        refused = _sweep(cfg, tmp_path / "clip.h5", 300, 1.3)  # the attack's sweep: the mass hits the end stops
        assert refused.returncode == 2, refused.stdout + refused.stderr
        assert "sweep refused: the mass would hit the end stops: predicted relative travel reaches the 17.5 mm " \
               "travel at 6." in refused.stderr and "passes: amplitude" in refused.stderr
        assert not (tmp_path / "clip.h5").exists()
        assert rig.plc.state.name == "IDLE" and rig.plc.setpoints == before  # nothing was written to the PLC

        # a rig configured with its own [rig] (the design rig of RigParameters' defaults) whose stops are 3 %
        # beyond the predicted travel of a 6 s sweep: it runs, warned (the travel does not change the smooth
        # model's prediction)
        plain = cfg.read_text()
        cfg.write_text(plain + "[rig]\nend_stop_travel_mm = 100.0\n")
        peak = predict(nominal_response(load_config(cfg)), SineSweep(1.0, 20.0, 6.0, 1.3)).travel_peak_mm
        travel = round(peak / (WARN_SHARE + 0.07), 2)
        cfg.write_text(plain + f"[rig]\nend_stop_travel_mm = {travel}\n")
        near = _sweep(cfg, tmp_path / "near.h5", 6, 1.3)
        assert near.returncode == 0, near.stdout + near.stderr
        assert f"preflight warning: predicted relative travel {peak:.3g} mm" in near.stdout
        assert f"of the end-stop travel {travel:g} mm" in near.stdout and "complete" in near.stdout
    finally:
        rig.stop()
