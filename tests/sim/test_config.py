"""Rig configuration files: the shipped examples load, mistakes are refused by name."""
from pathlib import Path

import pytest

from sim.config import ConfigError, load_config

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_shipped_examples_load():
    sim = load_config(EXAMPLES / "sim-rig.toml")
    assert sim.plc["transport"] == "modbus" and sim.fs_hz == 2048.0 and sim.limits.watchdog_s == 0.5
    assert sim.rig.model().coefficient("q1_dot", "q1*q2^2") == pytest.approx(1.162e4, rel=1e-3)
    real = load_config(EXAMPLES / "real-rig.toml")
    assert real.plc["transport"] == "ads" and real.limits.f_max_hz == 40.0 and real.stream["url"] == "/dev/ttyUSB0"


@pytest.mark.parametrize("text,message", [
    ("[limits]\nmax_strok_mm = 3\n", "unknown key.*max_strok_mm"),
    ("[plc]\ntransport = 'profibus'\n", "transport"),
    ("[rig.effects]\nwarp = 1.0\n", "unknown effect"),
    ("[sampling\nfs_hz = 1\n", "not valid TOML"),
    ("[sim]\nspeed = -1\n", "positive"),
    ("[sampling]\nsource = 'can'\n", "source must be"),
])
def test_bad_configs_are_refused_by_name(tmp_path, text, message):
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)
