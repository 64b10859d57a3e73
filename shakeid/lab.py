"""Commands that run the rig or its recordings: demo, sweep, sim, recordings (used by shakeid.cli)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from identify.errors import ShakeidError


def cmd_demo(args) -> int:
    """The main job on the simulated rig: sweep over Modbus with the serial stream -> HDF5 ->
    identification -> report."""
    from daq.plc import ModbusPLC
    from daq.sources import SerialSource
    from daq.recorder import read_h5_recording
    from daq.sweep import SweepRequest, SweepRunner
    from identify.frf.side_by_side import identification_document
    from identify.identifier import SparseIdentifier
    from protocol.plc import Limits
    from sim.plc import PLCConfig
    from sim.server import SENSITIVITY, SimulatedRig

    from reports.identification import write_report
    from reports.text import summary

    from .progress import Progress

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    h5 = out / "recording.h5"
    if h5.exists():
        if _operator(h5) != "demo":  # an operator's recording in the folder given: never replaced
            raise ShakeidError(f"{h5} exists and is not an earlier demo's recording; it is never overwritten: "
                               "give the demo another --out folder")
        h5.unlink()  # the demo's own file from an earlier run
    speed = 10.0
    # at 10x the client's 50 ms heartbeat is 0.5 s of rig time: the demo rig's watchdog allows 2 s
    rig = SimulatedRig(PLCConfig(limits=Limits(watchdog_s=2.0)), speed=speed).start()
    host, port = rig.endpoints["modbus"]
    print(f"simulated rig at {speed:g}x: PLC Modbus TCP {host}:{port}, accelerometers {rig.endpoints['stream']}")
    print(f"sweep {args.f_start_hz:g}-{args.f_end_hz:g} Hz over {args.duration_s:g} s at {args.amplitude_mm:g} mm "
          f"(the paper's Table 1 rig) -> {h5}", flush=True)
    try:
        plc, source = ModbusPLC(host, port), SerialSource(rig.endpoints["stream"], rig.plc.config.fs_hz)
        progress = Progress("sweep", args.duration_s)
        runner = SweepRunner(plc, source, Limits(), SENSITIVITY, on_progress=progress.sweep_status,
                             rig_config={"source": "shakeid demo", "simulated": True,
                                         "moving_mass_kg": rig.plc.config.rig.mass_kg})
        result = runner.run(SweepRequest(args.f_start_hz, args.f_end_hz, args.duration_s, args.amplitude_mm,
                                         operator="demo"), h5)
        progress.close()
        plc.close()
        source.close()
    finally:
        truth = rig.plc.model.to_dict()["model"]
        rig.stop()
    print(f"recorded: {result['status']}, {result['samples']} samples, {result['gaps']} gap(s)")
    if result["status"] != "complete":
        raise ShakeidError(f"demo sweep ended {result['status']}: {result['reason']}")
    print(f"identifying {h5} ...", flush=True)
    rec = read_h5_recording(h5)
    ident = SparseIdentifier().fit(rec)
    result = identification_document(ident, [rec])  # as `shakeid identify` delivers it: with the jumps
    write_report(ident, out / "report", result)
    print(summary(result, str(h5)))
    print("\n".join(truth_lines(result["model"], truth, result["physical"]["design"]["cubic_stiffness_per_kg"])))
    print(f"report: {out / 'report' / 'index.html'}")
    print("next: `.venv/bin/shakeid serve` runs the same chain behind HTTP, with a dashboard (docs/service.md)")
    return 0


def truth_lines(identified: dict, truth: dict, design_k3_per_kg: float) -> list[str]:
    """The identified model beside the simulated rig's true one, term by term, in one number format, with
    the relative error: what the demo shows (a term the fit missed or added is named as such). The rig's
    true k3 is its own (-the true q2^3 coefficient, N/m^3/kg), not the design value (`design_k3_per_kg`)
    the summary quotes for a real rig."""
    lines = ["identified beside the simulated rig's true model (the paper's Table 1):",
             f"  {'equation':8s} {'term':9s} {'identified':>12s} {'true':>12s} {'error':>8s}"]
    for eq in truth:
        got, true = identified.get(eq, {}), truth[eq]
        for term in list(true) + [t for t in got if t not in true]:
            g, t = got.get(term), true.get(term)
            rel = round(100 * (g - t) / abs(t), 2) if g is not None and t else None
            err = f"{rel + 0.0:+.2f} %" if rel is not None else "missed" if g is None else "extra"  # + 0.0: no -0.00
            lines.append(f"  {eq:8s} {term:9s} {'-' if g is None else f'{g:.5g}':>12s} "
                         f"{'-' if t is None else f'{t:.5g}':>12s} {err:>8s}")
    true_k3 = -truth.get("q1_dot", {}).get("q2^3", 0.0)
    lines.append(f"  (the simulated rig has the paper's identified values: its k3 / m = {true_k3 / 1e6:.3g} MN/m³/kg "
                 f"against the design's {design_k3_per_kg / 1e6:.3g}, as on the paper's rig; hence the design k3 "
                 "quoted above differs)")
    return lines


def sweep_devices(cfg):
    """PLC and accelerometer backends from a rig configuration."""
    from daq.plc import open_plc
    from daq.sources import open_source

    plc = open_plc(cfg.plc)
    try:
        return plc, open_source(cfg.stream, cfg.can, cfg.fs_hz, cfg.accelerometers)
    except Exception:
        plc.close()
        raise


def cmd_sweep(args) -> int:
    """Run one sweep on the rig of --config and record it (or, with --server, through the service)."""
    if args.server:
        from .remote import cmd_sweep_remote

        return cmd_sweep_remote(args)
    if not args.out:
        raise ShakeidError("--out FILE.h5 is needed with --config (the service keeps its own files)")
    from daq.sweep import SweepRequest, SweepRunner
    from sim.config import load_config

    from daq.recorder import recover_directory

    cfg = load_config(args.config)
    for path in recover_directory(Path(args.out).resolve().parent):  # crashed recordings, found on start
        print(f"{path}: was left running by a crash; marked aborted, its data kept")
    req = SweepRequest(args.f_start_hz, args.f_end_hz, args.duration_s, args.amplitude_mm, args.settle_s,
                       args.operator, args.note)
    from daq.plc import open_plc
    from daq.realtime import CONTROLLER_PRIORITY, make_realtime

    from .progress import Progress

    make_realtime(CONTROLLER_PRIORITY, round_robin=True)  # where allowed: the heartbeat is never late
    plc, source = sweep_devices(cfg)
    beat_plc = open_plc(cfg.plc)  # the heartbeat's own link: never behind a status poll
    progress = Progress("sweep", args.duration_s)
    from daq.preflight import nominal_response

    runner = SweepRunner(plc, source, cfg.limits, float(cfg.stream["sensitivity_counts_per_ms2"]), cfg.channels,
                         on_progress=progress.sweep_status, rig_config=cfg.recording_metadata(),
                         heartbeat_plc=beat_plc, response=nominal_response(cfg))  # refuses a sweep that would clip
    try:
        result = runner.run(req, args.out)
    finally:
        progress.close()
        for dev in (plc, beat_plc, source):
            dev.close()
    for warning in (result.get("preflight") or {}).get("warnings", []):
        print(f"preflight warning: {warning}")
    print(f"{result['path']}: {result['status']}{' (' + result['reason'] + ')' if result['reason'] else ''}, "
          f"{result['samples']} samples, {result['gaps']} gap(s)")
    return 0 if result["status"] == "complete" else 1


def cmd_sim(args) -> int:
    """Run the simulated rig until Ctrl-C or SIGTERM."""
    import signal
    import threading

    from sim.server import SimulatedRig

    from sim.config import RigConfig, load_config

    done = threading.Event()
    # before anything is printed: a supervisor may send SIGTERM as soon as it sees the endpoints
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    cfg = load_config(args.config) if args.config else RigConfig()
    speed = args.speed if args.speed is not None else cfg.speed
    if speed <= 0:
        raise ShakeidError("--speed must be positive")
    host = args.host or cfg.plc.get("host", "127.0.0.1")
    modbus_port = args.modbus_port or int(cfg.plc.get("port", 5020))
    url = cfg.stream["url"]
    if url.startswith("socket://"):  # serve the stream where the configuration says it is
        stream_host, config_port = url[len("socket://"):].rsplit(":", 1)[0], int(url.rsplit(":", 1)[-1])
    else:
        stream_host, config_port = host, 5021
    stream_host = args.host or stream_host  # --host (e.g. 0.0.0.0 in a container) binds both servers
    stream_port = args.stream_port or config_port
    ads = cfg.plc.get("host", "127.0.0.5") if cfg.plc.get("transport") == "ads" else None
    rig = SimulatedRig(cfg.plc_config(), host=host, modbus_port=modbus_port, stream_port=stream_port, speed=speed,
                       sensitivity=float(cfg.stream["sensitivity_counts_per_ms2"]), ads_address=ads,
                       can_interface=cfg.can.get("interface"), can_channel=cfg.can.get("channel"),
                       can_node=int(cfg.can.get("node", 0)), stream_host=stream_host)
    args.speed = speed
    try:
        rig.start()
    except RuntimeError as exc:
        raise ShakeidError(str(exc)) from None
    ep = rig.endpoints
    print(f"simulated rig (speed {args.speed:g}x): PLC Modbus TCP {ep['modbus'][0]}:{ep['modbus'][1]} device 1; "
          f"accelerometers {ep['stream']} ({ep['fs_hz']:g} Hz, channels {', '.join(ep['channels'])}, "
          f"{ep['sensitivity_counts_per_ms2']:.2f} counts per m/s^2)"
          + (f"; PLC ADS {ep['ads'][2]} net id {ep['ads'][0]} port {ep['ads'][1]}" if ep["ads"] else "")
          + (f"; CAN {rig.can_interface} {rig.can_channel}" if rig.can_interface else "")
          + f"; sensor-noise seed {rig.plc.seed} (sim.plc.PLCConfig.seed reproduces it). Ctrl-C stops.", flush=True)
    try:
        while not done.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    rig.stop()
    print("simulated rig stopped")
    return 0


def _recordings_of_service(args) -> int:
    """`shakeid recordings --server URL`: the service's recordings, newest first (GET /api/recordings)."""
    import time

    from .remote import ServiceClient

    if args.files or args.recover or args.process:
        raise ShakeidError("--server lists the service's recordings; FILE.h5, --recover and --process are for local files")
    recs = ServiceClient.for_args(args, "a viewer's is enough").request("GET", f"/api/recordings?limit={args.limit}")
    for rec in recs:
        if args.json:
            print(json.dumps({k: v for k, v in rec.items() if k != "path"}))
            continue
        info = rec.get("info") or {}
        created = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(rec["created"]))
        print(f"{rec['id']}  {created}  {rec['origin']:6s}  {rec['status']:8s}  {rec['filename']}"
              + (f"  ({info['samples']} samples at {info['fs_hz']:g} Hz)" if info.get("samples") and info.get("fs_hz")
                 else ""))
    if not args.json:
        print(f"{len(recs)} recording(s) on {args.server}" + (f" (the newest {args.limit}: --limit for more)"
                                                                if len(recs) == args.limit else ""))
    return 0


