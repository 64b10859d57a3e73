"""docker-compose.yml: validated by Debian's docker-compose (no engine needed), checked against what the
services run, and its rig configuration exercised for real with both services as local processes."""
from __future__ import annotations
import pytest

import shutil
import signal
import subprocess
import sys
from pathlib import Path

import yaml

from shakeid.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
COMPOSE = shutil.which("docker-compose")


def _config(path: Path) -> subprocess.CompletedProcess:
    assert COMPOSE, ("Debian's docker-compose is needed to validate docker-compose.yml: `make test` installs it "
                     "(apt-get install docker-compose) when run as root; otherwise install it once")
    return subprocess.run([COMPOSE, "-f", str(path), "config"], capture_output=True, text=True, cwd=path.parent,
                          env={"PATH": "/usr/bin:/bin", "SHAKEID_TOKENS": "t" * 12 + ":operator"})


def _mount(v) -> tuple[str, str]:
    """(source, target) of a volume entry, short ("src:dst:mode", compose v1) or long syntax."""
    if isinstance(v, dict):
        return v.get("source", ""), v["target"]
    parts = v.split(":")
    return parts[0], parts[1]


def test_compose_file_is_valid_and_runs_what_exists():
    p = _config(REPO / "docker-compose.yml")
    assert p.returncode == 0, p.stderr
    doc = yaml.safe_load(p.stdout)
    services = doc["services"]
    assert set(services) == {"rig-sim", "controller", "server", "dask-scheduler", "dask-worker"}
    server, rig, ctl = services["server"], services["rig-sim"], services["controller"]
    assert "controller" in server["depends_on"] and "rig-sim" in ctl["depends_on"]
    for svc in (server, ctl):  # the catalog, the recordings and the controller's socket are shared
        assert any(src == "shakeid-data" and dst == "/data" for src, dst in map(_mount, svc["volumes"]))
    address = server["command"][server["command"].index("--controller") + 1]
    assert address == ctl["command"][ctl["command"].index("--address") + 1] == "unix:/data/controller.sock"
    assert "shakeid-data" in doc["volumes"]
    assert server["environment"]["SHAKEID_TOKENS"] == "t" * 12 + ":operator"  # interpolated from the environment
    for svc in (server, rig, ctl):
        assert (Path(svc["build"]["context"]) / "Dockerfile").exists()
        assert svc["command"][0] == "shakeid"
        build_parser().parse_args(svc["command"][1:])  # a real subcommand with real options (exits if not)
        for src, _ in map(_mount, svc["volumes"]):
            if src.startswith("/"):  # a bind mount: the file must be in the repository
                assert Path(src).exists(), src
    from server.settings import Settings

    settings = Settings.load(REPO / "deploy" / "compose-rig.toml", env={})
    assert settings.rig.plc["host"] == "rig-sim" and str(settings.data_dir) == "/data"
    _check_stop_listener(server, ctl)
    _check_dask_services(services)


def _published(svc: dict) -> set[int]:
    """The host ports a service publishes (long syntax, as `docker-compose config` writes it; or short)."""
    return {int(p["published"]) if isinstance(p, dict) else int(str(p).split(":")[-2]) for p in svc.get("ports", [])}


def _check_stop_listener(server: dict, ctl: dict) -> None:
    """The controller's stop listener is published where the dashboard and the CLI look for it (the
    server's port + STOP_PORT_OFFSET), listens beyond the container's loopback, and takes the server's tokens."""
    from server.settings import STOP_PORT_OFFSET, Settings

    web_port = int(server["command"][server["command"].index("--port") + 1])
    assert web_port in _published(server)
    settings = Settings.load(REPO / "deploy" / "compose-rig.toml", env=ctl["environment"])
    settings.resolve_stop()
    assert settings.stop_port == web_port + STOP_PORT_OFFSET and settings.stop_port in _published(ctl)
    assert settings.stop_host == "0.0.0.0"
    assert ctl["environment"]["SHAKEID_TOKENS"] == server["environment"]["SHAKEID_TOKENS"]


def _check_dask_services(services: dict) -> None:
    """The server's jobs go to the compose Dask cluster: its scheduler address is the one the worker
    dials, the worker sees the data volume where the server does, and both commands parse with
    distributed's own command-line definitions (a misspelt option fails here)."""
    from distributed.cli import dask_scheduler, dask_worker

    from server.settings import Settings

    server, sched, work = services["server"], services["dask-scheduler"], services["dask-worker"]
    assert sched["command"][:2] == ["dask", "scheduler"] and work["command"][:2] == ["dask", "worker"]
    s_opts = dask_scheduler.main.make_context("dask scheduler", sched["command"][2:]).params
    w_opts = dask_worker.main.make_context("dask worker", work["command"][2:]).params
    address = server["environment"]["SHAKEID_SCHEDULER"]
    assert address == w_opts["scheduler"] == f"tcp://dask-scheduler:{s_opts['port']}"
    assert Settings.load(REPO / "deploy" / "compose-rig.toml", env=server["environment"]).scheduler == address
    assert str(s_opts["port"]) in map(str, sched["expose"]) and w_opts["nthreads"] == 1
    assert "dask-scheduler" in server["depends_on"] and "dask-scheduler" in work["depends_on"]
    assert ("shakeid-data", "/data") in list(map(_mount, work["volumes"]))
    for svc in (sched, work):
        assert (Path(svc["build"]["context"]) / "Dockerfile").exists() and svc["image"] == server["image"]


