"""The options of the commands that drive the rig, its simulation or its recordings: sweep, recordings,
rig, sim, serve, controller, demo (their code: lab.py, rigcmd.py). Every option says its unit and its
default (shakeid/helpformat.py appends the default from the parser itself)."""
from __future__ import annotations

import argparse

from .argtypes import int_in, non_negative, positive
from .lab import cmd_controller, cmd_demo, cmd_recordings, cmd_serve, cmd_sim, cmd_sweep
from .rigcmd import RIG_ACTIONS, cmd_rig

SERVER_HELP = "through the HTTP service at this URL, e.g. http://127.0.0.1:8000"
TOKEN_HELP = "with --server: an operator token (default: $SHAKEID_TOKEN)"


def add_sweep_shape(q, required: bool) -> None:
    """The sweep's frequencies, duration and amplitude: required for a real rig (no silent default
    drives a table), defaulted for the demo."""
    d = (lambda v: {"required": True}) if required else (lambda v: {"default": v})
    need = " (required)" if required else ""
    q.add_argument("--f-start-hz", type=positive, metavar="HZ", help="frequency the sweep starts at, Hz" + need, **d(1.0))
    q.add_argument("--f-end-hz", type=positive, metavar="HZ", help="frequency the sweep ends at, Hz" + need, **d(20.0))
    q.add_argument("--duration-s", type=positive, metavar="S", help="length of the sweep, s" + need, **d(60.0))
    q.add_argument("--amplitude-mm", type=positive, metavar="MM", help="table displacement amplitude (peak), mm" + need,
                   **d(1.3))


def add_lab_parsers(sub) -> None:
    """The lab's commands: sweep, recordings, rig, sim, serve, controller, demo (one function each below)."""
    for add in (_add_sweep, _add_recordings, _add_rig, _add_sim, _add_serve, _add_controller, _add_demo):
        add(sub)


def _add_sweep(sub) -> None:
    q = sub.add_parser("sweep", help="run a sweep on the rig of --config and record it to HDF5, or through a "
                                     "running shakeid serve (--server)")
    where = q.add_mutually_exclusive_group(required=True)
    where.add_argument("--config", metavar="RIG.toml", help="drive the rig of this configuration directly")
    where.add_argument("--server", metavar="URL", help=SERVER_HELP)
    q.add_argument("--token", help=TOKEN_HELP)
    q.add_argument("--wait-model", action="store_true", help="with --server: wait for the model and print it")
    add_sweep_shape(q, required=True)
    q.add_argument("--settle-s", type=non_negative, metavar="S", default=2.0,
                   help="time recorded after the sweep ends (the free decay), s")
    q.add_argument("--operator", default="", help="who runs the sweep, kept in the recording")
    q.add_argument("--note", default="", help="free text kept in the recording")
    q.add_argument("--out", metavar="FILE.h5", help="the recording (needed with --config; with --server: a copy, "
                                                    "downloaded; default: none)")
    q.set_defaults(func=cmd_sweep)


def _add_recordings(sub) -> None:
    q = sub.add_parser("recordings", help="inspect HDF5 recordings (metadata, status, gaps, quality flags), or list "
                                          "a service's recordings (--server)")
    q.add_argument("files", nargs="*", metavar="FILE.h5", help="recordings written by a sweep or the service")
    q.add_argument("--server", metavar="URL", help="list the recordings of a running `shakeid serve` instead "
                                                   "(newest first; a viewer's token: --token or SHAKEID_TOKEN)")
    q.add_argument("--token", help="with --server: a bearer token (default: $SHAKEID_TOKEN)")
    q.add_argument("--limit", type=int_in(1, 500), default=50, metavar="N", help="with --server: how many (default 50)")
    q.add_argument("--recover", action="store_true", help="mark recordings left running by a crash as aborted")
    q.add_argument("--process", action="store_true",
                   help="add processed signals: relative acceleration, velocity, displacement (/entry/processed)")
    q.add_argument("--json", action="store_true", help="one JSON object per file instead of text")
    q.set_defaults(func=cmd_recordings)