def cmd_recordings(args) -> int:
    """Metadata, status, gaps and quality flags of HDF5 recordings; --recover marks crashed ones as aborted."""
    from daq.recorder import describe, recover

    if args.server:
        return _recordings_of_service(args)
    if not args.files:
        raise ShakeidError("give recordings (FILE.h5 ...) or --server URL to list a service's")
    said = sys.stderr if args.json else sys.stdout  # with --json, stdout is one JSON object per file, nothing else
    for path in args.files:
        if args.recover:
            print(f"{path}: was left running by a crash; marked aborted" if recover(path) else
                  f"{path}: not left running by a crash; nothing to recover", file=said)
        if args.process:
            from daq.processing import add_processed

            p = add_processed(path)
            print(f"{path}: processed signals added (/entry/processed: relative acceleration, velocity, "
                  f"displacement; band {p['band_hz'][0]:.3g}-{p['band_hz'][1]:.3g} Hz, {p['segments']} segment(s), "
                  f"{100 * p['valid_fraction']:.1f} % of rows valid)", file=said)
        info = describe(path)
        reasons = identification_reasons(info)
        if args.json:  # with `shakeid identify`'s verdict: its refusals and the signals' quality together
            print(json.dumps({**info, "identification": {"usable": not reasons, "reasons": reasons}}, default=str))
            continue
        dur = info["samples"] / info["fs_hz"] if info.get("fs_hz") else 0
        print(f"{path}: {info['status']}{' (' + info['status_reason'] + ')' if info['status_reason'] else ''}; "
              f"{info['samples']} samples ({dur:.1f} s at {info['fs_hz']:g} Hz), channels {', '.join(info['channels'])}, "
              f"{len(info['gaps'])} gap(s)")
        print(f"  started {when(info.get('start_time'))}"
              + (f" by {info['operator']}" if info.get("operator") else " (no operator recorded)")
              + f"; {sweep_text(info.get('sweep'))}")
        if "link_frames" in info:
            print(f"  sensor link: {info['link_frames']} frames, {info.get('link_frames_lost', 0)} lost, "
                  f"{info.get('link_frames_corrupt', 0)} corrupt, {info.get('link_saturated_frames', 0)} saturated")
        for first, count in info["gaps"][:10]:
            print(f"  gap: {count} samples missing from sample {first} (t = {first / info['fs_hz']:.3f} s)")
        if len(info["gaps"]) > 10:
            print(f"  ... {len(info['gaps']) - 10} more gap(s) (--json lists all)")
        if info.get("processed"):
            print(f"  processed: {', '.join(info['processed'])}")
        for line in quality_lines(info["quality"], reasons):
            print("  " + line)
    return 0


