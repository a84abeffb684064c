"""``peg-sim replay``: replay a recorded episode to a video, or in the viewer."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``replay`` to the ``peg-sim`` subcommands."""
    p = sub.add_parser(
        "replay",
        help="replay a logged episode to a video, or in the viewer",
        description="Replay the episode recorded in RUN_DIR (its config.json and states.npz, written by "
        "peg-sim run): kinematically, from the recorded states. Writes RUN_DIR/replay.mp4 (or --video), "
        "or shows it in the MuJoCo viewer with --viewer (needs a display).",
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="an episode's output directory (peg-sim run --out)")
    p.add_argument("--video", metavar="OUT.mp4", help="the video to write (default RUN_DIR/replay.mp4)")
    p.add_argument("--viewer", action="store_true", help="show the replay in the MuJoCo viewer instead")
    p.add_argument(
        "--figure",
        metavar="OUT.png",
        help="instead of a video, one picture: the frame at --at beside the peg-block force and the "
        "peg's depth against time (needs the run's forces.npz)",
    )
    p.add_argument(
        "--at",
        type=float,
        metavar="T",
        help="the figure's moment [s] (default: the peg halfway to its deepest, else the peak "
        "peg-block force)",
    )
    p.add_argument(
        "--speed", type=float, default=1.0, help="simulated seconds per second of replay (default 1)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Replay the run, or draw its figure."""
    from peg_ctrl.errors import ConfigError
    from peg_ctrl.tools.replay import replay

    if args.figure is None and args.at is not None:
        raise ConfigError("--at is the moment of --figure; give --figure OUT.png too")
    if args.figure is not None:
        if args.video or args.viewer:
            raise ConfigError("--figure draws one picture: not with --video or --viewer")
        from peg_ctrl.tools.figure import insertion_figure

        path, when = insertion_figure(args.run_dir, args.figure, at=args.at)
        print(f"wrote {path} (the frame at {when:.2f} s)")
        return 0

    out = replay(args.run_dir, video=args.video, viewer=args.viewer, speed=args.speed)
    print(f"wrote {out}" if out is not None else "replay ended")
    return 0