def test_a_broken_compose_file_is_caught(tmp_path):
    """The validator itself: a typo in a key and a service without an image or build both fail."""
    text = (REPO / "docker-compose.yml").read_text()
    (tmp_path / "typo.yml").write_text(text.replace("depends_on:", "depend_on:"))
    (tmp_path / "nobuild.yml").write_text(text.replace("    build: .\n    image: shakeid:latest\n", "", 1))
    for name in ("typo.yml", "nobuild.yml"):
        p = _config(tmp_path / name)
        assert p.returncode != 0, name


@pytest.mark.slow
def test_compose_rig_configuration_drives_a_sweep_through_the_service(tmp_path):
    """The compose wiring without Docker: `shakeid sim`, `shakeid controller --config` and `shakeid serve
    --config --controller` as three processes with the compose rig configuration (hosts pointed at
    loopback, the socket in the data directory): the service drives the separate rig."""
    import httpx

    from sim.server import free_port

    from .server.conftest import wait_for

    mb, st, http = free_port(), free_port(), free_port()
    text = (REPO / "deploy" / "compose-rig.toml").read_text().replace("rig-sim", "127.0.0.1")
    text = text.replace("port = 5020", f"port = {mb}").replace(":5021", f":{st}")
    text = text.replace('data_dir = "/data"', f'data_dir = "{tmp_path / "data"}"').replace("speed = 1.0", "speed = 10.0")
    text = text.replace("watchdog_s = 0.5", "watchdog_s = 5.0")  # 50 ms heartbeats are 0.5 s of rig time at 10x
    cfg = tmp_path / "rig.toml"
    cfg.write_text(text)
    exe = str(Path(sys.executable).with_name("shakeid"))
    rig = subprocess.Popen([exe, "sim", "--config", str(cfg)], stdout=subprocess.PIPE, text=True)
    env = {"PATH": "/usr/bin:/bin", "SHAKEID_TOKENS": "compose-operator-token:operator"}
    log = open(tmp_path / "serve.log", "w")  # a file, not a pipe nobody reads (a full pipe blocks the writer)
    address = f"unix:{tmp_path / 'data' / 'controller.sock'}"
    ctl = subprocess.Popen([exe, "controller", "--config", str(cfg), "--address", address], env=env,
                           stdout=log, stderr=subprocess.STDOUT, text=True)
    serve = subprocess.Popen([exe, "serve", "--config", str(cfg), "--port", str(http), "--controller", address],
                             env=env, stdout=log, stderr=subprocess.STDOUT, text=True)
    try:
        assert "Modbus" in rig.stdout.readline()
        client = httpx.Client(base_url=f"http://127.0.0.1:{http}", timeout=10,
                              headers={"Authorization": "Bearer compose-operator-token"})

        def up():
            try:
                return client.get("/api/health").status_code == 200
            except httpx.HTTPError:
                return False

        wait_for(up, 60, "service")
        status = client.get("/api/rig").json()
        assert status["simulated"] is False and status["plc"]["reachable"] and status["limits"]["watchdog_s"] == 5.0
        sweep = client.post("/api/sweeps", json={"f_start_hz": 2, "f_end_hz": 10, "duration_s": 10,
                                                 "amplitude_mm": 1.0, "settle_s": 1.0})
        assert sweep.status_code == 202, sweep.text
        sid = sweep.json()["id"]
        done = wait_for(lambda: (s := client.get(f"/api/sweeps/{sid}").json())["state"] not in ("queued", "running")
                        and s, 60, "sweep end")
        assert done["state"] == "completed", done
        rec = client.get(f"/api/recordings/{done['recording_id']}").json()
        # the sweep and at least the settle after it, less at most one 64-sample frame (daq.sweep)
        assert rec["info"]["gaps"] == 0 and rec["info"]["samples"] >= 11 * 2048 - 64
    finally:
        for proc in (serve, ctl, rig):
            proc.send_signal(signal.SIGTERM)
        assert serve.wait(30) in (0, -signal.SIGTERM), (tmp_path / "serve.log").read_text()
        assert ctl.wait(30) == 0, (tmp_path / "serve.log").read_text()
        rig.wait(30)
        log.close()


@pytest.mark.slow
def test_the_wheel_the_image_installs_carries_the_service(tmp_path):
    """The Dockerfile runs `pip install .` (no editable install, no source tree at run time): the wheel
    must carry every package module, the compiled kernel, the dashboard page and the console script."""
    import zipfile

    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(REPO)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    (wheel,) = tmp_path.glob("shakeid-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for package in ("identify", "protocol", "sim", "daq", "reports", "server", "shakeid"):
        for module in (REPO / package).rglob("*.py"):
            assert str(module.relative_to(REPO)) in names, module
    assert {"server/dashboard.html", "server/static/dashboard.js", "server/static/dashboard.css"} <= names
    for kernel in ("identify/_simkernel", "identify/_polyrows"):
        assert any(n.startswith(kernel) and n.endswith(".so") for n in names), kernel
    entry = next(n for n in names if n.endswith("entry_points.txt"))
    assert "shakeid = shakeid.cli:main" in zipfile.ZipFile(wheel).read(entry).decode()
    assert not any(n.startswith(("tests/", "benchmarks/")) for n in names)