def _add_rig(sub) -> None:
    q = sub.add_parser("rig", help="the rig's PLC: status, reset, estop; through a running service (--server) or "
                                   "directly (--config: works while the service is wedged)")
    actions = q.add_subparsers(dest="action", required=True, metavar="ACTION")
    for action, about in RIG_ACTIONS.items():
        a = actions.add_parser(action, help=about, description=about)
        where = a.add_mutually_exclusive_group(required=True)
        where.add_argument("--server", metavar="URL", help="a running `shakeid serve` (its embedded rig too); "
                                                           + ("a viewer's token" if action == "status" else
                                                              "an operator's token") + ": --token or SHAKEID_TOKEN")
        where.add_argument("--config", metavar="RIG.toml", help="the PLC of this rig configuration ([plc]), directly")
        a.add_argument("--token", help="with --server: a bearer token (default: $SHAKEID_TOKEN)")
        if action == "estop":
            a.add_argument("--stop-url", metavar="URL", help="with --server: the rig controller's stop listener "
                           "(/api/health's stop_url; default: the --server URL's port + 1); the --server URL's own "
                           "route is used when nothing answers there")
        a.add_argument("--json", action="store_true", help="one JSON object instead of text")
        a.set_defaults(func=cmd_rig)


def _add_sim(sub) -> None:
    q = sub.add_parser("sim", help="run the simulated rig: PLC over Modbus TCP, accelerometer stream over TCP")
    q.add_argument("--config", metavar="RIG.toml", help="rig configuration, e.g. examples/sim-rig.toml "
                                                        "(default: the built-in simulated rig)")
    q.add_argument("--host", help="listen address (default: the config's, else 127.0.0.1)")
    q.add_argument("--modbus-port", type=int_in(1, 65535), metavar="PORT", help="TCP port of the PLC's Modbus server "
                                                                   "(default: the config's [plc] port, else 5020)")
    q.add_argument("--stream-port", type=int_in(1, 65535), metavar="PORT", help="TCP port of the accelerometer stream "
                                                                   "(default: the config's [stream] url port, else 5021)")
    q.add_argument("--speed", type=positive, metavar="X", help="rig seconds per wall-clock second, for the PLC and the "
                                                            "streams (default: the config's [sim] speed, else 1)")
    q.set_defaults(func=cmd_sim)


def _add_serve(sub) -> None:
    q = sub.add_parser("serve", help="the HTTP service: sweeps, recordings, models (FastAPI + uvicorn)")
    q.add_argument("--config", metavar="RIG.toml", help="rig + [server] configuration (default: none, an "
                                                        "embedded simulated rig)")
    q.add_argument("--host", default="127.0.0.1", help="listen address")
    q.add_argument("--port", type=int_in(1, 65535), default=8000, help="TCP port")
    q.add_argument("--data-dir", metavar="DIR", help="recordings, models, catalog, token (default: "
                                                     "$SHAKEID_DATA_DIR, else [server] data_dir, else ./shakeid-data)")
    q.add_argument("--sim-speed", type=positive, metavar="X",
                   help="embedded simulated rig: rig seconds per wall-clock second (default: $SHAKEID_SIM_SPEED, "
                        "else [server] sim_speed, else 1)")
    q.add_argument("--log-level", default="warning", choices=("debug", "info", "warning", "error"),
                   help="uvicorn's log level")
    q.add_argument("--controller", metavar="ADDRESS",
                   help="attach to a rig controller that runs on its own (`shakeid controller`), e.g. "
                        "unix:/run/shakeid/controller.sock or tcp:127.0.0.1:8765 (default: start one as a child)")
    q.set_defaults(func=cmd_serve)


def _add_controller(sub) -> None:
    q = sub.add_parser("controller", help="the rig controller process: sweeps, heartbeat, emergency stop (the "
                                          "service starts one itself; run it alone for a separate deployment)")
    q.add_argument("--config", metavar="RIG.toml", help="rig configuration (default: none, an embedded simulated rig)")
    q.add_argument("--data-dir", metavar="DIR", help="shared with the web server: catalog, recordings (default: as "
                                                     "serve's)")
    q.add_argument("--address", help="where to listen, unix:PATH or tcp:HOST:PORT (default: "
                                     "unix:DATA_DIR/controller.sock)")
    q.add_argument("--sim-speed", type=positive, metavar="X", help="embedded simulated rig: rig seconds per "
                                                                "wall-clock second (default: as serve's)")
    q.add_argument("--parent-pid", type=int, help=argparse.SUPPRESS)  # set by `shakeid serve` for its child
    q.set_defaults(func=cmd_controller)


def _add_demo(sub) -> None:
    q = sub.add_parser("demo", help="sweep the simulated rig (10x real time) over Modbus, record HDF5, identify, "
                                    "report")
    q.add_argument("--out", default="demo-output", metavar="DIR",
                   help="folder for recording.h5 and report/ (an earlier demo's files there are replaced)")
    add_sweep_shape(q, required=False)
    q.set_defaults(func=cmd_demo)
