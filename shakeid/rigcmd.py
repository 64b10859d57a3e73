"""`shakeid rig status|reset|estop --server URL | --config RIG.toml`: the rig's PLC through a running
service (its embedded simulated rig included: the only way to it), or the PLC of a rig configuration directly.

With --server, `estop` goes first to the rig controller's stop listener (server/stoplistener.py: the
--server URL's host on its port + STOP_PORT_OFFSET, or --stop-url), where no viewer traffic is queued, and
to the web server's own route only when nothing answers there.
With --config: no HTTP service and no rig controller in between (daq.plc.open_plc: Modbus TCP or ADS), so an
operator can read and stop the rig while the service is wedged. Exit 0 when the command took effect,
2 (one line `shakeid: error: ...`) when the PLC does not answer or did not do what it was told.
"""
from __future__ import annotations

import json
import time

from identify.errors import ShakeidError

#: how long a command may take to show in the state read back (s, wall clock); the PLC cycle is 10 ms
#: and a table stopping from full speed ramps down in 0.2 s of rig time
SETTLE_S = 5.0
POLL_S = 0.05
#: the actions, each with its own help (`shakeid rig ACTION --help`)
RIG_ACTIONS = {
    "status": "read the PLC: state, fault, table position, frequency",
    "reset": "clear a fault or an emergency stop once the table is at rest (refused while a sweep runs)",
    "estop": "emergency stop: the table ramps to rest at once; a running sweep ends aborted",
}


def _describe(st) -> dict:
    from protocol.plc import Fault, State

    def name(enum, code):
        try:
            return enum(code).name.lower()
        except ValueError:
            return f"unknown ({code})"

    return {"state": name(State, st.state), "fault_code": int(st.fault_code), "fault": name(Fault, st.fault_code),
            "position_mm": round(float(st.position_mm), 4), "frequency_hz": round(float(st.frequency_hz), 4),
            "elapsed_s": round(float(st.elapsed_s), 3)}


def _line(where: str, d: dict) -> str:
    return (f"{where}: state {d['state']}, fault {d['fault_code']} ({d['fault']}), position {d['position_mm']:+.3f} mm, "
            f"frequency {d['frequency_hz']:.2f} Hz")


def _wait(plc, done, timeout_s: float = SETTLE_S):
    """Poll the PLC until done(status) or the timeout; returns the last status read."""
    end = time.monotonic() + timeout_s
    st = plc.status()
    while not done(st) and time.monotonic() < end:
        time.sleep(POLL_S)
        st = plc.status()
    return st


def _at_rest(plc, timeout_s: float = SETTLE_S):
    """Wait until the table position reads the same twice, 0.1 s apart; returns (at rest, last status)."""
    end = time.monotonic() + timeout_s
    st = plc.status()
    while True:
        time.sleep(0.1)
        nxt = plc.status()
        if nxt.position_mm == st.position_mm:
            return True, nxt
        st = nxt
        if time.monotonic() > end:
            return False, st


def cmd_rig(args) -> int:
    if args.server:
        return _through_service(args)
    return _direct(args)


def _through_service(args) -> int:
    """The action through `shakeid serve` (GET /api/rig, POST /api/rig/reset, POST /api/rig/estop)."""
    from .remote import ServiceClient

    client = ServiceClient.for_args(args)
    message = ""
    if args.action == "estop":
        out, via = _estop(client, args.stop_url)
        message = "emergency stop: the PLC is in estop" + (f"; sweep {out['aborted_sweep']} aborted"
                                                           if out.get("aborted_sweep") else "") + f" (sent to {via})"
    elif args.action == "reset":
        message = f"reset: the PLC is {client.request('POST', '/api/rig/reset')['state']}"
    plc = client.request("GET", "/api/rig").get("plc", {})
    where = f"PLC of the service at {args.server}"
    if args.json:
        print(json.dumps({"plc": where, **plc, "action": args.action, "message": message}))
        return 0
    print(f"{where}: state {plc.get('state')}" + (f", fault {plc['fault']}" if plc.get("fault") else "")
          + (f", position {plc['position_mm']:+.3f} mm" if isinstance(plc.get("position_mm"), (int, float)) else "")
          + (f", frequency {plc['frequency_hz']:.2f} Hz" if isinstance(plc.get("frequency_hz"), (int, float)) else ""))
    if message:
        print(message)
    return 0


