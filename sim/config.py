"""Rig configuration file (TOML), one shape for the simulated and the real rig; the DAQ reads it too.

    [plc]      transport ("modbus" | "ads"), host, port (Modbus) / ams_net_id, ams_port (ADS)
    [stream]   url (a pyserial URL: socket://host:port or /dev/ttyUSB0), sensitivity_counts_per_ms2
    [can]      interface, channel, node (python-can; optional: accelerometers on a CAN bus)
    [sampling] fs_hz, channels (names, in stream order), source ("stream" | "can": where the DAQ
               reads the accelerometers; the simulated rig always serves both when [can] is set)
    [limits]   max_stroke_mm, max_velocity_ms, max_acceleration_ms2, f_min_hz, f_max_hz,
               max_duration_s, watchdog_s
    [rig]      mass_kg, damping_ns_per_m, stiffness_n_per_m, cubic_stiffness_n_per_m3, input_gain,
               end_stop_travel_mm (inf: no end stops), contact_stiffness_n_per_m, contact_damping_ns_per_m,
               end_stop_lower_mm / end_stop_upper_mm (per side), [rig.effects] (simulated rig only: the
               physics, its end stops and hidden effects); the suite's further physics fields
               (stiffness_drift, hysteresis_*, absorber_*, spring_free_play_mm: sim/rig.py) are accepted
               but the PLC refuses them (run_sweep only)
    [sensors]  noise_ms2, bias_ms2 (simulated rig only)
    [sim]      speed (simulated rig only)
    [server]   data_dir, tokens, ... (the HTTP service, server/settings.py)
    [compute]  scheduler, connect_timeout_s (the service's jobs on a Dask cluster, server/settings.py)

Unknown keys are refused by name, so a typo in a limit cannot silently leave the default in force.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from identify.errors import ShakeidError
from protocol import ACCELEROMETER_SOURCES, PLC_TRANSPORTS
from protocol.plc import Limits

from .plc import PLCConfig
from .rig import RigParameters
from .sensors import Accelerometer


class ConfigError(ShakeidError):
    """The rig configuration file is unreadable or names something unknown."""


@dataclass
class RigConfig:
    plc: dict = field(default_factory=lambda: {"transport": PLC_TRANSPORTS[0], "host": "127.0.0.1", "port": 5020})
    stream: dict = field(default_factory=lambda: {"url": "socket://127.0.0.1:5021",
                                                   "sensitivity_counts_per_ms2": 32767 / 50.0})
    can: dict = field(default_factory=dict)
    fs_hz: float = 2048.0
    channels: tuple[str, ...] = ("table_acc", "mass_acc")
    accelerometers: str = ACCELEROMETER_SOURCES[0]  # [sampling] source
    limits: Limits = field(default_factory=Limits)
    rig: RigParameters = field(default_factory=RigParameters.paper_table1)
    sensor_noise_ms2: float = 0.02
    sensor_bias_ms2: float = 0.0
    speed: float = 1.0
    source: str = "<defaults>"
    server: dict = field(default_factory=dict)
    compute: dict = field(default_factory=dict)
    moving_mass_kg: float | None = None  # [rig] mass_kg when the file gives it: the lab's mass, recorded

    def recording_metadata(self) -> dict:
        """What a sweep records of this configuration (/entry@rig_config): where it came from, the PLC's
        link, and the rig's moving mass when the file gives it (identify scales forces by it)."""
        return {"source": self.source, "plc": self.plc,
                **({"moving_mass_kg": self.moving_mass_kg} if self.moving_mass_kg else {})}

    def plc_config(self) -> PLCConfig:
        """The simulated PLC of this configuration; its two accelerometers alike ([sensors]), one object each."""
        def sensor():
            return Accelerometer(noise_fraction=0.0, noise_ms2=self.sensor_noise_ms2, bias_ms2=self.sensor_bias_ms2)
        return PLCConfig(rig=self.rig, limits=self.limits, fs_hz=self.fs_hz, table_sensor=sensor(), mass_sensor=sensor())


def _take(section: dict, allowed: set[str], where: str, path) -> dict:
    unknown = set(section) - allowed
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) in [{where}]: {', '.join(sorted(unknown))}; "
                          f"known: {', '.join(sorted(allowed))}")
    return section


def load_config(path) -> RigConfig:
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    cfg = RigConfig(source=str(path))
    _take(doc, {"plc", "stream", "can", "sampling", "limits", "rig", "sensors", "sim", "server", "compute"}, "top level",
          path)
    cfg.server = dict(doc.get("server", {}))  # checked by the HTTP service (server/settings.py)
    cfg.compute = dict(doc.get("compute", {}))  # likewise
    cfg.can = dict(_take(doc.get("can", {}), {"interface", "channel", "node"}, "can", path))
    if "plc" in doc:
        cfg.plc = dict(_take(doc["plc"], {"transport", "host", "port", "ams_net_id", "ams_port"}, "plc", path))
        if cfg.plc.get("transport", PLC_TRANSPORTS[0]) not in PLC_TRANSPORTS:
            raise ConfigError(f"{path}: [plc] transport must be one of {', '.join(PLC_TRANSPORTS)}")
    if "stream" in doc:
        cfg.stream.update(_take(doc["stream"], {"url", "sensitivity_counts_per_ms2"}, "stream", path))
    sampling = _take(doc.get("sampling", {}), {"fs_hz", "channels", "source"}, "sampling", path)
    cfg.accelerometers = sampling.get("source", cfg.accelerometers)
    if cfg.accelerometers not in ACCELEROMETER_SOURCES or (cfg.accelerometers == "can" and not cfg.can.get("interface")):
        raise ConfigError(f"{path}: [sampling] source must be one of {', '.join(ACCELEROMETER_SOURCES)} "
                          "(can needs [can] interface)")
    cfg.fs_hz = float(sampling.get("fs_hz", cfg.fs_hz))
    cfg.channels = tuple(sampling.get("channels", cfg.channels))
    limits = _take(doc.get("limits", {}), {f.name for f in fields(Limits)}, "limits", path)
    cfg.limits = Limits(**{k: float(v) for k, v in limits.items()})
    if "rig" in doc:
        rig = dict(_take(doc["rig"], {f.name for f in fields(RigParameters)}, "rig", path))
        try:
            cfg.rig = RigParameters(**rig)
            cfg.moving_mass_kg = cfg.rig.mass_kg if "mass_kg" in rig else None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: [rig]: {exc}") from None
    sensors = _take(doc.get("sensors", {}), {"noise_ms2", "bias_ms2"}, "sensors", path)
    cfg.sensor_noise_ms2 = float(sensors.get("noise_ms2", cfg.sensor_noise_ms2))
    cfg.sensor_bias_ms2 = float(sensors.get("bias_ms2", cfg.sensor_bias_ms2))
    cfg.speed = float(_take(doc.get("sim", {}), {"speed"}, "sim", path).get("speed", cfg.speed))
    if cfg.fs_hz <= 0 or cfg.speed <= 0:
        raise ConfigError(f"{path}: fs_hz and speed must be positive")
    return cfg
