"""`shakeid rig status|estop|reset --config RIG.toml` against a real simulated rig on loopback (Modbus)."""
import json
import time

import pytest

from shakeid import rigcmd
from shakeid.cli import main
from protocol.plc import Command, Fault, Limits, State
from sim.plc import PLCConfig
from sim.server import SimulatedRig, free_port


def _config(tmp_path, port):
    cfg = tmp_path / "rig.toml"
    cfg.write_text(f'[plc]\ntransport = "modbus"\nhost = "127.0.0.1"\nport = {port}\n')
    return cfg


@pytest.fixture
def rig():
    # no heartbeat in these tests: a watchdog long enough not to end the sweep on its own
    r = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=1e4)), speed=10.0).start()
    yield r
    r.stop()


def _start_sweep(rig):
    def start():
        for k, v in {"f_start_hz": 2.0, "f_end_hz": 10.0, "duration_s": 300.0, "amplitude_mm": 1.0}.items():
            rig.plc.set_setpoint(k, v)
        rig.plc.command(Command.START)
    rig.call(start)
    end = time.monotonic() + 10
    while rig.call(lambda: abs(rig.plc.status()["position_mm"])) < 0.1:  # the table is moving
        assert time.monotonic() < end
        time.sleep(0.02)


def test_estop_stops_a_running_table_and_reset_returns_to_idle(rig, tmp_path, capsys):
    cfg = _config(tmp_path, rig.endpoints["modbus"][1])
    _start_sweep(rig)
    assert main(["rig", "status", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "state running, fault 0 (none)" in out and "Hz" in out
    assert main(["rig", "reset", "--config", str(cfg)]) == 2  # never under a moving table
    assert "a sweep is running: not reset" in capsys.readouterr().err
    assert main(["rig", "estop", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "state estop" in out and "the table at rest" in out
    assert rig.call(lambda: rig.plc.state) == State.ESTOP and rig.call(rig.plc._table_at_rest)
    assert main(["rig", "status", "--config", str(cfg), "--json"]) == 0
    st = json.loads(capsys.readouterr().out)
    assert (st["state"], st["position_mm"], st["frequency_hz"]) == ("estop", 0.0, 0.0)
    assert main(["rig", "reset", "--config", str(cfg)]) == 0
    assert "reset: estop -> idle" in capsys.readouterr().out
    assert rig.call(lambda: rig.plc.state) == State.IDLE
    assert main(["rig", "reset", "--config", str(cfg)]) == 0  # nothing to do
    assert "nothing to reset" in capsys.readouterr().out


@pytest.mark.slow
def test_a_fault_is_named_and_a_reset_that_does_not_take_is_said(tmp_path, capsys, monkeypatch):
    """A drive fault while the table is still ramping down (a 1000 s ramp: it never comes to rest
    here): status names the fault, reset reports that the PLC stayed in fault (exit 2)."""
    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=1e4), estop_ramp_s=1000.0), speed=10.0).start()
    try:
        cfg = _config(tmp_path, rig.endpoints["modbus"][1])
        _start_sweep(rig)
        rig.call(rig.plc.inject_fault)
        assert main(["rig", "status", "--config", str(cfg)]) == 0
        assert f"state fault, fault {int(Fault.INJECTED)} (injected)" in capsys.readouterr().out
        monkeypatch.setattr(rigcmd, "SETTLE_S", 1.0)  # how long reset waits for rest (a setting, not a stub)
        assert main(["rig", "reset", "--config", str(cfg)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0] == (f"shakeid: error: {cfg}: reset did not take effect: the PLC stayed in "
                                            "fault (fault 7 injected; the table did not come to rest)")
        assert rig.call(lambda: rig.plc.state) == State.FAULT
    finally:
        rig.stop()


@pytest.mark.slow
def test_an_unreachable_plc_is_one_line_and_exit_2(tmp_path, capsys):
    cfg = _config(tmp_path, free_port())  # nothing listens there
    for action in ("status", "estop", "reset"):
        assert main(["rig", action, "--config", str(cfg)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"shakeid: error: {cfg}: PLC at 127.0.0.1:") and "does not answer" in err[0]
    # as a separate process (no pytest log capture): pymodbus's own "Connection to ... failed" log line is
    # not printed before ours
    import subprocess
    import sys
    from pathlib import Path

    p = subprocess.run([str(Path(sys.executable).with_name("shakeid")), "rig", "status", "--config", str(cfg)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.strip().splitlines() == [err[0]], p.stderr
