"""The stop listener (server/stoplistener.py) against a real `shakeid serve`: the rig controller's own HTTP
port stops a running sweep with an operator token, refuses a viewer's (403) and none (401), answers the
dashboard's CORS preflight, and delivers the stop while many live viewers load the web server's port.
/api/health names it, the dashboard's CSP allows it, `shakeid rig estop --server` posts to it (and falls
back to the web server's route when nothing answers there).

Structure, not timing: waits are for states; no wall-clock time is asserted.
"""
from __future__ import annotations

import subprocess

import httpx
import pytest

from server.settings import STOP_PORT_OFFSET, Settings, SettingsError
from server.stoplistener import ESTOP_PATH
from shakeid.rigcmd import stop_url
from sim.server import free_port

from .conftest import OPERATOR, SHAKEID, START_TIMEOUT_S, VIEWER, Service, wait_for
from .test_dashboard import TIMEOUT_MS, browser  # noqa: F401 - the browser fixture (Debian's Chromium)
from .test_live import open_stream

SWEEP = {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 600.0, "amplitude_mm": 1.0}
VIEWERS = 120


@pytest.fixture(scope="module")
def stop_service(tmp_path_factory):
    """A service whose stop listener has a port drawn free now (the default, web port + 1, may be taken
    by another test's server on a shared machine)."""
    s = Service(tmp_path_factory.mktemp("stop") / "data", env={"SHAKEID_STOP_PORT": str(free_port())}).start()
    yield s
    s.stop()


def _stop_url(service: Service) -> str:
    return wait_for(lambda: httpx.get(service.url + "/api/health", timeout=30).json()["stop_url"],
                    timeout_s=START_TIMEOUT_S, what="the controller attached and its stop listener named")


def _running_sweep(op: httpx.Client) -> tuple[str, str]:
    """Reset the rig and start a long sweep; (sweep id, recording id) once it runs."""
    wait_for(lambda: op.get("/api/rig").json()["active_sweep"] is None, what="an idle rig")
    wait_for(lambda: op.post("/api/rig/reset").status_code == 200, what="the rig reset")
    sweep = op.post("/api/sweeps", json=SWEEP)
    assert sweep.status_code == 202, sweep.text
    sweep_id = sweep.json()["id"]
    rec_id = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep_id}").json())["state"] == "running"
                      and s["recording_id"], what="the sweep running")
    wait_for(lambda: op.get("/api/rig").json()["plc"]["state"] == "running", what="the PLC running")
    return sweep_id, rec_id


def _stopped(op: httpx.Client, sweep_id: str) -> None:
    wait_for(lambda: op.get("/api/rig").json()["plc"]["state"] == "estop", what="the PLC in estop")
    wait_for(lambda: op.get(f"/api/sweeps/{sweep_id}").json()["state"] == "aborted", what="the sweep aborted")


@pytest.mark.slow
def test_the_stop_listener_stops_a_running_sweep_and_refuses_others(stop_service):
    url = _stop_url(stop_service)
    assert url == f"http://127.0.0.1:{stop_service.extra_env['SHAKEID_STOP_PORT']}{ESTOP_PATH}"
    with stop_service.client() as op:
        sweep_id, _ = _running_sweep(op)
        none = httpx.post(url, timeout=10)
        assert none.status_code == 401 and none.headers["www-authenticate"] == "Bearer", none.text
        viewer = httpx.post(url, headers={"Authorization": f"Bearer {VIEWER}"}, timeout=10)
        assert viewer.status_code == 403 and "operator role" in viewer.json()["detail"], viewer.text
        elsewhere = httpx.post(url.replace(ESTOP_PATH, "/api/rig/reset"),
                               headers={"Authorization": f"Bearer {OPERATOR}"}, timeout=10)
        assert elsewhere.status_code == 404
        assert op.get("/api/rig").json()["plc"]["state"] == "running"  # none of those stopped anything
        stop = httpx.post(url, headers={"Authorization": f"Bearer {OPERATOR}"}, timeout=10)
        assert stop.status_code == 200, stop.text
        assert stop.json() == {"state": "estop", "aborted_sweep": sweep_id}  # the web route's answer
        _stopped(op, sweep_id)


def test_the_dashboard_may_post_the_stop_there(stop_service):
    url = _stop_url(stop_service)
    page = httpx.get(stop_service.url + "/", timeout=10)
    connect = next(d for d in page.headers["content-security-policy"].split(";") if "connect-src" in d)
    assert url.removesuffix(ESTOP_PATH) in connect.split()
    asked = {"Access-Control-Request-Method": "POST", "Access-Control-Request-Headers": "authorization"}
    ok = httpx.options(url, headers={"Origin": stop_service.url, **asked}, timeout=10)
    assert ok.status_code == 204 and ok.headers["access-control-allow-origin"] == stop_service.url
    assert "Authorization" in ok.headers["access-control-allow-headers"]
    assert "POST" in ok.headers["access-control-allow-methods"]
    foreign = httpx.options(url, headers={"Origin": "http://attacker.example", **asked}, timeout=10)
    assert foreign.status_code == 403 and "access-control-allow-origin" not in foreign.headers


