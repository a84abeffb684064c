"""``peg-sim sweep``: run (or resume) an experiment, a grid of episodes, in parallel.

``--dry-run`` prints the sweep's size, its breakdown and an estimate of its wall time
(:mod:`peg_ctrl.experiments.estimate`) and writes nothing. A sweep of more than
:data:`MAX_EPISODES` episodes, or estimated to take more than :data:`MAX_WALL_S`, is refused
unless ``--yes`` is given, before anything is written.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from peg_ctrl.cli.common import add_out, add_set
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import check_output_dir, prepare_output_dir

if TYPE_CHECKING:
    from peg_ctrl.experiments.config import ExperimentConfig
    from peg_ctrl.experiments.estimate import Estimate, SweepSize

#: A sweep of more episodes than this needs ``--yes``.
MAX_EPISODES = 20_000
#: ... and so does one whose estimated wall time (the upper end of its range) is longer [s].
MAX_WALL_S = 24 * 3600.0


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``sweep`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "sweep",
        help="run an experiment (a grid of episodes) in parallel",
        description="Run or resume an experiment (controllers x planners x clearances x seeds); writes "
        "DIR/episodes.csv, .parquet, summary.csv, report.md and plots. Rerunning the same command "
        "skips finished episodes.",
    )
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument(
        "config",
        nargs="?",
        help="experiment file (.yaml, .toml or .json), or the name of a shipped one (e.g. quick)",
    )
    what.add_argument("--list", action="store_true", help="list the shipped experiments and exit")
    add_out(p, help="output directory (default runs/<experiment name>)")
    p.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    p.add_argument("--backend", choices=["local", "ray"], default="local", help="local process pool or Ray")
    p.add_argument("--address", help="Ray cluster address (with --backend ray)")
    add_set(p, "experiment")
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the number of episodes, their breakdown, how many are done in --out and an "
        "estimated wall time; write nothing",
    )
    p.add_argument(
        "--yes",
        action="store_true",
        help=f"run a sweep above {MAX_EPISODES:,} episodes or {MAX_WALL_S / 3600:g} h estimated "
        "(refused without it)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """List the shipped experiments, or run one and print how many episodes inserted."""
    if args.list:
        shipped = shipped_experiments()
        width = max((len(name) for name in shipped), default=0)
        for name, path in shipped.items():
            print(f"{name:<{width}}  {_description(path)}")
        return 0

    path = resolve_experiment(args.config)
    from peg_ctrl.config import read_mapping
    from peg_ctrl.experiments.config import apply_experiment_overrides, experiment_from_mapping
    from peg_ctrl.experiments.runner import run_sweep
    from peg_ctrl.run.batch import default_workers

    data = apply_experiment_overrides(read_mapping(path), args.set or [])
    exp = experiment_from_mapping(data, default_name=path.stem)
    workers = args.workers if args.workers is not None else default_workers()
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    out = Path(args.out) if args.out else Path("runs") / exp.name
    if args.dry_run or not args.yes:
        # Counted and estimated before anything is written (a huge sweep is refused here).
        size, est = _size_and_estimate(exp, out, workers, args.backend)
        if args.dry_run:
            print("\n".join(describe(size, est, out, workers)))
            return 0
        if size.episodes > MAX_EPISODES or est.high_s > MAX_WALL_S:
            raise ConfigError(
                f"sweep {exp.name}: {size.episodes:,} episodes, estimated {_span(est)} with "
                f"{_workers(est, workers)}: more than {MAX_EPISODES:,} episodes or "
                f"{MAX_WALL_S / 3600:g} h; pass --yes to run it anyway (or --dry-run to see the breakdown)"
            )
    out = prepare_output_dir(out)
    # run_sweep locks out (Python callers get the same protection)
    rows = run_sweep(exp, out, workers=workers, backend=args.backend, address=args.address)
    wins = sum(r["status"] == "success" for r in rows)
    print(f"{exp.name}: {wins}/{len(rows)} episodes inserted; wrote {out / 'report.md'}")
    return 0


def _size_and_estimate(
    exp: ExperimentConfig, out: Path, workers: int, backend: str
) -> tuple[SweepSize, Estimate]:
    """The sweep's size and estimated wall time; the episodes finished in ``out`` (when it holds
    this experiment) are not counted as work. Creates nothing.

    Raises:
        OutputError: a file stands where ``out`` would be.
        ConfigError: ``out`` holds another experiment's results (the sweep would refuse it).
    """
    from peg_ctrl.experiments.estimate import estimate, sweep_size
    from peg_ctrl.experiments.runner import check_same_experiment, finished_summaries
    from peg_ctrl.run.batch import default_workers

    check_output_dir(out)
    done: dict[str, dict[str, Any]] = {}
    if out.is_dir():
        check_same_experiment(out, exp)
        done = finished_summaries(out)
    size = sweep_size(exp)
    cores = default_workers() if backend == "local" else None
    return size, estimate(size, workers=workers, cores=cores, done=done)


def describe(size: SweepSize, est: Estimate, out: Path, workers: int) -> list[str]:
    """``--dry-run``'s lines: the size and its breakdown, what ``out`` holds, the estimate with
    ``workers`` and what it is based on."""
    lines = _breakdown(size)
    done = size.episodes - est.episodes
    if not out.exists():
        where = f"{out} does not exist yet"
    elif done == size.episodes:
        where = f"{out} holds all {done:,} episodes, finished"
    elif done:
        where = f"{out} holds {done:,} finished episodes: the sweep resumes"
    else:
        where = f"{out} holds no finished episode"
    lines.append(f"  {where}; {est.episodes:,} to run")
    if est.episodes == 0:
        lines.append("nothing to run: the sweep would only redraw its tables and report")
    else:
        lines += estimate_lines(est, out, workers)
    return [*lines, "dry run: nothing written"]


def _breakdown(size: SweepSize) -> list[str]:
    """The episode count as a product, and each of its factors."""
    product = " x ".join(f"{n:,} {what if n != 1 else what[:-1]}" for n, what in size.factors())
    lines = [f"{size.name}: {size.episodes:,} episodes = {product}"]
    lines.append(f"  arms ({len(size.arms)}): {_listing(size.arms)}")
    if size.axes:
        lines.append(f"  cells ({size.cells:,}) = " + " x ".join(axis.name for axis in size.axes))
        for axis in size.axes:
            keys = "" if axis.keys == (axis.name,) else f" = {', '.join(axis.keys)}"
            levels = [_value(v[0]) if len(v) == 1 else f"({', '.join(map(_value, v))})" for v in axis.levels]
            lines.append(f"    {axis.name}{keys} ({len(levels)}): {_listing(levels)}")
    else:
        lines.append("  cells (1): no grid")
    lines.append(f"  seeds ({len(size.seeds):,}): {_seeds(size.seeds)}")
    lines.append(
        f"  planners ({len(size.planners)}): {_listing(size.planners)}; "
        f"clearances ({len(size.clearances)}): {_listing([f'{c:g} m' for c in size.clearances])}"
    )
    return lines


def estimate_lines(est: Estimate, out: Path, workers: int) -> list[str]:
    """The estimate, its parts (one per controller, task and profile) and its sources."""
    from peg_ctrl.experiments.estimate import EPISODE_OVERHEAD_S

    worst = f" (at most {_about(est.worst_s)} if every episode ran to its time limit)"
    lines = [
        f"estimated wall time with {_workers(est, workers)}: {_span(est)}"
        + (worst if est.worst_s > 1.1 * est.high_s else ""),
        "  per controller, one worker's time: episodes x (wall s per simulated s x simulated s "
        f"per episode (its limit) + {EPISODE_OVERHEAD_S:g} s to set up and write); measured in",
    ]
    parts = [p for p in est.parts if p.episodes]
    width = max(len(p.controller) for p in parts)
    for part in parts:
        where = ", ".join("measured here" if s == "here" else s for s in part.sources)
        lines.append(
            f"    {part.controller:<{width}} {part.task}/{part.physics}: {part.episodes:,} x "
            f"{_range(part.wall_per_sim, '{:.2g}')} x {_range(part.sim_s, '{:.3g}')} s "
            f"({part.limit_s:g} s) = {_range((part.low_s, part.high_s), _about)}; "
            + (f"{part.note} ({where})" if part.note else where)
        )
    lines.append("  based on measured runs:")
    if any("here" in p.sources for p in parts):
        lines.append(f"    measured here: the finished episodes in {out} (this machine)")
    lines += [f"    {name}: {text}" for name, text in est.sources.items()]
    lines.append("  another machine, or a busy one, is slower or faster in proportion")
    return lines


def _workers(est: Estimate, asked: int) -> str:
    if asked and asked != est.parallel:
        return f"{asked} workers ({est.parallel} at once)"
    return f"{est.parallel} worker" + ("s" if est.parallel != 1 else "")


def _about(seconds: float) -> str:
    """A rough duration: ``40 s``, ``34 min``, ``2.5 h``, ``3.1 days``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 48 * 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def _span(est: Estimate) -> str:
    """The estimate's range, or one value when its ends round alike."""
    low, high = _about(est.low_s), _about(est.high_s)
    return low if low == high else f"{low} to {high}"


