"""``peg-sim``: the command-line entry point.

User mistakes end with a one-line ``peg-sim: error: ...`` on stderr and exit code 2, never a
traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

__all__ = ["main"]

_PENDING: dict[str, str] = {}


class UsageError(Exception):
    """A mistake in the user's input; reported in one line with exit code 2."""


class _Parser(argparse.ArgumentParser):
    """Argument errors in one line (``peg-sim: error: ...``), exit code 2; ``--help`` for usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"peg-sim: error: {message} (see '{self.prog} --help')\n")


def _cmd_model(args: argparse.Namespace) -> int:
    from peg_ctrl.scene import export_scene

    path = export_scene(Path(args.out))
    print(f"wrote {path} (open it with: python -m mujoco.viewer --mjcf={path})")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from peg_ctrl import jaw
    from peg_ctrl.scene import build_model

    if args.samples < 4:
        raise UsageError(f"--samples must be >= 4, got {args.samples}")
    cal = jaw.calibrate(build_model(), n_samples=args.samples, n_knots=max(2, args.samples // 2 + 1))
    out = Path(args.out) if args.out else jaw.DEFAULT_PATH
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(cal.to_json() + "\n")
    print(
        f"jaw calibration: {len(cal.bytes_)} knots, open {cal.sep_open_m * 1e3:.2f} mm, "
        f"closed {cal.sep_closed_m * 1e3:.2f} mm, max fit error {cal.fit_max_error_m * 1e3:.3f} mm "
        f"-> {out}"
    )
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from controllers import REGISTRY
    from peg_ctrl.bench import run_benchmarks

    names = args.controller or sorted(REGISTRY)
    unknown = [n for n in names if n not in REGISTRY]
    if unknown:
        raise UsageError(f"unknown controller {unknown[0]!r}; known: {', '.join(sorted(REGISTRY))}")
    if args.steps < 100 or args.repeats < 1:
        raise UsageError(f"--steps must be >= 100 and --repeats >= 1, got {args.steps}, {args.repeats}")
    for dt in args.control_dt or []:
        if not dt > 0:
            raise UsageError(f"--control-dt must be > 0 s, got {dt}")
    if args.sweep:
        import json

        from experiments.runner import bench_sweep

        result = bench_sweep(args.sweep_episodes)
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=2) + "\n")
        print(
            f"sweep of {result['episodes']} episodes: 1 worker {result['wall_s']['1']:.1f} s, "
            f"2 workers {result['wall_s']['2']:.1f} s, speedup {result['speedup_2_vs_1']:.2f}x; wrote {out}"
        )
        return 0
    results = run_benchmarks(
        Path(args.out),
        controllers=names,
        n_steps=args.steps,
        repeats=args.repeats,
        control_dts=args.control_dt or None,
    )
    for r in results["controllers"]:
        print(
            f"{r['controller']:>10} @ {1e6 / r['control_period_us']:5.0f} Hz: "
            f"physics {r['raw_step_us_median']:.1f} us/step, with controller "
            f"{r['loop_step_us_median']:.1f} us/step, overhead {100 * r['overhead_ratio']:+.1f} %, "
            f"solve median {r['solver_call_us_median']:.1f} us (p99 {r['solver_call_us_p99']:.1f} us, "
            f"period {r['solver_period_us']:.0f} us)"
        )
    for e in results["episodes"]:
        print(
            f"{e['controller']:>10} episode: physics {e['raw_step_us_median']:.1f} us/step, loop "
            f"{e['episode_step_us_median']:.1f} us/step, overhead {100 * e['overhead_ratio']:+.1f} % "
            f"(logging {100 * e['logging_share_of_overhead']:.0f} % of it)"
        )
    print(f"wrote {args.out}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from peg_ctrl.config import read_mapping
    from peg_ctrl.episode import episode_config_from_mapping, run_episode

    data = read_mapping(Path(args.config)) if args.config else {}
    # Command-line flags override the file.
    if args.controller is not None:
        ctrl = data.get("controller")
        if isinstance(ctrl, dict) and ctrl.get("name", args.controller) == args.controller:
            data["controller"] = {**ctrl, "name": args.controller}
        else:
            data["controller"] = {"name": args.controller}
    if args.planner is not None:
        data["planner"] = args.planner
    if args.seed is not None:
        data["seed"] = args.seed
    if args.randomize:
        data["randomization"] = {**data.get("randomization", {}), "enabled": True}
    if args.max_steps is not None:
        data["max_steps"] = args.max_steps
    cfg = episode_config_from_mapping(data)
    out = Path(args.out)
    if args.viewer:
        result = _run_with_viewer(cfg, out)
    else:
        result = run_episode(cfg, out, video=args.video)
    print(result.one_line())
    print(f"wrote {out / 'summary.json'}")
    return 0 if result.status == "success" else 1


def _run_with_viewer(cfg, out: Path):  # type: ignore[no-untyped-def]
    import time

    import mujoco.viewer

    from peg_ctrl.episode import run_episode

    handle: dict[str, object] = {}
    wall0 = time.perf_counter()

    def sync(model, data) -> None:  # type: ignore[no-untyped-def]
        viewer = handle.get("viewer")
        if viewer is None:
            viewer = mujoco.viewer.launch_passive(model, data)
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


SCRIPTED_INSERTION = (
    ("z", 0.020),
    ("jaw", 0.0),
    ("wait", 0.8),
    ("z", 0.15),
    ("roll", 1.5707963267948966),
    ("wait", 0.5),
    ("align", None),
    ("wait", 0.5),
    ("align", None),
    ("z", 0.09),
    ("jaw", 0.085),
    ("wait", 2.0),
)


def _cmd_teleop(args: argparse.Namespace) -> int:
    from peg_ctrl.teleop import SPEED_RANGE, ScriptedOperator, TeleopSession

    lo, hi = SPEED_RANGE
    if not lo <= args.speed <= hi:
        raise UsageError(f"--speed must be in [{lo}, {hi}], got {args.speed}")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    if not args.scripted and not os.environ.get("DISPLAY"):
        raise UsageError("teleop needs a display (DISPLAY is not set); use --scripted to run headless")
    from controllers import REGISTRY

    if args.controller not in REGISTRY:
        raise UsageError(f"unknown controller {args.controller!r}; known: {', '.join(sorted(REGISTRY))}")
    session = TeleopSession(
        Path(args.out), controller=args.controller, seed=args.seed, randomize=args.randomize
    )
    session.mapper.set_speed(args.speed)
    if args.scripted:
        ScriptedOperator(session, SCRIPTED_INSERTION).run(max_sim_s=120.0)
        summary = session.finish("script_done")
    else:
        from peg_ctrl.teleop_window import WindowUnavailable, run_window

        try:
            summary = run_window(session, screenshot=Path(args.screenshot) if args.screenshot else None)
        except WindowUnavailable as exc:
            session.finish("no_window")
            raise UsageError(str(exc)) from None
    inserted = "inserted" if summary["status"] == "success" else "not inserted"
    print(
        f"teleop ended ({summary['end']}): {inserted}, {summary['total_timesteps']} steps, "
        f"{summary['attempts']} attempt(s); wrote {Path(args.out) / 'summary.json'}"
    )
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from experiments.config import load_experiment
    from experiments.runner import run_sweep
    from peg_ctrl.batch import default_workers

    exp = load_experiment(Path(args.config))
    workers = args.workers or default_workers()
    if workers < 1:
        raise UsageError(f"--workers must be >= 1, got {workers}")
    out = Path(args.out) if args.out else Path("runs") / exp.name
    rows = run_sweep(exp, out, workers=workers, backend=args.backend, address=args.address)
    wins = sum(r["status"] == "success" for r in rows)
    print(f"{exp.name}: {wins}/{len(rows)} episodes inserted; wrote {out / 'report.md'}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from experiments.report import write_report

    out = Path(args.dir)
    if not (out / "episodes.csv").is_file():
        raise UsageError(f"{out} has no episodes.csv (run peg-sim sweep first)")
    print(f"wrote {write_report(out)}")
    return 0


def _pending(name: str) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        raise UsageError(f"'{name}' is not available in this version yet")

    return run


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="peg-sim", description="Peg-in-hole simulation and controller research in MuJoCo.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("model", help="write the compiled scene as scene.xml plus meshes")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=_cmd_model)

    p = sub.add_parser("calibrate", help="measure the jaw byte <-> pad separation map and save it")
    p.add_argument("--out", help="output JSON (default: the packaged calibration)")
    p.add_argument("--samples", type=int, default=103, help="bytes swept over 0..255 (default 103)")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("bench", help="controller overhead over raw physics, written to JSON")
    p.add_argument("--out", default="bench.json", help="output JSON (default bench.json)")
    p.add_argument("--controller", action="append", help="controller to bench (repeatable; default all)")
    p.add_argument("--steps", type=int, default=3000, help="physics steps per repetition")
    p.add_argument("--repeats", type=int, default=7, help="alternating repetitions (median taken)")
    p.add_argument(
        "--control-dt",
        type=float,
        action="append",
        help="control period in s to bench (repeatable; default: each controller's own)",
    )
    p.add_argument("--sweep", action="store_true", help="instead: sweep speedup of 2 workers over 1")
    p.add_argument("--sweep-episodes", type=int, default=6, help="episodes per sweep timing (default 6)")
    p.set_defaults(func=_cmd_bench)

    p = sub.add_parser(
        "run",
        help="run one autonomous episode headless: summary, logs, force plot (and video)",
        description="Run one autonomous episode (grasp, lift, turn, align, release, settle) and write "
        "DIR/summary.json, DIR/log.jsonl, DIR/forces.npz, DIR/force_profile.png (and DIR/episode.mp4). "
        "Exit code 0 on success, 1 on a failed episode, 2 on bad input.",
    )
    p.add_argument("--controller", help="controller name (default pd, or the config file's)")
    p.add_argument("--planner", help="ruckig (default) or fixed_speed")
    p.add_argument("--seed", type=int, help="random seed for the initial conditions (default 0)")
    p.add_argument("--randomize", action="store_true", help="randomise the peg's start pose from the seed")
    p.add_argument("--max-steps", type=int, help="physics step limit (default 20000)")
    p.add_argument("--out", default="runs/episode", help="output directory (default runs/episode)")
    p.add_argument("--video", action="store_true", help="also render DIR/episode.mp4 offscreen")
    p.add_argument("--viewer", action="store_true", help="show the episode in the MuJoCo viewer instead")
    p.add_argument("--config", help="episode config file (.yaml, .toml or .json)")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "teleop",
        help="drive the gripper from the keyboard in a window (or --scripted, headless)",
        description="Teleoperation. Keys: 4/5 +Y/-Y, 6/7 +X/-X, 8/9 +Z/-Z, Q/E roll, Up/Down pitch, "
        "Left/Right yaw, [ / ] jaw open/close, Shift fine motion, J/K/L speed 0.5x/1x/2x, -/= speed "
        "down/up, Z reset, Esc quit. Mouse: left-drag rotate, right-drag move, scroll zoom.",
    )
    p.add_argument("--controller", default="pd", help="controller name (default pd)")
    p.add_argument("--seed", type=int, default=0, help="random seed for the peg's start pose")
    p.add_argument("--randomize", action="store_true", help="randomise the peg's start pose (and on reset)")
    p.add_argument("--speed", type=float, default=1.0, help="initial speed multiplier, 0.1 to 5 (default 1)")
    p.add_argument("--out", default="runs/teleop", help="output directory (default runs/teleop)")
    p.add_argument("--screenshot", help="save the last frame (with overlay) to this PNG on exit")
    p.add_argument("--scripted", action="store_true", help="run a scripted insertion headless (no window)")
    p.set_defaults(func=_cmd_teleop)

    p = sub.add_parser(
        "sweep",
        help="run an experiment file (controllers x planners x clearances x seeds) in parallel",
        description="Run or resume an experiment; writes DIR/episodes.csv, .parquet, summary.csv, "
        "report.md and plots. Rerunning the same command skips finished episodes.",
    )
    p.add_argument(
        "config", help="experiment file (.yaml, .toml or .json), e.g. experiments/configs/quick.yaml"
    )
    p.add_argument("--out", help="output directory (default runs/<experiment name>)")
    p.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    p.add_argument("--backend", choices=["local", "ray"], default="local", help="local process pool or Ray")
    p.add_argument("--address", help="Ray cluster address (with --backend ray)")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser("plot", help="redraw the plots and report.md of a sweep from its saved results")
    p.add_argument("dir", help="a sweep's output directory")
    p.set_defaults(func=_cmd_plot)

    for name, text in _PENDING.items():
        p = sub.add_parser(name, help=f"{text} (coming in a later version)")
        p.set_defaults(func=_pending(name))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if not os.environ.get("DISPLAY") and not getattr(args, "viewer", False):
        # Offscreen rendering without a window system; must be set before mujoco is imported.
        os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        return int(args.func(args))
    except (UsageError, ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"peg-sim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("peg-sim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
