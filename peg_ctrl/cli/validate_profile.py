"""``peg-sim validate-profile``: check a physics profile against a reference on both tasks."""

from __future__ import annotations

import argparse

from peg_ctrl.cli.common import PROFILES, add_known, add_out
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir, prepare_output_dir


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``validate-profile`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "validate-profile",
        help="check a physics profile against a reference",
        description="Run both tasks for --seeds seeds in PROFILE and in --reference and compare success, "
        "peak force, slip and speed; writes DIR/validation.json and DIR/validation.md. Exit code 1 if "
        "a check fails.",
    )
    add_known(p, "profile", PROFILES, "the profile to validate: %(choices)s", metavar="PROFILE")
    reference = "the reference profile (default %(default)s)"
    add_known(p, "--reference", PROFILES, reference, default="seed", metavar="PROFILE")
    p.add_argument("--seeds", type=int, default=100, help="seeds per task and profile (default 100)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    add_out(p, help="output directory (default runs/validate-<profile>)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Compare the profiles; exit code 1 when a check fails."""
    from peg_ctrl.tools.profile_check import validate_profile

    if args.profile == args.reference:
        raise ConfigError(f"--reference must differ from the profile, got {args.reference!r} for both")
    if args.seeds < 2:
        raise ConfigError(f"--seeds must be >= 2, got {args.seeds}")
    if args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    with lock_output_dir(prepare_output_dir(args.out or f"runs/validate-{args.profile}")) as out:
        result = validate_profile(
            args.profile, out, reference=args.reference, seeds=args.seeds, workers=args.workers
        )
    print((out / "validation.md").read_text(), end="")
    print(f"wrote {out / 'validation.json'} and {out / 'validation.md'}")
    return 0 if result["passed"] else 1
