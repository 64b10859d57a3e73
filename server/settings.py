"""Settings of the HTTP service: the rig configuration's [server] section, then the environment.

    [server]
    data_dir = "/var/lib/shakeid"          # recordings, models, the SQLite catalog
    tokens = { "k3y-of-anna" = "operator", "k3y-of-ben" = "viewer" }
    sim_speed = 10.0                         # embedded simulated rig only (no --config)
    identify_workers = 1                     # processes for identification jobs
    auto_identify = true                     # identify every completed sweep
    max_upload_mb = 512                      # larger uploads are refused (413) before they are read
    controller = "unix:/run/shakeid/controller.sock"   # attach to a rig controller that runs on its own
                                             # (`shakeid controller`); unset: `shakeid serve` starts one
    stop_port = 8001                         # the rig controller's stop listener (POST /api/rig/estop
                                             # where no viewer waits); unset: the web port + 1; 0: none
    stop_host = "0.0.0.0"                    # where it listens; unset: the web server's --host

    [compute]
    scheduler = "tcp://dask-scheduler:8786"  # run identification jobs on this Dask cluster (its workers
                                             # must see data_dir at the same path); unset: the embedded
                                             # process pool of identify_workers processes
    connect_timeout_s = 10.0                 # a job fails with the reason when the scheduler is not
                                             # reached in this time

Environment (wins over the file): SHAKEID_DATA_DIR, SHAKEID_TOKENS ("token:role,token:role"),
SHAKEID_SIM_SPEED, SHAKEID_CONTROLLER, SHAKEID_MAX_UPLOAD_MB, SHAKEID_SCHEDULER ([compute] scheduler),
SHAKEID_STOP_PORT, SHAKEID_STOP_HOST.
With no configuration file the service starts an embedded simulated rig; with no
token configured it makes one operator token, prints it and keeps it in <data_dir>/operator-token so a
new user can log in without reading anything first.
"""
from __future__ import annotations

import hmac
import os
import secrets
from dataclasses import dataclass, field
from pathlib import Path

from identify.errors import ShakeidError
from sim.config import RigConfig, load_config

ROLES = ("viewer", "operator")
KEYS = {"data_dir", "tokens", "sim_speed", "identify_workers", "auto_identify", "max_upload_mb", "controller",
        "stop_port", "stop_host"}
#: `shakeid serve`'s port when none is given (`--port`)
DEFAULT_WEB_PORT = 8000
#: the stop listener's port is the web server's plus this, unless stop_port is set (server/stoplistener.py)
STOP_PORT_OFFSET = 1
#: where the stop listener listens when neither stop_host nor a web server's --host says (`shakeid controller`)
DEFAULT_STOP_HOST = "127.0.0.1"
COMPUTE_KEYS = {"scheduler", "connect_timeout_s"}


def token_role(tokens: dict[str, str], token: str) -> str | None:
    """The role of a bearer token, or None for an unknown one (compared in constant time): the web
    server's check (server/auth.py) and the stop listener's (server/stoplistener.py)."""
    return next((r for t, r in tokens.items() if hmac.compare_digest(t.encode(), token.encode())), None)


def token_refusal(found: str | None, needed: str) -> tuple[int, str] | None:
    """(status, detail) refusing a token of role `found` (None: no or an unknown token, 401) where `needed`
    or above is required (403), or None when it may: one wording for both ports (auth.py, stoplistener.py)."""
    if found is None:
        return 401, "a valid bearer token is needed (Authorization: Bearer <token>)"
    if ROLES.index(found) < ROLES.index(needed):
        return 403, f"this needs the {needed} role; the token is {found}"
    return None


class SettingsError(ShakeidError):
    """The service's configuration is unusable (named)."""


