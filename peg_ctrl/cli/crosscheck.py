"""``peg-sim crosscheck``: the contact situations that set the studies' forces, in MuJoCo and Drake."""

from __future__ import annotations

import argparse

from peg_ctrl.cli.common import Known, add_known, add_out
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir, prepare_output_dir

SITUATIONS = Known("situation", "peg_ctrl.tools.crosscheck.situations", "BY_NAME")
MODELS = Known("contact model", "peg_ctrl.tools.crosscheck.battery", "BY_NAME")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``crosscheck`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "crosscheck",
        help="the studies' contact situations in MuJoCo and Drake",
        description="Runs each contact situation (a held peg sliding down the bore, landings, a side "
        "touch, wedging and entry pushes) in each contact model (MuJoCo's precision profile and its "
        "friction-time variants, the gripper's grasp, Drake's lagged and convex approximations) on "
        "one rig; writes DIR/crosscheck.md, DIR/crosscheck.json and plots. Needs Drake: "
        "pip install 'peg-ctrl[crosscheck]'.",
    )
    add_known(p, "--situation", SITUATIONS, "only this situation (repeatable; default all)", action="append")
    add_known(p, "--model", MODELS, "only this contact model (repeatable; default all)", action="append")
    p.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    add_out(p, "runs/crosscheck")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the cross-check and write its report."""
    from peg_ctrl.run.batch import default_workers
    from peg_ctrl.tools.crosscheck.battery import MODELS as ALL_MODELS
    from peg_ctrl.tools.crosscheck.battery import model
    from peg_ctrl.tools.crosscheck.drake_rig import require_drake
    from peg_ctrl.tools.crosscheck.situations import SITUATIONS as ALL_SITUATIONS
    from peg_ctrl.tools.crosscheck.situations import situation

    workers = args.workers if args.workers is not None else default_workers()
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    situations = [situation(n) for n in dict.fromkeys(args.situation)] if args.situation else ALL_SITUATIONS
    models = [model(n) for n in dict.fromkeys(args.model)] if args.model else ALL_MODELS
    if any(m.engine == "drake" for m in models):
        require_drake()
    from peg_ctrl.tools.crosscheck.report import run_crosscheck

    with lock_output_dir(prepare_output_dir(args.out)) as out:
        print(f"wrote {run_crosscheck(out, situations, models, workers=workers)}")
    return 0
