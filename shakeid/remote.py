"""`shakeid sweep --server URL`: the same sweep through a running `shakeid serve`, which owns the rig.

The service records, keeps the file and identifies it; this command starts the sweep, shows its
progress, aborts it on Ctrl-C, and can fetch the file (--out) and wait for the model (--wait-model).
Plain urllib (standard library): a client this small needs no HTTP package at run time.
"""
from __future__ import annotations

import json
import os
import time
import urllib.error
import urllib.request
from pathlib import Path

from identify.errors import ShakeidError

from .progress import rig_label


class ServiceError(ShakeidError):
    """The service answered with an error; `status` is the HTTP status (0: no answer at all)."""

    def __init__(self, message: str, status: int = 0):
        super().__init__(message)
        self.status = status


class ServiceClient:
    def __init__(self, url: str, token: str, timeout_s: float = 10.0):
        if not url.startswith(("http://", "https://")):
            raise ShakeidError(f"--server {url}: give the service's URL with its scheme, e.g. http://{url}")
        self.url, self.token, self.timeout_s = url.rstrip("/"), token, timeout_s

    @classmethod
    def for_args(cls, args, whose: str = "") -> "ServiceClient":
        """The client of a command's --server and --token (or $SHAKEID_TOKEN): refused before anything is
        sent when there is no token, saying whose it needs."""
        token = args.token or os.environ.get("SHAKEID_TOKEN", "")
        if not token:
            raise ShakeidError("--server needs a token: --token or SHAKEID_TOKEN" + (f" ({whose})" if whose else ""))
        return cls(args.server, token)

    def request(self, method: str, path: str, body: dict | None = None, raw: bool = False):
        """JSON (or bytes with raw=True) of a 2xx answer; ShakeidError with the service's detail otherwise."""
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(self.url + path, data=data, method=method,
                                     headers={"Authorization": f"Bearer {self.token}",
                                              **({"Content-Type": "application/json"} if data else {})})
        try:
            with urllib.request.urlopen(req, timeout=self.timeout_s) as r:
                payload = r.read()
        except urllib.error.HTTPError as exc:
            try:
                detail = json.loads(exc.read()).get("detail", exc.reason)
            except ValueError:
                detail = exc.reason
            raise ServiceError(f"{method} {path}: {exc.code} {_words(detail)}", exc.code) from None
        except (urllib.error.URLError, OSError) as exc:
            raise ServiceError(f"the service at {self.url} does not answer: {exc}") from None
        return payload if raw else (json.loads(payload) if payload else {})


def _words(detail) -> str:
    """The service's error detail as a sentence: a request the schema refused (FastAPI's list of
    {"loc", "msg", "input"}) as "field: what is wrong (got value)" per field, not as JSON."""
    if isinstance(detail, str):
        return detail
    if isinstance(detail, list) and all(isinstance(d, dict) and "msg" in d for d in detail):
        parts = []
        for d in detail:
            loc = [str(x) for x in d.get("loc", []) if x != "body"]
            got = f" (got {d['input']})" if "input" in d and not isinstance(d["input"], (dict, list)) else ""
            parts.append(f"{'.'.join(loc) or 'request'}: {d['msg']}{got}")
        return "; ".join(parts)
    return json.dumps(detail)


def cmd_sweep_remote(args) -> int:
    from reports.text import summary

    from .progress import Progress

    client = ServiceClient.for_args(args, "an operator's")
    if args.out and Path(args.out).exists():  # before the table moves: the download would replace it
        raise ShakeidError(f"{args.out}: exists already; a recording is never overwritten (give --out a new name)")
    body = {"f_start_hz": args.f_start_hz, "f_end_hz": args.f_end_hz, "duration_s": args.duration_s,
            "amplitude_mm": args.amplitude_mm, "settle_s": args.settle_s, "note": args.note}
    started = client.request("POST", "/api/sweeps", body)
    sweep_id = started["id"]
    print(f"sweep {sweep_id} started on {args.server}", flush=True)
    for warning in (started.get("preflight") or {}).get("warnings", []):  # near a limit (daq/preflight.py)
        print(f"preflight warning: {warning}", flush=True)
    progress = Progress("sweep", args.duration_s)
    try:
        while (sweep := client.request("GET", f"/api/sweeps/{sweep_id}"))["state"] in ("queued", "running"):
            progress.update(sweep["progress"], _rig_label(client, sweep["state"]))
            time.sleep(0.2)
    except KeyboardInterrupt:
        client.request("POST", f"/api/sweeps/{sweep_id}/abort")
        while (sweep := client.request("GET", f"/api/sweeps/{sweep_id}"))["state"] in ("queued", "running"):
            time.sleep(0.2)
    progress.update(sweep["progress"], sweep["state"])
    progress.close(sweep["state"])
    rec_id = sweep["recording_id"]
    print(f"sweep {sweep_id}: {sweep['state']}{' (' + sweep['error'] + ')' if sweep['error'] else ''}; "
          + (f"recording {rec_id}" if rec_id else "no recording"))
    if rec_id and args.out:
        Path(args.out).write_bytes(client.request("GET", f"/api/recordings/{rec_id}/file", raw=True))
        print(f"{args.out}: the recording, downloaded")
    if sweep["state"] != "completed":
        return 1
    if args.wait_model:
        end = time.monotonic() + 300
        while True:
            try:
                result = client.request("GET", f"/api/recordings/{rec_id}/model")
                break
            except ServiceError as exc:
                if exc.status != 404 or time.monotonic() > end:  # 404: no model yet
                    raise
                jobs = [j for j in client.request("GET", "/api/jobs") if j["recording_id"] == rec_id]
                if jobs and all(j["state"] == "failed" for j in jobs):
                    raise ShakeidError(f"identification failed: {jobs[0]['error']}") from None
                time.sleep(0.2)
        print(summary(result, f"recording {rec_id}"))
        print(f"plots and report: {args.server.rstrip('/')}/#/recording/{rec_id} (the dashboard; "
              f"GET /api/recordings/{rec_id}/plots lists the figures)")
    return 0


def _rig_label(client: ServiceClient, state: str) -> str:
    """The progress line's label: the sweep's state with the PLC's frequency and table position, as a local
    sweep shows them (GET /api/rig, which the service answers from a status at most 0.1 s old); the state
    alone when the rig's status cannot be read or says nothing of this sweep (queued: the PLC may still
    run another). The PLC finishes a poll or two before the service has closed the recording: its
    frequency then reads 0, and the line says the sweep is finishing instead."""
    if state != "running":
        return state
    try:
        plc = client.request("GET", "/api/rig").get("plc", {})
        if plc["state"] != "running":
            return f"finishing: the PLC is {plc['state']}, the recording is being closed"
        return rig_label(state, float(plc["frequency_hz"]), float(plc["position_mm"]))
    except (ShakeidError, KeyError, TypeError, ValueError):
        return state
