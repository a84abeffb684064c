"""``peg-sim plot``: redraw a sweep's plots and report from its saved tables."""

from __future__ import annotations

import argparse
from pathlib import Path

from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``plot`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "plot",
        help="redraw a sweep's plots and report.md",
        description="Redraw the plots and report.md of a sweep from the episodes.csv it saved in DIR. "
        "An episodes.csv that is missing, cut off or behind the episodes (a killed sweep) is first "
        "rebuilt from DIR/episodes/*/summary.json, and refused when that is not possible.",
    )
    p.add_argument("dir", metavar="DIR", help="a sweep's output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Rebuild the tables if needed, then redraw the report."""
    from peg_ctrl.experiments.report import write_report
    from peg_ctrl.experiments.runner import refresh_tables

    out = Path(args.dir)
    if not (out / "episodes.csv").is_file() and not (out / "experiment.json").is_file():
        raise ConfigError(f"{out} has no episodes.csv (run peg-sim sweep first)")
    with lock_output_dir(out):
        # A cut-off or stale episodes.csv is rebuilt from the episode summaries, or refused.
        for note in refresh_tables(out):
            print(note)
        print(f"wrote {write_report(out)}")
    return 0