@dataclass
class Settings:
    data_dir: Path = Path("shakeid-data")
    tokens: dict[str, str] = field(default_factory=dict)  # token -> role
    rig: RigConfig | None = None                         # None: embedded simulated rig
    sim_speed: float = 1.0
    identify_workers: int = 1
    auto_identify: bool = True
    max_upload_mb: float = 512.0
    generated_token: str | None = None                   # set when no token was configured
    config_path: Path | None = None                      # the rig configuration file, if any
    controller: str | None = None                        # an existing rig controller; None: start one
    scheduler: str | None = None                         # a Dask scheduler for jobs; None: process pool
    connect_timeout_s: float = 10.0                      # reaching the Dask scheduler, seconds
    stop_port: int | None = None                         # the stop listener; None: web port + STOP_PORT_OFFSET; 0: none
    stop_host: str | None = None                         # its address; None: the web server's --host

    @classmethod
    def load(cls, config_path=None, env=None, data_dir=None) -> "Settings":
        env = os.environ if env is None else env
        s = cls()
        if config_path:
            s.config_path = Path(config_path).resolve()
            s.rig = load_config(config_path)
            section = s.rig.server
            unknown = set(section) - KEYS
            if unknown:
                raise SettingsError(f"{config_path}: unknown key(s) in [server]: {', '.join(sorted(unknown))}; "
                                    f"known: {', '.join(sorted(KEYS))}")
            s.data_dir = Path(section.get("data_dir", s.data_dir))
            s.tokens = dict(section.get("tokens", {}))
            s.sim_speed = float(section.get("sim_speed", s.sim_speed))
            s.identify_workers = int(section.get("identify_workers", s.identify_workers))
            s.auto_identify = bool(section.get("auto_identify", s.auto_identify))
            s.max_upload_mb = float(section.get("max_upload_mb", s.max_upload_mb))
            s.controller = section.get("controller", s.controller)
            s.stop_port = section.get("stop_port", s.stop_port)
            s.stop_host = section.get("stop_host", s.stop_host)
            compute = s.rig.compute
            unknown = set(compute) - COMPUTE_KEYS
            if unknown:
                raise SettingsError(f"{config_path}: unknown key(s) in [compute]: {', '.join(sorted(unknown))}; "
                                    f"known: {', '.join(sorted(COMPUTE_KEYS))}")
            s.scheduler = compute.get("scheduler", s.scheduler)
            s.connect_timeout_s = float(compute.get("connect_timeout_s", s.connect_timeout_s))
        if env.get("SHAKEID_DATA_DIR"):
            s.data_dir = Path(env["SHAKEID_DATA_DIR"])
        if data_dir:
            s.data_dir = Path(data_dir)
        if env.get("SHAKEID_TOKENS"):
            try:
                s.tokens = dict(item.strip().rsplit(":", 1) for item in env["SHAKEID_TOKENS"].split(",") if item.strip())
            except ValueError:
                raise SettingsError("SHAKEID_TOKENS must read token:role,token:role") from None
        if env.get("SHAKEID_MAX_UPLOAD_MB"):
            s.max_upload_mb = float(env["SHAKEID_MAX_UPLOAD_MB"])
        if env.get("SHAKEID_CONTROLLER"):
            s.controller = env["SHAKEID_CONTROLLER"]
        if env.get("SHAKEID_STOP_PORT"):
            s.stop_port = env["SHAKEID_STOP_PORT"]
        if env.get("SHAKEID_STOP_HOST"):
            s.stop_host = env["SHAKEID_STOP_HOST"]
        if s.stop_port is not None:
            try:
                s.stop_port = int(s.stop_port)
            except (TypeError, ValueError):
                s.stop_port = -1
            if not 0 <= s.stop_port <= 65535:
                raise SettingsError("stop_port must be a TCP port (1-65535), or 0 for no stop listener")
        if env.get("SHAKEID_SCHEDULER"):
            s.scheduler = env["SHAKEID_SCHEDULER"]
        if s.scheduler is not None and not (isinstance(s.scheduler, str) and "://" in s.scheduler):
            raise SettingsError(f"[compute] scheduler must be a Dask address like tcp://HOST:8786, not {s.scheduler!r}")
        if s.connect_timeout_s <= 0:
            raise SettingsError("[compute] connect_timeout_s must be positive")
        if env.get("SHAKEID_SIM_SPEED"):
            s.sim_speed = float(env["SHAKEID_SIM_SPEED"])
        bad = {t: r for t, r in s.tokens.items() if r not in ROLES}
        if bad:
            raise SettingsError(f"token role(s) {sorted(set(bad.values()))} unknown: roles are {', '.join(ROLES)}")
        short = [t for t in s.tokens if len(t) < 8]
        if short:
            raise SettingsError(f"{len(short)} token(s) shorter than 8 characters: use long random tokens")
        if not 0 < s.sim_speed < float("inf") or s.identify_workers < 1:
            raise SettingsError("sim_speed must be positive and identify_workers at least 1")
        return s

    def resolve_stop(self, web_host: str | None = None, web_port: int = DEFAULT_WEB_PORT) -> None:
        """Fill in the stop listener's address from the web server's (`shakeid serve --host --port`): the
        port STOP_PORT_OFFSET above the web port, the same host, unless stop_port/stop_host say."""
        if self.stop_port is None:
            self.stop_port = web_port + STOP_PORT_OFFSET if web_port + STOP_PORT_OFFSET <= 65535 else 0
        if self.stop_host is None:
            self.stop_host = web_host or DEFAULT_STOP_HOST

    def prepare(self) -> None:
        """Create the data directory; make and keep an operator token when none is configured."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        (self.data_dir / "recordings").mkdir(exist_ok=True)
        (self.data_dir / "results").mkdir(exist_ok=True)
        if not self.tokens:
            path = self.data_dir / "operator-token"
            if not path.exists():
                path.write_text(secrets.token_urlsafe(24) + "\n")
                path.chmod(0o600)
            self.generated_token = path.read_text().strip()
            self.tokens = {self.generated_token: "operator"}
