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
    ("[plc]\ntransport = 'profibus'\n", "transport must be one of modbus, ads"),
    ("[rig.effects]\nwarp = 1.0\n", "unknown effect"),
    ("[sampling\nfs_hz = 1\n", "not valid TOML"),
    ("[sim]\nspeed = -1\n", "positive"),
    ("[sampling]\nsource = 'can'\n", "source must be"),
    ("[rig]\nend_stop_travel = 17.5\n", "unknown key.*end_stop_travel"),
    ("[rig]\nend_stop_travel_mm = -2.0\n", "end_stop_travel_mm must be positive"),
    ("[rig]\ncontact_stiffness_n_per_m = 0\n", "contact stiffness"),
])
def test_bad_configs_are_refused_by_name(tmp_path, text, message):
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_end_stops_from_the_rig_section(tmp_path):
    """[rig] sets the end stops the simulated PLC runs with; inf takes them away; defaults otherwise."""
    from sim.plc import RigPLC

    path = tmp_path / "rig.toml"
    path.write_text("[rig]\nend_stop_travel_mm = 20.0\ncontact_stiffness_n_per_m = 5e5\ncontact_damping_ns_per_m = 250\n")
    plc = RigPLC(load_config(path).plc_config())
    assert plc.physics.travel == {"q2": pytest.approx(0.020)}
    assert plc.physics.coefficient("q1_dot", "stop(q2)") == pytest.approx(-5e5 / 0.49)
    assert plc.physics.coefficient("q1_dot", "q1*contact(q2)") == pytest.approx(-250 / 0.49)
    assert "stop(q2)" not in plc.model.term_names  # the smooth model, as identification sees it
    path.write_text("[rig]\nend_stop_travel_mm = inf\n")
    assert RigPLC(load_config(path).plc_config()).physics.travel == {}
    assert load_config(EXAMPLES / "sim-rig.toml").rig.end_stop_travel_mm == 17.5


def test_a_configs_moving_mass_is_what_a_sweep_records(tmp_path):
    """[rig] mass_kg is the lab's moving mass: a sweep records it (/entry@rig_config) so identify scales
    the forces by it; a configuration without it records none (identify then says it assumed one)."""
    cfg = tmp_path / "lab.toml"
    cfg.write_text("[rig]\nmass_kg = 0.98\n")
    meta = load_config(cfg).recording_metadata()
    assert meta["moving_mass_kg"] == 0.98 and meta["source"].endswith("lab.toml")
    cfg.write_text("[limits]\nwatchdog_s = 0.5\n")
    assert "moving_mass_kg" not in load_config(cfg).recording_metadata()
