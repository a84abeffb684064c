"""``peg-sim run``: one autonomous episode, headless (or in the MuJoCo viewer)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from peg_ctrl.cli.common import (
    CONTROLLERS,
    EXIT_FAILED,
    PLANNERS,
    add_config,
    add_known,
    add_out,
    add_set,
    episode_mapping,
    require_display,
)
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir, prepare_output_dir

if TYPE_CHECKING:
    from peg_ctrl.run.episode import EpisodeConfig, EpisodeResult


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``run`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "run",
        help="run one autonomous episode headless",
        description="Run one autonomous episode (grasp, lift, turn, align, release, settle) and write "
        "DIR/summary.json, DIR/log.jsonl, DIR/forces.npz, DIR/force_profile.png (and DIR/episode.mp4). "
        "Exit code 0 on success, 1 on a failed episode, 2 on bad input.",
    )
    add_known(
        p,
        "--controller",
        CONTROLLERS,
        "controller: %(choices)s (default pd, or --set controller.name's, or the config file's; the "
        "file's controller fields are kept only for its own controller, --set controller.* always)",
    )
    add_known(p, "--planner", PLANNERS, "planner: %(choices)s (default ruckig, or the config file's)")
    p.add_argument(
        "--seed",
        type=int,
        help="random seed (default 0) of the start pose (with --randomize), the domain draw and "
        "sensor noise; refused when the episode would not depend on it",
    )
    p.add_argument("--randomize", action="store_true", help="randomise the peg's start pose from the seed")
    p.add_argument(
        "--max-steps",
        type=int,
        help="physics step limit (default: 20 s of simulated time, 20000 steps in the seed profile)",
    )
    add_out(p, "runs/episode")
    p.add_argument("--video", action="store_true", help="also render DIR/episode.mp4 offscreen")
    p.add_argument("--viewer", action="store_true", help="show the episode in the MuJoCo viewer instead")
    add_config(p)
    add_set(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the episode; exit code 0 when it inserted, 1 when it failed."""
    from peg_ctrl.run.episode import run_episode

    cfg = _config(args)
    if args.viewer:  # refused before anything is written
        require_display("--viewer", "run without it, or with --video")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        if args.viewer:
            result = _run_with_viewer(cfg, out)
        else:
            result = run_episode(cfg, out, video=args.video)
    print(result.one_line())
    print(f"wrote {out / 'summary.json'}")
    return 0 if result.status == "success" else EXIT_FAILED


def _config(args: argparse.Namespace) -> EpisodeConfig:
    """The episode config: the file, ``--set``, then the named flags, which override both
    (``--controller`` as :func:`~peg_ctrl.cli.common.merge_controller` says)."""
    from peg_ctrl.run.episode import episode_config_from_mapping

    data = episode_mapping(args)
    if args.planner is not None:
        data["planner"] = args.planner
    if args.seed is not None:
        data["seed"] = args.seed
    if args.randomize:
        data["randomization"] = {**data.get("randomization", {}), "enabled": True}
    if args.max_steps is not None:
        data["max_steps"] = args.max_steps
    cfg = episode_config_from_mapping(data)
    if args.seed is not None and not cfg.seeded:
        # Refused rather than ignored: a loop over --seed would silently run one episode N times.
        raise ConfigError(
            "--seed has no effect here: the start pose is drawn only with --randomize (or "
            "randomization.enabled in the config) and the config's domain has no ranges or noise; "
            "add --randomize"
        )
    return cfg


def _run_with_viewer(cfg: EpisodeConfig, out: Path) -> EpisodeResult:
    """The episode in a passive MuJoCo viewer, paced to real time; closing the window ends it."""
    import time

    from peg_ctrl.run.episode import run_episode
    from peg_ctrl.sim.gl import PassiveViewer

    handle: dict[str, object] = {}
    wall0 = time.perf_counter()

    def sync(model, data) -> None:  # type: ignore[no-untyped-def]
        viewer = handle.get("viewer")
        if viewer is None:
            viewer = PassiveViewer(model, data)  # Triton first, a close that waits (peg_ctrl.sim.gl)
            handle["viewer"] = viewer
        if not viewer.is_running():  # type: ignore[attr-defined]
            raise KeyboardInterrupt
        viewer.sync()  # type: ignore[attr-defined]
        lag = data.time - (time.perf_counter() - wall0)
        if lag > 0:
            time.sleep(lag)  # real-time pacing

    try:
        return run_episode(cfg, out, on_step=sync)
    finally:
        viewer = handle.get("viewer")
        if viewer is not None:
            viewer.close()  # type: ignore[attr-defined]