def identification_reasons(info: dict) -> list[str]:
    """Why `shakeid identify` would refuse a recording, from daq.recorder.describe(): its status
    (identify.data.quality.status_problem), a missing channel of the pair it reads by default, and the
    recorder's quality verdict; empty when it would identify it."""
    from daq.recorder import DEFAULT_CHANNELS
    from identify.data.quality import status_problem

    status = status_problem(info.get("status") or "unknown", info.get("status_reason"))
    missing = [c for c in DEFAULT_CHANNELS if c not in info.get("channels", [])]
    q = info.get("quality") or {}
    reasons = (([status] if status else []) + ([f"missing channel(s) {missing}"] if missing else [])
               + ([] if q.get("usable_for_identification", True) else list(q.get("reasons") or [])))
    return list(dict.fromkeys(reasons))  # the quality verdict carries the status too (describe): said once


def when(iso) -> str:
    """A recording's ISO 8601 time as a person reads it: '2026-11-23 10:57:34 UTC' (its own zone kept)."""
    from datetime import datetime

    if not iso:
        return "at an unknown time"
    try:
        t = datetime.fromisoformat(str(iso))
    except ValueError:
        return str(iso)
    zone = "UTC" if t.utcoffset() is not None and not t.utcoffset() else t.strftime("%z")
    return t.strftime("%Y-%m-%d %H:%M:%S") + (f" {zone}" if zone else "")


