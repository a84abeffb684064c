"""``peg-sim compare``: bring a controller to a committed study and get its row.

Only the new arm runs (on the study's grid and seeds, after ``--set``), with a verification
sample of each of the study's arms; every other study episode comes from the committed run
(:mod:`peg_ctrl.experiments.compare`). ``--dry-run`` says how many episodes that is and how long
they should take, and writes nothing.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from peg_ctrl.cli.common import add_out, add_set
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import check_output_dir, prepare_output_dir

if TYPE_CHECKING:
    from peg_ctrl.experiments.compare import Comparison


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``compare`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "compare",
        help="run a new arm against a committed study",
        description="Run one new arm on a committed study's grid and seeds and compare it with the "
        "study's arms, whose episodes come from the committed run (a sample of each is rerun first and "
        "classed reproduced, agrees or differs; only differs stops it: docs/reproducibility.md). "
        "Writes DIR/report.md (the new arm against each study arm: success with "
        "Wilson intervals, peak force, time, Holm-corrected p-values), the tables and plots. Rerunning "
        "the same command resumes.",
        epilog="example: peg-sim compare contact_hard --controller my_ctrl.py:MyConfig --strategy align "
        "--set seeds=2 --out runs/mine",
    )
    p.add_argument(
        "study", help="a committed study's name (docs/<study>/, e.g. contact_hard) or a sweep's directory"
    )
    p.add_argument(
        "--controller",
        required=True,
        metavar="C",
        help="a registered controller name (a study controller of that name brings its fields: change "
        "them with --set controller.<field>), or PATH.py:ClassName (a ControllerConfig subclass in your "
        "file; registered for the run and in its workers)",
    )
    p.add_argument(
        "--strategy",
        metavar="S",
        help="a registered strategy name (a study strategy of that name brings its fields), or "
        "PATH.py:ClassName; needed when the study crosses strategies",
    )
    add_set(
        p,
        help="set a field by dotted path, value parsed as YAML (repeatable): controller.<field> and "
        "strategy.<field> the new arm's, any other key the study's experiment (seeds=2, a grid key); "
        "study episodes the committed run lacks need --rerun-baselines",
    )
    add_out(p, required=True, help="output directory")
    p.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    p.add_argument(
        "--verify",
        type=int,
        default=1,
        metavar="N",
        help="committed episodes of each study arm rerun to check they reproduce (default %(default)s)",
    )
    p.add_argument(
        "--rerun-baselines",
        action="store_true",
        help="rerun a study arm whose committed episodes do not reproduce (or are missing) instead of "
        "stopping",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the episodes it would run and an estimate; write nothing",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Plan the comparison; print it (``--dry-run``) or run it and print the new arm's row."""
    from peg_ctrl.experiments.compare import plan_comparison, run_comparison
    from peg_ctrl.run.batch import default_workers

    workers = args.workers if args.workers is not None else default_workers()
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    comp = plan_comparison(args.study, args.controller, args.strategy, args.set or [], verify=args.verify)
    out = Path(args.out)
    if args.dry_run:
        check_output_dir(out)
        print("\n".join(_dry_run(comp, out, workers, args.rerun_baselines)))
        return 0
    out = prepare_output_dir(out)
    started = time.perf_counter()
    rows = run_comparison(comp, out, workers=workers, rerun_baselines=args.rerun_baselines)
    mine = [r for r in rows if r["arm"] == comp.arm]
    wins = sum(r["status"] == "success" for r in mine)
    verified = sum(len(s) for s in comp.sample.values())
    arms = len(comp.study_jobs)
    record = json.loads((out / "compare.json").read_text())
    for line in _verification_lines(record):
        print(line)
    print(
        f"{comp.arm}: {wins}/{len(mine)} inserted; {len(rows) - len(mine)} episodes of {arms} "
        f"{comp.study} arms from the committed run ({verified} rerun to verify them); "
        f"{time.perf_counter() - started:.0f} s; wrote {out / 'report.md'}"
    )
    return 0


def _verification_lines(record: dict[str, Any]) -> list[str]:
    """What the verification found: the environment's differences from the study's, and each
    study arm's class (docs/reproducibility.md)."""
    env = record.get("environment") or {}
    differ = env.get("differences") or []
    lines = [
        f"environment {env.get('here', '?')}: " + ("the study's in everything recorded" if not differ else "")
    ]
    lines[0] += "; ".join(differ) if differ else ""
    for arm, v in record.get("verified", {}).items():
        lines.append(f"  {record['study']} {arm}: {v['class']} ({v['detail']})")
    for arm in record.get("rerun", []):
        lines.append(f"  {record['study']} {arm}: rerun here in full")
    return lines


def _dry_run(comp: Comparison, out: Path, workers: int, rerun_baselines: bool) -> list[str]:
    """What ``compare`` would run, and the estimate of its wall time."""
    import dataclasses

    from peg_ctrl.cli.sweep import estimate_lines
    from peg_ctrl.experiments.compare import jobs_to_run
    from peg_ctrl.experiments.config import experiment_from_mapping
    from peg_ctrl.experiments.estimate import estimate, sweep_size
    from peg_ctrl.experiments.runner import finished_summaries
    from peg_ctrl.run.batch import default_workers

    missing = comp.missing
    rerun = set(missing) if rerun_baselines else set()
    jobs = jobs_to_run(comp, rerun)
    counts: dict[tuple[str, str, str], int] = {}
    for job in jobs:
        key = (job.config.task.name, job.config.physics.profile, job.controller)
        counts[key] = counts.get(key, 0) + 1
    size = dataclasses.replace(sweep_size(experiment_from_mapping(comp.experiment)), counts=counts)
    done = finished_summaries(out) if (out / "compare.json").is_file() else {}
    est = estimate(size, workers=workers, cores=default_workers(), done=done)
    sampled = len(comp.sample_jobs(rerun))
    lines = [
        f"compare {comp.arm} against {comp.study} ({comp.study_dir}): {len(jobs)} episodes to run",
        f"  the new arm: {len(comp.new_jobs)} episodes (the study's grid x seeds)",
        f"  verification: {sampled} committed episodes rerun ({len(comp.sample)} study arms: "
        f"{', '.join(comp.sample)})",
    ]
    for arm, n in missing.items():
        what = "rerun (--rerun-baselines)" if rerun_baselines else "refused without --rerun-baselines"
        lines.append(f"  {arm}: {n} episodes not in the committed run: {what}")
    taken = sum(len(j) for a, j in comp.study_jobs.items() if a not in missing)
    lines.append(f"  from the committed run: {taken} episodes")
    lines += estimate_lines(est, out, workers) if est.episodes else [f"nothing to run: {out} holds them all"]
    return [*lines, "dry run: nothing written"]