def stop_url(server: str, given: str | None = None) -> str:
    """Where the stop listener is: --stop-url (its path added if it has none), else the --server URL's host
    on the port STOP_PORT_OFFSET above the server's."""
    from urllib.parse import urlsplit

    from server.settings import STOP_PORT_OFFSET
    from server.stoplistener import ESTOP_PATH

    if given:
        return given if urlsplit(given).path not in ("", "/") else given.rstrip("/") + ESTOP_PATH
    url = urlsplit(server)
    port = url.port or (443 if url.scheme == "https" else 80)
    host = f"[{url.hostname}]" if ":" in (url.hostname or "") else url.hostname
    return f"http://{host}:{port + STOP_PORT_OFFSET}{ESTOP_PATH}"


def _estop(client, given: str | None) -> tuple[dict, str]:
    """POST the stop to the stop listener; to the web server's route only if nothing answers there (or
    not a stop listener: 404/405). (answer, where it was sent)."""
    from server.stoplistener import CLIENT_TIMEOUT_S, ESTOP_PATH

    from .remote import ServiceClient, ServiceError

    url = stop_url(client.url, given)
    origin, _, path = url.partition("://")[2].partition("/")
    listener = ServiceClient(url.split("://")[0] + "://" + origin, client.token, timeout_s=CLIENT_TIMEOUT_S)
    try:
        return listener.request("POST", "/" + path), url
    except ServiceError as exc:
        if exc.status not in (0, 404, 405):  # it answered: 401/403 (the token), 503 (not delivered)
            raise
    return client.request("POST", ESTOP_PATH), client.url + ESTOP_PATH


def _direct(args) -> int:
    from daq.plc import open_plc
    from daq.devices import DeviceError
    from sim.config import load_config
    from protocol.plc import Command, State

    cfg = load_config(args.config)
    p = cfg.plc
    where = (f"PLC {p.get('host', '127.0.0.1')}:{p.get('port', 502)} (Modbus TCP)" if p.get("transport", "modbus") == "modbus"
             else f"PLC {p.get('ams_net_id', '')} at {p.get('host', '127.0.0.1')} (ADS)")
    try:
        plc = open_plc(p)
    except DeviceError as exc:
        raise ShakeidError(f"{args.config}: {exc}") from None
    try:
        before = plc.status()
        message = ""
        if args.action == "estop":
            plc.command(Command.ESTOP)
            st = _wait(plc, lambda s: s.state == State.ESTOP)
            if st.state != State.ESTOP:
                raise ShakeidError(f"{args.config}: emergency stop did not take effect: {_line(where, _describe(st))}")
            rest, st = _at_rest(plc)
            if not rest:
                raise ShakeidError(f"{args.config}: the PLC is in estop but the table still moves: "
                                   f"{_line(where, _describe(st))}")
            message = "emergency stop: the PLC is in estop, the table at rest"
        elif args.action == "reset":
            if before.state == State.RUNNING:
                raise ShakeidError(f"{args.config}: a sweep is running: not reset (stop it with `shakeid rig estop`)")
            if before.state == State.IDLE:
                st, message = before, "nothing to reset: the PLC is idle"
            else:
                rest, _ = _at_rest(plc)  # the PLC resets only a table at rest
                plc.command(Command.RESET)
                st = _wait(plc, lambda s: s.state == State.IDLE, 1.0)
                if st.state != State.IDLE:
                    d = _describe(st)
                    raise ShakeidError(f"{args.config}: reset did not take effect: the PLC stayed in {d['state']} "
                                       f"(fault {d['fault_code']} {d['fault']}"
                                       f"{'' if rest else '; the table did not come to rest'})")
                message = f"reset: {_describe(before)['state']} -> idle"
        else:
            st = before
        d = _describe(st)
    except DeviceError as exc:
        raise ShakeidError(f"{args.config}: {exc}") from None
    finally:
        plc.close()
    if args.json:
        print(json.dumps({"plc": where, **d, "action": args.action, "message": message}))
    else:
        print(_line(where, d))
        if message:
            print(message)
    return 0