def sweep_text(sweep) -> str:
    """The sweep a recording was made with (its /entry/sweep attributes), in words and units."""
    if not sweep or "f_start_hz" not in sweep:
        return "no sweep recorded (not made by a sweep)"
    text = (f"sweep {float(sweep['f_start_hz']):g}-{float(sweep['f_end_hz']):g} Hz over "
            f"{float(sweep['duration_s']):g} s at {float(sweep['amplitude_mm']):g} mm")
    if sweep.get("settle_s") is not None:
        text += f", {float(sweep['settle_s']):g} s settle"
    return text + (f"; note: {sweep['note']}" if sweep.get("note") else "")


def quality_lines(q: dict, reasons: list[str], max_flags: int = 10) -> list[str]:
    """The quality flags of a recording (daq.recorder.describe()["quality"]) and `shakeid identify`'s
    verdict on it (`reasons`: identification_reasons()), readably."""
    if not q.get("assessed"):
        return [f"quality: {q.get('note', 'not assessed')}"] + (
            ["NOT usable for identification: " + "; ".join(reasons)] if reasons else [])
    when = "" if q.get("final") else " (as of the last flush: the file was not closed)"
    ratio = q.get("mass_table_rms_ratio")
    head = (f"quality{when}: " + ("NOT usable for identification: " + "; ".join(reasons) if reasons
                                  else "usable for identification")
            + (f"; mass/table RMS ratio {ratio:.3g}" if ratio is not None else "")
            + (f"; {q['link_saturated_frames']} saturated frame(s) on the link" if q.get("link_saturated_frames") else ""))
    lines = [head]
    for f in q["flags"][:max_flags]:
        kind, v = f["kind"], f["value"]
        what = (f"clipped ({f['samples']} samples at full scale)" if kind == "clipped" else "dead (exactly 0)"
                if kind == "dead" else f"non-finite ({f['samples']} samples)" if kind == "nonfinite" else
                f"implausible ratio {v:.3g}" if kind == "ratio" and v is not None else f"stuck at {v:.6g}"
                if kind == "stuck" and v is not None else kind)
        lines.append(f"flag: {f['channel']} {what}, rows {f['first']}-{f['first'] + f['count']} "
                     f"(t = {f['t_start_s']:.3f}-{f['t_end_s']:.3f} s)")
    if q["flags_total"] > max_flags:
        lines.append(f"... {q['flags_total'] - max_flags} more flag(s) (--json lists them)")
    return lines


