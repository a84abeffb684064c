"""``peg-sim``: the command-line entry point.

User mistakes end with a one-line ``peg-sim: error: ...`` on stderr and exit code 2, never a
traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = ["main"]

_PENDING = {
    "run": "run one autonomous episode headless (state machine, planners, logs, plot, video)",
    "teleop": "drive the gripper from the keyboard in a MuJoCo viewer window",
    "sweep": "run an experiment file: controllers x seeds x randomisation, in parallel",
}


class UsageError(Exception):
    """A mistake in the user's input; reported in one line with exit code 2."""


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
            f"solve median {r['solve_time_us_median']:.1f} us (p99 {r['solve_time_us_p99']:.1f} us)"
        )
    print(f"wrote {args.out}")
    return 0


def _pending(name: str) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        raise UsageError(f"'{name}' is not available in this version yet")

    return run


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="peg-sim", description="Peg-in-hole simulation and controller research in MuJoCo."
    )
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
    p.set_defaults(func=_cmd_bench)

    for name, text in _PENDING.items():
        p = sub.add_parser(name, help=f"{text} (coming in a later version)")
        p.set_defaults(func=_pending(name))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (UsageError, ValueError, FileNotFoundError) as exc:
        print(f"peg-sim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("peg-sim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
