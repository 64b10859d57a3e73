"""`shakeid campaign`: a plan of sweeps (daq/campaign.py) run on the rig of --config, or through a
running service (--server).

With --config the sweeps run here, one after another, each recorded to OUT/<name>-<k>.h5 (k from 1, in
run order) through the same SweepRunner as `shakeid sweep --config`; OUT/<name>.campaign.json holds the
campaign's state after every change. A sweep that does not end complete and usable pauses the
campaign: the command exits 1 naming the sweep and the reason, and `--resume` (after `shakeid rig reset
--config RIG.toml` if the PLC is in fault or estop) re-runs that sweep (the earlier file is kept as
<name>-<k>.attempt-<j>.h5) and goes on. Ctrl-C stops the table, closes the file "aborted" and ends the
campaign aborted (exit 130); an aborted or completed campaign is not resumed.
"""
from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

from identify.errors import ShakeidError

CTRL_C = "operator abort (Ctrl-C)"


def add_campaign_parser(sub) -> None:
    q = sub.add_parser("campaign", help="run a plan of sweeps (amplitudes, up and down, repeats) on the rig of "
                                        "--config, or through a running shakeid serve (--server)")
    q.add_argument("plan", metavar="PLAN.toml", help="the campaign's plan (examples/campaign.toml)")
    where = q.add_mutually_exclusive_group(required=True)
    where.add_argument("--config", metavar="RIG.toml", help="drive the rig of this configuration directly")
    where.add_argument("--server", metavar="URL", help="through the HTTP service at this URL, e.g. http://127.0.0.1:8000")
    q.add_argument("--token", help="with --server: an operator token (default: $SHAKEID_TOKEN)")
    q.add_argument("--out", metavar="DIR", help="with --config: the recordings <name>-<k>.h5 and <name>.campaign.json "
                                                "(default: none; needed with --config)")
    q.add_argument("--resume", action="store_true",
                   help="with --config: go on with the paused campaign of the same name in --out")
    q.add_argument("--operator", default="", help="who runs the campaign, kept in every recording")
    q.set_defaults(func=cmd_campaign)


def cmd_campaign(args) -> int:
    from daq.campaign import load_plan

    plan = load_plan(args.plan)
    if args.server:
        return _remote(args, plan)
    if not args.out:
        raise ShakeidError("--out DIR is needed with --config (the recordings and the campaign's state go there)")
    return _local(args, plan)


def _state_path(out: Path, name: str) -> Path:
    return out / f"{name}.campaign.json"


def _load(args, plan, out: Path):
    """The campaign to run: a new one, or (--resume) the paused one of the same name in out."""
    from daq.campaign import Campaign

    path = _state_path(out, plan.name)
    if not path.exists():
        if args.resume:
            raise ShakeidError(f"--resume: no campaign {plan.name} in {out} ({path.name} missing)")
        return Campaign(plan)
    saved = json.loads(path.read_text())
    done = sum(1 for it in saved["sweeps"] if it["status"] == "complete")
    if not args.resume:
        ended = saved["state"] in ("completed", "aborted")  # nothing to resume: only a new name or folder helps
        raise ShakeidError(f"campaign {plan.name} is already in {out} ({saved['state']}, {done} of "
                           f"{len(saved['sweeps'])} sweeps done): "
                           + ("give the plan another name or another --out" if ended else
                              "--resume to go on, or another name or --out"))
    if saved["state"] in ("completed", "aborted"):
        raise ShakeidError(f"campaign {plan.name} in {out} is {saved['state']}: nothing to resume")
    if saved["plan"] != plan.to_dict():
        raise ShakeidError(f"{args.plan} is not the plan campaign {plan.name} in {out} was started with; "
                           "give the campaign another name to run a new plan")
    return Campaign(plan, state="paused", reason=saved.get("reason"), items=saved["sweeps"])