@pytest.mark.slow
def test_the_dashboards_stop_button_posts_to_the_stop_listener(browser, stop_service):  # noqa: F811
    """In Chromium, under the page's own CSP: the press goes to the stop listener (a CSP or CORS refusal
    would show as the fallback's POST to the web server's route instead)."""
    url = _stop_url(stop_service)
    ctx = browser.new_context()
    page = ctx.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    posts, errors = [], []
    page.on("request", lambda r: r.method == "POST" and posts.append(r.url))
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        with stop_service.client() as op:
            sweep_id, _ = _running_sweep(op)
            with page.expect_response(lambda r: r.url.endswith("/api/health")):
                page.goto(f"{stop_service.url}/#token={OPERATOR}")
            page.wait_for_selector("#session:has-text('operator')")
            page.click("#estop")
            page.wait_for_selector(f".msg.error:has-text('sweep {sweep_id} aborted')")
            assert posts == [url], posts
            _stopped(op, sweep_id)
        assert not errors, errors
    finally:
        ctx.close()


def test_the_stop_is_delivered_while_many_viewers_load_the_web_server(stop_service):
    url = _stop_url(stop_service)
    with stop_service.client() as op:
        sweep_id, rec_id = _running_sweep(op)
        streams = [open_stream(stop_service.port, rec_id, small_window=k % 10 == 0) for k in range(VIEWERS)]
        try:
            wait_for(lambda: op.get("/api/live").json()["recordings"].get(rec_id, {}).get("viewers") == VIEWERS,
                     timeout_s=240, what="every viewer connected")
            stop = httpx.post(url, headers={"Authorization": f"Bearer {OPERATOR}"}, timeout=30)
            assert stop.status_code == 200 and stop.json()["aborted_sweep"] == sweep_id, stop.text
            _stopped(op, sweep_id)
        finally:
            for sock in streams:
                sock.close()


@pytest.mark.slow
def test_the_cli_sends_the_stop_to_the_listener_and_falls_back_to_the_server(stop_service):
    url = _stop_url(stop_service)
    run = [SHAKEID, "rig", "estop", "--server", stop_service.url, "--token", OPERATOR]
    with stop_service.client() as op:
        sweep_id, _ = _running_sweep(op)
        sent = subprocess.run([*run, "--stop-url", url], capture_output=True, text=True, timeout=120)
        assert sent.returncode == 0 and f"sent to {url}" in sent.stdout, sent.stdout + sent.stderr
        _stopped(op, sweep_id)
        sweep_id, _ = _running_sweep(op)
        closed = f"http://127.0.0.1:{free_port()}"  # nothing listens there: the server's own route
        fell = subprocess.run([*run, "--stop-url", closed], capture_output=True, text=True, timeout=120)
        assert fell.returncode == 0 and f"sent to {stop_service.url}{ESTOP_PATH}" in fell.stdout, fell.stdout + fell.stderr
        _stopped(op, sweep_id)


def test_the_stop_port_is_the_web_port_plus_the_offset_unless_set():
    s = Settings.load(env={})
    s.resolve_stop("0.0.0.0", 8123)
    assert (s.stop_host, s.stop_port) == ("0.0.0.0", 8123 + STOP_PORT_OFFSET)
    s = Settings.load(env={"SHAKEID_STOP_PORT": "0"})
    s.resolve_stop("127.0.0.1", 8123)
    assert s.stop_port == 0  # none
    with pytest.raises(SettingsError, match="stop_port"):
        Settings.load(env={"SHAKEID_STOP_PORT": "70000"})
    assert stop_url("http://rig-pc:8000") == f"http://rig-pc:{8000 + STOP_PORT_OFFSET}{ESTOP_PATH}"
    assert stop_url("http://rig-pc:8000", "http://other:9") == f"http://other:9{ESTOP_PATH}"


def test_a_web_server_attaching_while_the_controller_starts_is_told_the_stop_port(tmp_path, monkeypatch):
    """The rig controller opens its stop listener before it writes its key: a web server that attaches
    as soon as it can (RigLink polls for the key) is told the listener's port in the first hello. The stop
    listener is slowed here to open that window wide; with the key written first, the web server attached
    while the listener was still opening, held a session without its port, and /api/health never named
    stop_url (seen: this module's tests failing under load, the controller's log saying the listener was up).
    An in-process controller on its simulated rig, a real socket, the web server's own handshake."""
    import threading
    import time

    import server.controller as controller_module
    from server.ipc import connect, read_key

    settings = Settings.load(data_dir=tmp_path / "data", env={})
    settings.stop_host, settings.stop_port = "127.0.0.1", free_port()
    real_open = controller_module.open_listener

    def slow_open(*args, **kwargs):
        time.sleep(1.0)  # a loaded machine: the listener's thread and socket take their time
        return real_open(*args, **kwargs)

    monkeypatch.setattr(controller_module, "open_listener", slow_open)
    ctl = controller_module.RigController(settings)
    hellos = []

    def attach():  # what server.rigclient.RigLink._keep_session does, from the first moment a key exists
        line = connect(ctl.address, read_key(controller_module.key_path(settings.data_dir), wait_s=30), "session")
        hellos.append(line.hello)
        line.close()

    web = threading.Thread(target=attach)
    web.start()
    ctl.start()
    try:
        web.join(30)
        assert hellos and hellos[0]["stop_port"] == settings.stop_port, hellos
        assert ctl.stop_listener is not None and ctl.stop_listener.port == settings.stop_port
    finally:
        ctl.stop("the test is over")
        ctl.run()
