"""``peg-sim teleop``: drive the gripper from the keyboard (or a scripted insertion, headless)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from peg_ctrl.cli.common import (
    CONTROLLERS,
    EXIT_FAILED,
    add_known,
    add_out,
    add_set,
    episode_mapping,
    require_display,
)
from peg_ctrl.errors import ConfigError
from peg_ctrl.io import lock_output_dir, prepare_output_dir

if TYPE_CHECKING:
    from peg_ctrl.run.episode import EpisodeConfig

# The episode config fields that teleop's --set may change: the task is teleoperation (its own
# targets, limits and insertion check, no domain draws), and the start pose is --seed/--randomize's.
_TELEOP_SET_FIELDS = ("controller", "physics", "scene")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``teleop`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "teleop",
        help="drive the gripper from the keyboard",
        description="Teleoperation in a window (--scripted: a scripted insertion, headless). Writes "
        "DIR/summary.json (the fields of 'peg-sim run' plus attempts and end), DIR/log.jsonl and "
        "DIR/forces.npz. Keys: 4/5 +Y/-Y, 6/7 +X/-X, 8/9 +Z/-Z, Q/E roll, Up/Down pitch, "
        "Left/Right yaw, [ / ] jaw open/close, Shift fine motion, J/K/L speed 0.5x/1x/2x, -/= speed "
        "down/up, Z reset, Esc quit. Mouse: left-drag rotate, right-drag move, scroll zoom. "
        "--set takes the controller, physics profile and scene fields of 'peg-sim run' (default: seed "
        "physics); DIR/config.json and the summary record what the session ran. Exit code 0 when "
        "the session ends with the peg inserted, 1 when it ends without, 2 on bad input.",
    )
    add_known(
        p, "--controller", CONTROLLERS, "controller: %(choices)s (default pd, or --set controller.name's)"
    )
    p.add_argument(
        "--seed",
        type=int,
        help="random seed of the peg's start pose (default 0; only with --randomize)",
    )
    p.add_argument("--randomize", action="store_true", help="randomise the peg's start pose (and on reset)")
    p.add_argument("--speed", type=float, default=1.0, help="initial speed multiplier, 0.1 to 5 (default 1)")
    add_out(p, "runs/teleop")
    p.add_argument("--screenshot", help="save the last frame (with overlay) to this PNG on exit")
    p.add_argument("--scripted", action="store_true", help="run a scripted insertion headless (no window)")
    add_set(
        p,
        help="set a controller.*, physics.* or scene.* field of the session by dotted path, value "
        "parsed as YAML (repeatable), e.g. --set physics.profile=precision "
        "--set scene.assets.clearance=1e-4 --set controller.kp_pos=[2000,2000,2000]",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check the arguments, run the session and print how it ended; exit code 0 when it ended
    with the peg inserted, 1 when not (as ``run`` for a failed episode)."""
    from peg_ctrl.teleop import SPEED_RANGE

    lo, hi = SPEED_RANGE
    if not lo <= args.speed <= hi:
        raise ConfigError(f"--speed must be in [{lo}, {hi}], got {args.speed}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.seed is not None and not args.randomize:
        raise ConfigError("--seed only changes the peg's start pose with --randomize; add --randomize")
    cfg = _config(args)
    if not args.scripted:
        require_display("teleop", "use --scripted to run headless")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        summary = _session(args, cfg, out)
    inserted = "inserted" if summary["status"] == "success" else "not inserted"
    print(
        f"teleop ended ({summary['end']}): {inserted}, {summary['total_timesteps']} steps, "
        f"{summary['attempts']} attempt(s); wrote {out / 'summary.json'}"
    )
    return 0 if summary["status"] == "success" else EXIT_FAILED


def _config(args: argparse.Namespace) -> EpisodeConfig:
    """A teleop session's simulation as an episode config (``--set``, then ``--controller``,
    ``--seed``, ``--randomize``), checked as ``run`` checks one, before anything is written."""
    from peg_ctrl.run.episode import episode_config_from_mapping

    data = episode_mapping(args)
    allowed = ", ".join(f"{name}.*" for name in _TELEOP_SET_FIELDS)
    for item in args.set or []:
        key = item.partition("=")[0].strip()
        if key.split(".")[0] not in _TELEOP_SET_FIELDS:
            raise ConfigError(
                f"--set {key}: not a teleop setting; teleop takes {allowed} "
                "(the start pose: --seed and --randomize)"
            )
    data["seed"] = args.seed if args.seed is not None else 0
    data["randomization"] = {"enabled": args.randomize}
    return episode_config_from_mapping(data)  # refuses a control period the timestep does not divide


def _session(args: argparse.Namespace, cfg: EpisodeConfig, out: Path) -> dict[str, Any]:
    """A teleop session of ``cfg`` (see :func:`_config`) in the (locked) directory ``out``;
    returns its summary."""
    from peg_ctrl.teleop import SCRIPTED_INSERTION, ScriptedOperator, TeleopSession

    session = TeleopSession(
        out,
        controller=cfg.controller,
        seed=cfg.seed,
        randomize=args.randomize,
        scene=cfg.scene,
        physics=cfg.physics,
    )
    session.mapper.set_speed(args.speed)
    if args.scripted:
        try:
            ScriptedOperator(session, SCRIPTED_INSERTION).run(max_sim_s=120.0)
        except KeyboardInterrupt:
            session.finish("interrupted")  # keep the records so far; main() exits with 130
            raise
        return session.finish("script_done")
    from peg_ctrl.cli.teleop_window import WindowUnavailable, run_window

    try:
        return run_window(session, screenshot=Path(args.screenshot) if args.screenshot else None)
    except WindowUnavailable:
        session.finish("no_window")
        raise
