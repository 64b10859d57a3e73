"""`shakeid plan-campaign MODEL.json [--config RIG.toml] [--out PLAN.toml] [--json]`: a campaign proposed
from the model's predicted folds (daq.plan): amplitudes that bracket the jump, a band that brackets every
jump frequency, each sweep inside the PLC's limits and predicted inside the rig's (docs/frf.md)."""
from __future__ import annotations

import json
from pathlib import Path

from identify.errors import ShakeidError

from .argtypes import positive
from .model_arg import add_model_arguments, read_model


def add_plan_parser(sub) -> None:
    q = sub.add_parser("plan-campaign", help="propose a campaign (amplitudes, band) that brackets the model's "
                                             "predicted jumps inside the rig's limits")
    add_model_arguments(q, "use")
    q.add_argument("--config", metavar="RIG.toml", help="the rig's limits, accelerometer range and end-stop travel "
                                                        "(default: the simulated rig's, examples/sim-rig.toml)")
    from daq.plan import JUMP_AMPLITUDES, JUMP_AMPLITUDES_RANGE, PROPOSAL_NAME

    low, high = JUMP_AMPLITUDES_RANGE
    q.add_argument("--name", default=PROPOSAL_NAME, help=f"the campaign's name (default: {PROPOSAL_NAME})")
    q.add_argument("--jump-amplitudes", type=int, default=JUMP_AMPLITUDES, choices=range(low, high + 1),
                   metavar="N", help=f"amplitudes with a predicted jump, {low}-{high} (default {JUMP_AMPLITUDES}; "
                                     "one more below the onset)")
    q.add_argument("--rate", type=positive, default=None, metavar="HZ_PER_S",
                   help="sweep rate, Hz/s (default: daq.plan.RATE_HZ_PER_S = 0.1)")
    q.add_argument("--out", metavar="PLAN.toml", help="write the plan for `shakeid campaign PLAN.toml` here")
    q.add_argument("--json", action="store_true", help="print the proposal as one JSON document")
    q.set_defaults(func=cmd_plan_campaign)


def cmd_plan_campaign(args) -> int:
    from daq.plan import RATE_HZ_PER_S, plan_toml, propose_campaign, with_model
    from daq.preflight import nominal_response
    from sim.config import RigConfig, load_config

    from identify.frf.balance import check_model

    out = Path(args.out) if args.out else None
    if out is not None and out.exists():
        raise ShakeidError(f"{out}: exists; a plan is never overwritten (give another --out)")
    cfg = load_config(args.config) if args.config else RigConfig()
    model = read_model(args, "use", check_model)
    rig = with_model(nominal_response(cfg), model, f"the model in {args.model}")
    proposal = propose_campaign(rig, cfg.limits, args.name, args.jump_amplitudes, args.rate or RATE_HZ_PER_S)
    if out is not None:
        out.write_text(plan_toml(proposal["plan"]))
    if args.json:
        print(json.dumps(proposal))
        return 0
    plan, s = proposal["plan"], proposal["plan"]["sweep"]
    print(f"proposed from {args.model}: jumps from {proposal['onset_mm']:.3g} mm (onset), largest amplitude the rig "
          f"takes {proposal['largest_mm']:.3g} mm")
    print(f"band {s['f_start_hz']:g}-{s['f_end_hz']:g} Hz over {s['duration_s']:g} s, up and down")
    print(f"{'table mm':>9} {'jump down Hz':>13} {'jump up Hz':>11} {'peak mm':>8} {'travel mm':>10} {'mass m/s^2':>11}")
    for a in proposal["amplitudes"]:
        f = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731
        pre = a.get("preflight") or {}
        print(f"{a['amplitude_mm']:>9g} {f(a['jump_down_hz']):>13} {f(a['jump_up_hz']):>11} {a['peak_response_mm']:>8.3g} "
              f"{pre.get('travel_peak_mm', float('nan')):>10.3g} {pre.get('mass_peak_ms2', float('nan')):>11.3g}")
    for note in proposal["notes"]:
        print(f"  {note}")
    if out is not None:
        print(f"plan: {out} (run it: shakeid campaign {out} --config RIG.toml --out DIR, or --server URL)")
    return 0