def _check_port_free(host: str, port: int) -> None:
    """ShakeidError naming the port when something already listens there (bound as uvicorn binds it)."""
    import socket

    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            raise ShakeidError(f"cannot serve on {host}:{port}: {exc.strerror.lower()} (another shakeid serve?); "
                               "stop it or give another --port") from None


def cmd_serve(args) -> int:
    """The HTTP service (FastAPI under uvicorn); an embedded simulated rig when there is no --config."""
    import uvicorn

    from server.app import create_app
    from server.settings import Settings

    settings = Settings.load(args.config, data_dir=args.data_dir)
    if args.sim_speed is not None:
        settings.sim_speed = args.sim_speed
    if args.controller:
        settings.controller = args.controller
    settings.resolve_stop(args.host, args.port)  # the child controller's stop listener: --port + 1 by default
    _check_port_free(args.host, args.port)  # said before the banner and the token, not after them
    app = create_app(settings)  # prepares the data directory (and the generated token, if any)
    rig = f"rig of {args.config}" if args.config else f"embedded simulated rig at {settings.sim_speed:g}x"
    rig += f", rig controller at {settings.controller}" if settings.controller else ", rig controller as a child process"
    print(f"shakeid serve: http://{args.host}:{args.port}/ ({rig}); data in {settings.data_dir.resolve()}", flush=True)
    if settings.generated_token:
        print(f"shakeid serve: no tokens configured; operator token: {settings.generated_token} "
              f"(kept in {settings.data_dir / 'operator-token'}); dashboard: "
              f"http://{args.host}:{args.port}/#token={settings.generated_token}", flush=True)
    class Server(uvicorn.Server):
        def handle_exit(self, sig, frame):
            app.state.shutting_down.set()  # live streams (SSE) end now instead of holding the shutdown up
            super().handle_exit(sig, frame)

    config = uvicorn.Config(app, host=args.host, port=args.port, log_level=args.log_level, timeout_graceful_shutdown=5)
    Server(config).run()
    return 0


def cmd_controller(args) -> int:
    """The rig controller process (server/controller.py): started by `shakeid serve`, or on its own."""
    from server.run_controller import run

    return run(args.config, args.data_dir, args.sim_speed, args.address, args.parent_pid)


def _operator(h5: Path) -> str | None:
    """The operator a shakeid recording names (the demo's own: "demo"); None when the file is not one."""
    from daq.recorder import describe

    try:
        return describe(h5).get("operator")
    except (ShakeidError, OSError):
        return None
