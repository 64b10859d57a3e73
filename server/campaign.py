"""Campaigns in the rig controller (server/controller.py): a plan of sweeps run one after another,
unattended, each through the same path as a single sweep (a catalog sweep + recording, identified when
complete as any sweep is); the plan, its check and the loop are daq/campaign.py's, shared with
`shakeid campaign --config`.

Safety (the controller's rules hold for campaign sweeps as for any other):
- every sweep of the plan is checked against the rig's limits before the campaign starts (422 naming
  the sweep and the limit; nothing reaches the PLC);
- a sweep that does not end complete and usable (PLC fault, emergency stop, lost link, operator abort,
  web server gone, unusable quality) pauses the campaign with the reason; it never goes on by itself:
  resume (refused while the PLC is in fault or estop) re-runs that sweep, abort ends the campaign;
- the emergency stop never waits for a campaign: it sets a flag (`halt`, plain attributes and an Event)
  that no one holds a lock around, then stops the table; a sweep the campaign started at that instant
  is aborted as soon as its ids are known, and no next sweep starts;
- the campaign's state is in the catalog (table campaigns): a controller that restarts finds a campaign
  it was running and marks it paused: the rig never moves unattended after a crash.
"""
from __future__ import annotations

import threading
import time

from daq.campaign import Campaign, CampaignControl, PlanError, parse_plan, plan_violation, run_campaign
from daq.devices import DeviceError
from daq.sweep import SweepRefused

from .catalog import new_id
from .preflight import predicted_body
from .sweep_launch import Refused

#: why a campaign a dead or stopped controller was running is paused after the restart
RESTARTED = ("the rig controller stopped during the campaign (restart or crash); the table was stopped; "
             "resume when the rig is checked (a campaign never continues by itself after a restart)")


