"""``peg-sim validity``: the physical validity battery per physics profile."""

from __future__ import annotations

import argparse

from peg_ctrl.cli.common import PROFILES, add_known, add_out
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir, prepare_output_dir


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``validity`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "validity",
        help="physical validity battery per physics profile",
        description="Held pushes per physics profile against clearance, chamfer and tilt; writes "
        "DIR/validity.md, DIR/validity.json and plots.",
    )
    add_known(
        p,
        "--profile",
        PROFILES,
        "physics profile: %(choices)s (repeatable; default seed and precision)",
        action="append",
        metavar="PROFILE",
    )
    p.add_argument(
        "--friction-time",
        type=float,
        metavar="SECONDS",
        help="also run precision with the peg's friction at this time constant "
        "(physics.friction_time, docs/physics.md 'Known limits')",
    )
    p.add_argument("--trials", type=int, default=10, help="pushes per clearance (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start-error draws (default 0)")
    add_out(p, "runs/validity")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the battery and write its report."""
    import dataclasses

    from peg_ctrl.sim.physics import PhysicsConfig, PhysicsProfile
    from peg_ctrl.tools.validity_report import run_battery

    profiles: list[str | PhysicsProfile] = list(args.profile or ["seed", "precision"])  # checked names
    if args.friction_time is not None:
        try:
            slow = PhysicsConfig("precision", friction_time=args.friction_time).resolved()
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("physics.friction_time", "--friction-time")) from None
        name = f"precision, friction {args.friction_time * 1e3:g} ms"
        profiles.append(dataclasses.replace(slow, name=name))
    if args.trials < 1:
        raise ConfigError(f"--trials must be >= 1, got {args.trials}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        print(f"wrote {run_battery(out, profiles, trials=args.trials, seed=args.seed)}")
    return 0