def _local(args, plan) -> int:
    """The plan on the rig of --config: refused before anything reaches the PLC if a sweep breaks a limit
    or is predicted to; crashed recordings in --out marked aborted; then the sweeps one after another."""
    from daq.campaign import plan_prediction, plan_violation
    from daq.preflight import nominal_response
    from daq.recorder import recover_directory
    from sim.config import load_config

    cfg = load_config(args.config)
    problem = plan_violation(cfg.limits, plan)
    if problem:
        raise ShakeidError(f"{args.plan}: campaign refused: {problem} (nothing was sent to the PLC)")
    response = nominal_response(cfg)  # every sweep predicted now, and again by its runner before it starts
    problem, warnings = plan_prediction(response, cfg.limits, plan)
    if problem:
        raise ShakeidError(f"{args.plan}: campaign refused: {problem} (nothing was sent to the PLC)")
    for label, said in warnings.items():
        print("\n".join(f"preflight warning: {label}: {w}" for w in said), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for path in recover_directory(out):  # crashed recordings, found on start
        print(f"{path}: was left running by a crash; marked aborted, its data kept")
    return _LocalCampaign(args, plan, cfg, response, out).run()


class _LocalCampaign:
    """One campaign run here: its sweeps through the SweepRunner, its state saved after every change, the
    PLC checked between sweeps, Ctrl-C stopping the table (daq.campaign.run_campaign calls back into it)."""

    def __init__(self, args, plan, cfg, response, out: Path):
        from daq.campaign import CampaignControl

        self.args, self.plan, self.cfg, self.response, self.out = args, plan, cfg, response, out
        self.campaign = _load(args, plan, out)
        self.state_path = _state_path(out, plan.name)
        self.control = CampaignControl()
        self.runner = None  # the sweep running now
        self.status_plc = None  # the link check() polls between sweeps

    def run(self) -> int:
        from daq.campaign import run_campaign
        from daq.realtime import CONTROLLER_PRIORITY, make_realtime

        args, plan, campaign = self.args, self.plan, self.campaign
        make_realtime(CONTROLLER_PRIORITY, round_robin=True)  # where allowed: the heartbeat is never late
        print(f"campaign {plan.name}: {campaign.total} sweeps ({campaign.done} done), rig of {args.config} -> "
              f"{self.out}", flush=True)
        previous = signal.signal(signal.SIGINT, self.on_sigint)
        try:
            run_campaign(campaign, self.run_sweep, self.control, self.save, self.check)
        finally:
            signal.signal(signal.SIGINT, previous)
            if self.status_plc is not None:
                self.status_plc.close()
        print(f"campaign {plan.name}: {campaign.state}, {campaign.done} of {campaign.total} sweeps complete"
              + (f"; {campaign.reason}" if campaign.reason else "") + f" ({self.state_path})")
        if campaign.state == "paused":
            print(f"to go on: reset the PLC if needed (`shakeid rig reset --config {args.config}`), then "
                  f"`shakeid campaign {args.plan} --config {args.config} --out {args.out} --resume`")
            return 1
        if campaign.state == "aborted":
            return 130 if campaign.reason == CTRL_C else 1
        return 0

    def on_sigint(self, *_) -> None:
        """No next sweep starts; the running one is stopped by the sweep's own path."""
        self.control.abort(CTRL_C)
        runner = self.runner
        if runner is not None:
            runner.abort(CTRL_C)

    def save(self, c) -> None:
        tmp = self.state_path.with_suffix(".tmp")
        tmp.write_text(json.dumps({**c.to_dict(), "updated": time.time()}, indent=1))
        os.replace(tmp, self.state_path)

    def _path(self, planned, item) -> Path:
        """OUT/<name>-<k>.h5; an earlier attempt's file moved aside (<name>-<k>.attempt-<j>.h5), its
        attempt entry following it."""
        path = self.out / f"{self.plan.name}-{planned.index}.h5"
        if path.exists():
            j = 1
            while (aside := self.out / f"{self.plan.name}-{planned.index}.attempt-{j}.h5").exists():
                j += 1
            path.rename(aside)
            for attempt in item["attempts"]:
                if attempt.get("path") == str(path):
                    attempt["path"] = str(aside)
        return path

    def run_sweep(self, planned, item) -> dict:
        from daq.devices import DeviceError
        from daq.plc import open_plc
        from daq.sweep import SweepRefused, SweepRunner

        from .lab import sweep_devices
        from .progress import Progress

        cfg, total = self.cfg, self.campaign.total
        path = self._path(planned, item)
        print(f"{planned.label(total)}: {planned.f_start_hz:g} -> {planned.f_end_hz:g} Hz over "
              f"{planned.duration_s:g} s -> {path}", flush=True)
        try:
            plc, source = sweep_devices(cfg)
        except DeviceError as exc:
            return {"status": "refused", "reason": f"rig not reachable: {exc}"}
        devices, progress = [plc, source], None
        try:
            devices.append(open_plc(cfg.plc))  # the heartbeat's own link: never behind a status poll
            progress = Progress(f"sweep {planned.index} of {total}:", planned.duration_s)
            runner = SweepRunner(plc, source, cfg.limits, float(cfg.stream["sensitivity_counts_per_ms2"]),
                                 cfg.channels, on_progress=progress.sweep_status, heartbeat_plc=devices[2],
                                 rig_config=cfg.recording_metadata(), response=self.response)
            if self.control.held():
                return {"status": "held"}
            self.runner = runner
            note = f"campaign {self.plan.name}: {planned.label(total)}" + (f"; {self.plan.note}" if self.plan.note else "")
            result = runner.run(planned.request(self.args.operator, note), path)
        except SweepRefused as exc:
            return {"status": "refused", "reason": str(exc)}
        except DeviceError as exc:
            return {"status": "refused", "reason": f"rig not reachable: {exc}"}
        finally:
            self.runner = None
            if progress is not None:
                progress.close()
            for dev in devices:
                dev.close()
        print(f"  {path.name}: {result['status']}{' (' + result['reason'] + ')' if result['reason'] else ''}, "
              f"{result['samples']} samples, {result['gaps']} gap(s)", flush=True)
        return {"status": result["status"], "reason": result["reason"], "quality": result.get("quality"),
                "path": str(path)}

    def check(self) -> str | None:
        """Between sweeps: the PLC in estop or fault, or the table moving, pauses the campaign."""
        from daq.devices import DeviceError
        from daq.plc import open_plc
        from protocol.plc import Fault, State

        try:
            if self.status_plc is None:
                self.status_plc = open_plc(self.cfg.plc)
            st = self.status_plc.status()
        except DeviceError as exc:
            self.status_plc = None
            return f"the PLC does not answer: {exc}"
        if st.state in (State.IDLE, State.DONE):
            return None
        return ("the PLC is in emergency stop" if st.state == State.ESTOP else "the table is moving"
                if st.state == State.RUNNING else f"the PLC is in fault ({Fault(st.fault_code).name.lower()})")


def _remote(args, plan) -> int:
    """The same plan through a running service: started, followed sweep by sweep, aborted on Ctrl-C."""
    from .remote import ServiceClient

    client = ServiceClient.for_args(args, "an operator's")
    started = client.request("POST", "/api/campaigns", plan.to_dict())
    cid = started["id"]
    print(f"campaign {plan.name} ({cid}) started on {args.server}", flush=True)
    for label, said in ((started.get("preflight") or {}).get("warnings") or {}).items():  # near a limit
        print("\n".join(f"preflight warning: {label}: {w}" for w in said), flush=True)
    seen: dict = {}
    try:
        while True:
            c = client.request("GET", f"/api/campaigns/{cid}")
            _report(c, seen)
            if c["state"] not in ("running", "pausing"):
                break
            time.sleep(0.5)
    except KeyboardInterrupt:
        client.request("POST", f"/api/campaigns/{cid}/abort")
        while (c := client.request("GET", f"/api/campaigns/{cid}"))["state"] in ("running", "pausing"):
            time.sleep(0.2)
        _report(c, seen)
    print(f"campaign {plan.name} ({cid}): {c['state']}, {c['progress']['done']} of {c['progress']['total']} sweeps "
          f"complete{'; ' + c['reason'] if c['reason'] else ''}; recordings {', '.join(c['recording_ids']) or 'none'}")
    if c["state"] == "paused":
        print(f"to go on: POST {args.server}/api/campaigns/{cid}/resume (after POST /api/rig/reset if needed)")
    return 0 if c["state"] == "completed" else 1


def _report(c: dict, seen: dict) -> None:
    """One line per sweep as it starts and as it ends."""
    for it in c["sweeps"]:
        key = (it["index"], it["sweep_id"], it["status"])
        if it["status"] == "planned" or seen.get(it["index"]) == key:
            continue
        seen[it["index"]] = key
        what = (f"sweep {it['index']} of {c['progress']['total']} ({it['amplitude_mm']:g} mm, {it['direction']})")
        print(f"{what}: {it['status']}" + (f", recording {it['recording_id']}" if it["recording_id"] else "")
              + (f" ({it['reason']})" if it["reason"] else ""), flush=True)