class CampaignService:
    """The controller's campaigns: at most one runs (the rig is one); paused ones wait in the catalog."""

    def __init__(self, controller):
        self.ctl = controller
        self.catalog = controller.catalog
        self.active: dict | None = None  # {"id", "campaign", "control", "thread", "operator"}
        self._lock = threading.Lock()    # campaign bookkeeping only: the estop path never takes it

    # -- what the controller asks -------------------------------------------------------------------------
    def recover(self) -> list[str]:
        """Campaigns a dead controller left running or pausing: paused, their running sweep failed."""
        notes = []
        for row in self.catalog.list("campaigns", "state IN ('running', 'pausing')", limit=10_000):
            items = row["sweeps"]
            for it in items:
                if it["status"] == "running":
                    it.update(status="failed", reason="interrupted: the rig controller stopped during the sweep")
            self.catalog.update("campaigns", row["id"], state="paused", reason=RESTARTED, sweeps=items)
            notes.append(f"campaign {row['id']} ({row['name']}): was {row['state']}; marked paused")
        return notes

    def busy(self) -> str | None:
        """Why a single sweep cannot start now: a campaign runs (named), or None."""
        act = self.active
        if act is None or act["campaign"].state not in ("running", "pausing"):  # none, or its thread ending
            return None
        c = act["campaign"]
        now = c.progress()["current"]
        return (f"campaign {c.plan.name} ({act['id']}) is {c.state}"
                + (f" (sweep {now} of {c.total})" if now else f" ({c.done} of {c.total} sweeps done)")
                + f"; pause or abort it first (POST /api/campaigns/{act['id']}/pause)")

    def halt(self, reason: str) -> None:
        """An emergency stop or a lost web server: no next sweep (and the current one is aborted by the
        caller's own path). Plain attribute writes and an Event: safe from any thread, never blocking."""
        act = self.active
        if act is not None:
            act["control"].halt(reason)

    def join(self, timeout_s: float = 20.0) -> None:
        act = self.active
        if act is not None:
            act["thread"].join(timeout_s)

    # -- operations (the controller's op_* delegate here) ---------------------------------------------------
    def start(self, plan: dict, operator: str = "") -> dict:
        try:
            parsed = parse_plan(plan)
        except PlanError as exc:
            raise Refused(422, f"campaign refused: {exc}") from None
        problem = plan_violation(self.ctl.rig.cfg.limits, parsed)
        if problem:
            raise Refused(422, f"campaign refused: {problem}")
        campaign = Campaign(parsed, state="running")
        with self.ctl.sweeps.starting:  # no single sweep slips in between the checks and the campaign's start
            self._check_rig_free()
            cid, now = new_id(), time.time()
            self.catalog.insert("campaigns", id=cid, created=now, updated=now, name=parsed.name, state="running",
                                reason=None, operator=operator, **self._row(campaign))
            self._launch(cid, campaign, operator)
        return {"id": cid, "state": "running"}

    def pause(self, campaign_id: str, operator: str = "") -> dict:
        with self._lock:
            act = self._running(campaign_id, "pause", ("running", "pausing"))
            act["control"].pause(f"paused by {operator or 'an operator'}")
            if act["campaign"].state == "running":
                act["campaign"].state = "pausing"  # the running sweep finishes first; the thread says paused
                self._save(act)
            return {"id": campaign_id, "state": act["campaign"].state}

    def resume(self, campaign_id: str, operator: str = "") -> dict:
        with self.ctl.sweeps.starting:
            row = self._row_or_404(campaign_id)
            if row["state"] != "paused":
                raise Refused(409, f"campaign {campaign_id} is {row['state']}, not paused")
            self._check_rig_free()
            campaign = Campaign(parse_plan(row["plan"]), state="running", items=row["sweeps"])
            self.catalog.update("campaigns", campaign_id, state="running", reason=None)
            self._launch(campaign_id, campaign, row["operator"] or operator)
        return {"id": campaign_id, "state": "running"}

    def abort(self, campaign_id: str, operator: str = "") -> dict:
        reason = f"aborted by {operator or 'an operator'}"
        with self._lock:
            act = self.active
            if act is not None and act["id"] == campaign_id:
                # running, pausing, or its thread finishing with paused: that thread's last word reads this
                self._running(campaign_id, "abort", ("running", "pausing", "paused"))
                act["control"].abort(reason)
                self._abort_sweep(act)
                return {"id": campaign_id, "state": "aborting"}
            row = self._row_or_404(campaign_id)
            if row["state"] != "paused":
                raise Refused(409, f"campaign {campaign_id} is {row['state']}: nothing to abort")
            self.catalog.update("campaigns", campaign_id, state="aborted", reason=reason)
            return {"id": campaign_id, "state": "aborted"}

    # -- the campaign's thread ------------------------------------------------------------------------------
    def _launch(self, cid: str, campaign: Campaign, operator: str) -> None:
        act = {"id": cid, "campaign": campaign, "control": CampaignControl(), "operator": operator}
        act["thread"] = threading.Thread(target=self._run, args=(act,), name=f"campaign-{cid}", daemon=True)
        self.active = act
        act["thread"].start()

    def _run(self, act: dict) -> None:
        campaign = act["campaign"]
        try:
            run_campaign(campaign, lambda planned, item: self._run_sweep(act, planned, item), act["control"],
                         lambda _c: self._save(act), check=self._rig_check)
        except Exception as exc:  # said in the catalog, never lost in a thread; the rig is left alone
            campaign.state = "paused"
            campaign.reason = f"campaign error: {type(exc).__name__}: {exc}"
        finally:
            with self._lock:  # the last word, under the lock pause() and abort() take
                if campaign.state == "paused" and act["control"].abort_reason:  # came while this thread ended
                    campaign.state, campaign.reason = "aborted", act["control"].abort_reason
                self._save(act)
                if self.active is act:
                    self.active = None
        done = campaign.recording_ids()
        print(f"shakeid controller: campaign {act['id']} ({campaign.plan.name}) {campaign.state}: {len(done)} of "
              f"{campaign.total} sweeps complete{'; ' + campaign.reason if campaign.reason else ''}", flush=True)
        # Joint identification: every complete recording is identified (as any sweep; settings.auto_identify);
        # a completed campaign of two or more also gets one model of all of them (identify.joint), queued by
        # the web server (NamedQueries.owed_jobs) when told
        if campaign.state == "completed":
            self.ctl.notify({"event": "campaign_complete", "campaign_id": act["id"]})

    def _run_sweep(self, act: dict, planned, item: dict) -> dict:
        """One sweep of the campaign through the controller's own sweep path; waits for its end."""
        campaign, control = act["campaign"], act["control"]
        ended, box = threading.Event(), {}

        def after_end(result, error):
            box.update(result=result, error=error)
            ended.set()

        info = {"id": act["id"], "name": campaign.plan.name, "index": planned.index, "total": campaign.total,
                "direction": planned.direction, "repeat": planned.repeat}
        note = (f"campaign {campaign.plan.name} ({act['id']}): {planned.label(campaign.total)}"
                + (f"; {campaign.plan.note}" if campaign.plan.note else ""))
        try:
            # predicted again right before it starts (a sweep of this campaign may have given a newer model),
            # the prediction kept in the sweep's request as a single sweep's
            body = predicted_body(self.catalog, self.ctl.settings.rig, {**planned.body(note), "campaign": info})
            started = self.ctl.sweeps.launch(body, act["operator"], after_end, held=control.held)
        except Refused as exc:
            return {"status": "refused", "reason": exc.detail}
        except SweepRefused as exc:
            return {"status": "refused", "reason": str(exc)}
        except DeviceError as exc:
            return {"status": "refused", "reason": f"rig not reachable: {exc}"}
        if started is None:  # control.held() said no at the last moment: nothing was started
            return {"status": "held"}
        with self._lock:
            campaign.begin(item, sweep_id=started["id"], recording_id=started["recording_id"])
            self._save(act)
            if control.abort_reason or control.halted:  # asked for while the sweep was being started
                self._abort_sweep(act)
        ended.wait()
        result = box.get("result")
        if result is None:
            return {"status": "failed", "reason": box.get("error"), "sweep_id": started["id"]}
        return {"status": result["status"], "reason": result["reason"], "quality": result.get("quality"),
                "sweep_id": started["id"], "recording_id": started["recording_id"]}

    def _abort_sweep(self, act: dict) -> None:
        """Abort the campaign's running sweep, if it is the rig's active one (the table is commanded to stop)."""
        item = next((it for it in act["campaign"].items if it["status"] == "running"), None)
        sweep = self.ctl.rig.active
        if item is not None and sweep is not None and sweep["id"] == item["sweep_id"]:
            sweep["runner"].abort(f"campaign {act['campaign'].plan.name} ({act['id']}): "
                                  f"{act['control'].abort_reason or act['control'].pause_reason}")

    def _rig_check(self) -> str | None:
        """Between sweeps: the PLC in estop or fault (a hardware stop, `shakeid rig estop`) or the table
        moving under another client pauses the campaign."""
        try:
            return self.ctl.rig.not_ready()
        except DeviceError as exc:
            return f"the PLC does not answer: {exc}"

    # -- helpers --------------------------------------------------------------------------------------------
    def _check_rig_free(self) -> None:
        act = self.active
        if act is not None and act["campaign"].state not in ("running", "pausing"):
            act["thread"].join(5.0)  # it has ended and is writing its last word
        if (act := self.active) is not None:
            raise Refused(409, self.busy() or f"campaign {act['id']} is ending; try again")
        sweep = self.ctl.rig.active
        if sweep is not None and not sweep.get("ending"):
            raise Refused(409, f"a sweep is running ({sweep['id']}); abort it or wait")
        refusal = self.ctl.rig.not_ready()
        if refusal:
            raise Refused(409, f"campaign refused: {refusal}")

    def _running(self, campaign_id: str, what: str, states: tuple[str, ...]) -> dict:
        """The active campaign if it is campaign_id and in one of states; else 409 (404 if unknown)."""
        act = self.active
        if act is None or act["id"] != campaign_id or act["campaign"].state not in states:
            state = act["campaign"].state if act is not None and act["id"] == campaign_id else \
                self._row_or_404(campaign_id)["state"]
            raise Refused(409, f"campaign {campaign_id} is {state}, not running: nothing to {what}")
        return act

    def _row_or_404(self, campaign_id: str) -> dict:
        row = self.catalog.get("campaigns", campaign_id)
        if row is None:
            raise Refused(404, f"no campaign {campaign_id}")
        return row

    def _row(self, campaign: Campaign) -> dict:
        d = campaign.to_dict()
        return {k: d[k] for k in ("plan", "sweeps", "progress", "recording_ids")}

    def _save(self, act: dict) -> None:
        c = act["campaign"]
        self.catalog.update("campaigns", act["id"], state=c.state, reason=c.reason, **self._row(c))
