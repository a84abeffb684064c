"""``peg-sim sweep``: run (or resume) an experiment, a grid of episodes, in parallel."""

from __future__ import annotations

import argparse
from pathlib import Path

from peg_ctrl.cli.common import add_out, add_set
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import prepare_output_dir


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
    out = prepare_output_dir(args.out if args.out else Path("runs") / exp.name)
    # run_sweep locks out (Python callers get the same protection)
    rows = run_sweep(exp, out, workers=workers, backend=args.backend, address=args.address)
    wins = sum(r["status"] == "success" for r in rows)
    print(f"{exp.name}: {wins}/{len(rows)} episodes inserted; wrote {out / 'report.md'}")
    return 0


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