def _range(pair: tuple[float, float], fmt: Any) -> str:
    def show(x: float) -> str:
        return str(fmt(x) if callable(fmt) else fmt.format(x))

    low, high = show(pair[0]), show(pair[1])
    return low if low == high else f"{low}-{high}"


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return json.dumps(v) if isinstance(v, (list, dict)) else str(v)


def _listing(items: Sequence[str], most: int = 12) -> str:
    """``a, b, c``; a long list as its first and last items around ``...``."""
    items = list(items)
    if len(items) > most:
        items = [*items[: most - 2], "...", items[-1]]
    return ", ".join(items)


def _seeds(seeds: Sequence[int]) -> str:
    if len(seeds) > 2 and list(seeds) == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}..{seeds[-1]}"
    return _listing([str(s) for s in seeds])


def shipped_experiments() -> dict[str, Path]:
    """The experiment files installed with the package (``peg_ctrl/experiments/configs``), by name."""
    from importlib import resources

    root = resources.files("peg_ctrl.experiments") / "configs"
    found = {}
    for entry in root.iterdir():
        if entry.name.endswith((".yaml", ".yml", ".toml", ".json")) and entry.is_file():
            found[entry.name.rsplit(".", 1)[0]] = Path(str(entry))
    return dict(sorted(found.items()))


def _description(path: Path) -> str:
    """An experiment file's leading comment block, joined into one line."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("#").strip())
    return " ".join(part for part in lines if part) or "(no description)"


def resolve_experiment(config: str) -> Path:
    """A path to an experiment file, or the name of a shipped one (``quick``)."""
    path = Path(config)
    if path.exists():
        return path
    shipped = shipped_experiments()
    if config in shipped:
        return shipped[config]
    raise ConfigError(
        f"experiment file {config!r} does not exist, and no shipped experiment has that name; "
        f"shipped: {', '.join(shipped) or '(none)'} (see peg-sim sweep --list)"
    )
