"""The rig controller as a process of its own, started in one of two ways that end in run() here:

- `shakeid serve` starts its child as `python -m server.run_controller --parent-pid PID ...`
  (server/rigclient.py), so the service needs nothing from the command-line package shakeid;
- an operator or a compose service runs `shakeid controller ...` (shakeid/lab.py), the same options.
"""
from __future__ import annotations

import argparse
import sys

from identify.errors import ShakeidError


def run(config=None, data_dir=None, sim_speed: float | None = None, address: str | None = None,
        parent_pid: int | None = None) -> int:
    """Load the settings (RIG.toml, environment, --data-dir) and run the controller until it is stopped."""
    from .controller import main
    from .settings import Settings

    settings = Settings.load(config, data_dir=data_dir)
    if sim_speed is not None:
        settings.sim_speed = sim_speed
    return main(settings, address or settings.controller, parent_pid)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m server.run_controller",
                                description="the rig controller process (`shakeid controller` is the same)")
    p.add_argument("--config", metavar="RIG.toml")
    p.add_argument("--data-dir", metavar="DIR")
    p.add_argument("--address")
    p.add_argument("--sim-speed", type=float)
    p.add_argument("--parent-pid", type=int)
    args = p.parse_args(argv)
    try:
        return run(args.config, args.data_dir, args.sim_speed, args.address, args.parent_pid)
    except ShakeidError as exc:
        print(f"shakeid controller: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
