"""``peg-sim``: the command-line entry point (also ``python -m peg_ctrl``).

Exit codes, decided in one place (:func:`main`):

- 0: done (an episode: inserted);
- 1: an episode ran but failed (timeout, force spike, ...);
- 2: the user's or the system's problem: a bad argument or config (every class in
  :data:`peg_ctrl.errors.USER_ERRORS`, and any other :class:`~peg_ctrl.errors.PegCtrlError` that
  is not a simulation error, such as no window system for teleop), or an :class:`OSError` (a
  read-only or full disk, an unusable ``--out``). One line ``peg-sim: error: ...`` on stderr;
- 130: interrupted with Ctrl-C.

Any other exception is a bug and keeps its traceback.

Every command that takes ``--out`` checks it (created, writable) after validating its arguments
and before any work starts. A command that writes a directory (``run``, ``teleop``, ``sweep``,
``validity``, ``validate-profile``, ``plot``) locks it while it works
(:func:`peg_ctrl.io.lock_output_dir`): a second one on the same directory is refused (exit 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from peg_ctrl.errors import (
    USER_ERRORS,
    ConfigError,
    DivergenceError,
    OutputWarning,
    PegCtrlError,
    PlanningError,
    UnknownComponent,
)
from peg_ctrl.io import (
    atomic_write_text,
    lock_output_dir,
    prepare_output_dir,
    prepare_output_file,
    to_json,
)
from peg_ctrl.progress import ENV_VAR

if TYPE_CHECKING:
    from peg_ctrl.episode import EpisodeConfig

__all__ = ["main"]


EXIT_FAILED = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


def _is_user_error(exc: BaseException) -> bool:
    """The user's or the system's doing (exit 2, one line) rather than a bug (traceback)."""
    if isinstance(exc, (*USER_ERRORS, OSError)):
        return True
    return isinstance(exc, PegCtrlError) and not isinstance(exc, (DivergenceError, PlanningError))


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, PegCtrlError) and exc.strerror:
        # "[Errno 28] No space left on device: 'x'" -> "'x': No space left on device"
        where = f"{str(exc.filename)!r}: " if exc.filename is not None else ""
        text = f"{where}{exc.strerror}"
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


class _Parser(argparse.ArgumentParser):
    """Argument errors in one line (``peg-sim: error: ...``), exit code 2; ``--help`` for usage."""

    def error(self, message: str) -> NoReturn:
        """Print ``message`` as one ``peg-sim: error:`` line and exit with code 2."""
        self.exit(2, f"peg-sim: error: {message} (see '{self.prog} --help')\n")


class _Known:
    """The names in one of the package's registries, for an option's ``choices`` (listed in its
    help as ``%(choices)s``) and ``type`` (an unknown name is refused with the known ones).

    The registry is imported on first use, not when the parser is built: ``peg-sim --help``
    stays fast, and :func:`main` picks the GL backend before anything imports mujoco.
    """

    def __init__(self, kind: str, module: str, attr: str) -> None:
        self.kind = kind
        self.module = module
        self.attr = attr

    def names(self) -> list[str]:
        """The registered names, sorted."""
        from importlib import import_module

        return sorted(getattr(import_module(self.module), self.attr))

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __contains__(self, name: object) -> bool:
        return name in self.names()

    def __call__(self, value: str) -> str:
        if value not in self:
            raise argparse.ArgumentTypeError(str(UnknownComponent(self.kind, value, self.names())))
        return value


CONTROLLERS = _Known("controller", "peg_ctrl.controllers", "REGISTRY")
PLANNERS = _Known("planner", "peg_ctrl.planners", "PLANNERS")
PROFILES = _Known("physics profile", "peg_ctrl.physics", "PROFILES")
BENCH_TASKS = _Known("task", "peg_ctrl.bench", "BENCH_TASKS")


def _version() -> str:
    """The installed distribution's version, or ``unknown`` when it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("peg-ctrl")
    except PackageNotFoundError:
        return "unknown (not installed)"


def _episode_mapping(args: argparse.Namespace) -> dict[str, Any]:
    """The episode config's plain data: ``--config`` file, then every ``--set KEY=VALUE``."""
    from peg_ctrl.config import apply_overrides, read_mapping

    data = read_mapping(Path(args.config)) if args.config else {}
    return apply_overrides(data, args.set or [])


def _set_controller(data: dict[str, Any], name: str | None) -> None:
    """Apply a ``--controller NAME`` flag to episode config data: it keeps the controller fields
    of the file and ``--set`` when they are for the same controller, else replaces them."""
    if name is None:
        return
    ctrl = data.get("controller")
    if isinstance(ctrl, dict) and ctrl.get("name", name) == name:
        data["controller"] = {**ctrl, "name": name}
    else:
        data["controller"] = {"name": name}


def _cmd_model(args: argparse.Namespace) -> int:
    from peg_ctrl.episode import episode_config_from_mapping
    from peg_ctrl.scene import export_scene

    cfg = episode_config_from_mapping(_episode_mapping(args))
    path = export_scene(prepare_output_dir(args.out), cfg.scene, cfg.physics.profile)
    print(f"wrote {path} (open it with: python -m mujoco.viewer --mjcf={path})")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from peg_ctrl import jaw
    from peg_ctrl.scene import build_model

    if args.samples < 4:
        raise ConfigError(f"--samples must be >= 4, got {args.samples}")
    if args.replace_packaged:
        target = jaw.source_tree_path()
        if target is None:
            raise ConfigError(
                "--replace-packaged works only in a source checkout: this installed copy's packaged "
                "calibration is read-only; use --out FILE"
            )
    else:
        target = Path(args.out)
    out = prepare_output_file(target)
    cal = jaw.calibrate(
        build_model(), n_samples=args.samples, n_knots=max(2, args.samples // 2 + 1), progress=True
    )
    atomic_write_text(out, cal.to_json() + "\n")
    print(
        f"jaw calibration: {len(cal.bytes_)} knots, open {cal.sep_open_m * 1e3:.2f} mm, "
        f"closed {cal.sep_closed_m * 1e3:.2f} mm, max fit error {cal.fit_max_error_m * 1e3:.3f} mm "
        f"-> {out}"
    )
    return 0


def _print_profiles(result: dict[str, Any]) -> None:
    for r in result["rows"]:
        print(
            f"{r['profile']:>10} {r['situation']:<12}: {r['step_us_median']:7.1f} us/step "
            f"(dt {r['timestep_ms']:g} ms, {r['contacts']} contacts), "
            f"{r['us_per_simulated_ms']:7.1f} us per simulated ms, {r['cost_vs_seed']:.2f}x seed"
        )


def _cmd_bench(args: argparse.Namespace) -> int:
    from peg_ctrl.bench import BENCH_TASKS, TARGET_OVERHEAD, run_benchmarks
    from peg_ctrl.controllers import REGISTRY

    # Controller, task and profile names were checked by the parser (CONTROLLERS, ...).
    names = args.controller or sorted(REGISTRY)
    tasks = args.task or list(BENCH_TASKS)
    if args.repeats < 1:
        raise ConfigError(f"--repeats must be >= 1, got {args.repeats}")
    if args.throughput_episodes < 0:
        raise ConfigError(f"--throughput-episodes must be >= 0, got {args.throughput_episodes}")
    for dt in args.control_dt or []:
        if not dt > 0:
            raise ConfigError(f"--control-dt must be > 0 s, got {dt}")
    if args.sweep_episodes < 1:
        raise ConfigError(f"--sweep-episodes must be >= 1, got {args.sweep_episodes}")
    if sum((args.physics, args.sweep, args.qp)) > 1:
        raise ConfigError("--physics, --sweep and --qp are separate benchmarks; give one")
    if args.control_dt:  # reject a period the physics step does not divide before any work
        from peg_ctrl.physics import PROFILES
        from peg_ctrl.timing import control_decimation

        for dt in args.control_dt:
            control_decimation(dt, PROFILES[args.profile].timestep)
    out = prepare_output_file(args.out)
    if args.qp:
        from peg_ctrl.bench import bench_qp

        result = bench_qp(repeats=args.repeats)
        atomic_write_text(out, to_json(result, indent=2) + "\n")
        for row in result["rows"]:
            print(
                f"{row['qp']:>7} QP  {row['backend']:<18} "
                f"p50 {row['p50_us']:8.1f} us  p99 {row['p99_us']:8.1f} us"
            )
        print(f"wrote {out}")
        return 0
    if args.physics:
        from peg_ctrl.bench import bench_profiles

        result = bench_profiles(repeats=args.repeats)
        atomic_write_text(out, to_json(result, indent=2) + "\n")
        _print_profiles(result)
        print(f"wrote {out}")
        return 0
    if args.sweep:
        from peg_ctrl.experiments.runner import bench_sweep

        result = bench_sweep(args.sweep_episodes)
        atomic_write_text(out, to_json(result, indent=2) + "\n")
        print(
            f"sweep of {result['episodes']} episodes: 1 worker {result['wall_s']['1']:.1f} s, "
            f"2 workers {result['wall_s']['2']:.1f} s, speedup {result['speedup_2_vs_1']:.2f}x; wrote {out}"
        )
        return 0
    results = run_benchmarks(
        out,
        controllers=names,
        tasks=tasks,
        repeats=args.repeats,
        profile=args.profile,
        control_dts=args.control_dt or None,
        throughput=args.throughput_episodes > 0,
        throughput_episodes=args.throughput_episodes,
    )
    print(f"clock: {results['clock']}; {args.repeats} interleaved repeats, median (min)")
    target = f"{100 * TARGET_OVERHEAD:.0f}"
    for r in results["episodes"]:
        c = r["components_us_per_step"]
        k = r["physics_steps_per_control_step"]
        raw, lp, ov = r["raw_us_per_step"], r["loop_us_per_step"], r["overhead"]
        print(
            f"{r['controller']:>10} @ {r['control_hz']:4.0f} Hz, {r['task']}/{r['profile']} ({r['status']}, "
            f"{r['physics_steps']} steps): raw {raw['median']:6.1f} ({raw['min']:6.1f}) us/step, "
            f"loop {lp['median']:6.1f} ({lp['min']:6.1f}), overhead {100 * ov['median']:+5.1f} % "
            f"({100 * ov['min']:+5.1f} %){'' if r['within_target'] else f'  > {target} % target'}\n"
            f"{'':>12}per control step: task {c['task'] * k:5.1f}, controller {c['controller'] * k:5.1f}, "
            f"monitors {c['monitors'] * k:5.1f}, recording {c['recording'] * k:5.1f} us "
            f"(physics {c['physics'] * k:6.1f} us for {k} steps)"
        )
    if results["episodes"]:
        print(
            "overhead = the loop's CPU time / that of a bare mj_step replay of the same controls (the same "
            "trajectory) - 1: the Python per control step split above\n"
            f"target: median <= {target} % ({out.name}: within_target); not met yet (docs/performance.md), "
            "and on a loaded or shared 2-core machine it varies and can read higher; no episode result "
            "depends on it"
        )
    for t in results["throughput"]:
        print(
            f"sweep, {t['task']} task, {t['profile']:>9}: {t['episodes']} episodes on {t['workers']} workers "
            f"in {t['wall_s']:.1f} s wall = {t['episodes_per_hour']:,.0f} episodes/hour"
        )
    print(f"wrote {out}")
    return 0


def _require_display(what: str, instead: str) -> None:
    """A window needs a display: without one, one line naming the alternative (exit 2)."""
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if sys.platform.startswith("linux") and not display:
        raise ConfigError(f"{what} needs a display (DISPLAY is not set); {instead}")


def _cmd_run(args: argparse.Namespace) -> int:
    from peg_ctrl.episode import episode_config_from_mapping, run_episode

    data = _episode_mapping(args)
    # The named flags override the file and --set.
    _set_controller(data, args.controller)
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
    if args.viewer:  # refused before anything is written
        _require_display("--viewer", "run without it, or with --video")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        if args.viewer:
            result = _run_with_viewer(cfg, out)
        else:
            result = run_episode(cfg, out, video=args.video)
    print(result.one_line())
    print(f"wrote {out / 'summary.json'}")
    return 0 if result.status == "success" else EXIT_FAILED


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


def _cmd_teleop(args: argparse.Namespace) -> int:
    from peg_ctrl.teleop import SPEED_RANGE

    lo, hi = SPEED_RANGE
    if not lo <= args.speed <= hi:
        raise ConfigError(f"--speed must be in [{lo}, {hi}], got {args.speed}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.seed is not None and not args.randomize:
        raise ConfigError("--seed only changes the peg's start pose with --randomize; add --randomize")
    cfg = _teleop_config(args)
    if not args.scripted:
        _require_display("teleop", "use --scripted to run headless")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        summary = _teleop(args, cfg, out)
    inserted = "inserted" if summary["status"] == "success" else "not inserted"
    print(
        f"teleop ended ({summary['end']}): {inserted}, {summary['total_timesteps']} steps, "
        f"{summary['attempts']} attempt(s); wrote {out / 'summary.json'}"
    )
    return 0


# The episode config fields that teleop's --set may change: the task is teleoperation (its own
# targets, limits and insertion check, no domain draws), and the start pose is --seed/--randomize's.
_TELEOP_SET_FIELDS = ("controller", "physics", "scene")


def _teleop_config(args: argparse.Namespace) -> EpisodeConfig:
    """A teleop session's simulation as an episode config (``--set``, then ``--controller``,
    ``--seed``, ``--randomize``), checked as ``run`` checks one, before anything is written."""
    from peg_ctrl.config import apply_overrides
    from peg_ctrl.episode import episode_config_from_mapping
    from peg_ctrl.physics import profile
    from peg_ctrl.timing import control_decimation

    data = apply_overrides({}, args.set or [])
    allowed = ", ".join(f"{name}.*" for name in _TELEOP_SET_FIELDS)
    for item in args.set or []:
        key = item.partition("=")[0].strip()
        if key.split(".")[0] not in _TELEOP_SET_FIELDS:
            raise ConfigError(
                f"--set {key}: not a teleop setting; teleop takes {allowed} "
                "(the start pose: --seed and --randomize)"
            )
    _set_controller(data, args.controller)
    data["seed"] = args.seed if args.seed is not None else 0
    data["randomization"] = {"enabled": args.randomize}
    cfg = episode_config_from_mapping(data)
    control_decimation(cfg.controller.control_dt, profile(cfg.physics.profile).timestep)
    return cfg


def _teleop(args: argparse.Namespace, cfg: EpisodeConfig, out: Path) -> dict[str, Any]:
    """A teleop session of ``cfg`` (see :func:`_teleop_config`) in the (locked) directory
    ``out``; returns its summary."""
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
    from peg_ctrl.teleop_window import WindowUnavailable, run_window

    try:
        return run_window(session, screenshot=Path(args.screenshot) if args.screenshot else None)
    except WindowUnavailable:
        session.finish("no_window")
        raise


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


def _resolve_experiment(config: str) -> Path:
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


def _cmd_sweep(args: argparse.Namespace) -> int:
    if args.list:
        shipped = shipped_experiments()
        width = max((len(name) for name in shipped), default=0)
        for name, path in shipped.items():
            print(f"{name:<{width}}  {_description(path)}")
        return 0

    path = _resolve_experiment(args.config)
    from peg_ctrl.batch import default_workers
    from peg_ctrl.config import read_mapping
    from peg_ctrl.experiments.config import apply_experiment_overrides, experiment_from_mapping
    from peg_ctrl.experiments.runner import run_sweep

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


def _cmd_validity(args: argparse.Namespace) -> int:
    from peg_ctrl.validity_report import run_battery

    profiles = args.profile or ["seed", "precision"]  # names checked by the parser (PROFILES)
    if args.trials < 1:
        raise ConfigError(f"--trials must be >= 1, got {args.trials}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    with lock_output_dir(prepare_output_dir(args.out)) as out:
        print(f"wrote {run_battery(out, profiles, trials=args.trials, seed=args.seed)}")
    return 0


def _cmd_validate_profile(args: argparse.Namespace) -> int:
    from peg_ctrl.profile_check import validate_profile

    if args.profile == args.reference:
        raise ConfigError(f"--reference must differ from the profile, got {args.reference!r} for both")
    if args.seeds < 2:
        raise ConfigError(f"--seeds must be >= 2, got {args.seeds}")
    if args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    with lock_output_dir(prepare_output_dir(args.out or f"runs/validate-{args.profile}")) as out:
        result = validate_profile(
            args.profile, out, reference=args.reference, seeds=args.seeds, workers=args.workers
        )
    print((out / "validation.md").read_text(), end="")
    print(f"wrote {out / 'validation.json'} and {out / 'validation.md'}")
    return 0 if result["passed"] else 1


def _cmd_replay(args: argparse.Namespace) -> int:
    from peg_ctrl.replay import replay

    out = replay(args.run_dir, video=args.video, viewer=args.viewer, speed=args.speed)
    print(f"wrote {out}" if out is not None else "replay ended")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
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


def _add_set(p: argparse.ArgumentParser, what: str = "config") -> None:
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help=f"set a {what} field by dotted path, value parsed as YAML (repeatable), "
        "e.g. --set physics.profile=precision --set scene.assets.clearance=5e-5",
    )


def _parser() -> argparse.ArgumentParser:
    """The ``peg-sim`` parser: one subcommand per command, each with a help line and a description."""
    parser = _Parser(
        prog="peg-sim",
        description="Peg-in-hole simulation and controller research in MuJoCo. "
        "'peg-sim COMMAND --help' describes a command.",
        epilog=f"Progress bars go to stderr when it is a terminal; {ENV_VAR}=0 hides them, "
        f"{ENV_VAR}=1 shows them anyway.",
    )
    parser.add_argument("--version", action="version", version=f"peg-sim {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "model",
        help="write the compiled scene (scene.xml + meshes)",
        description="Write the compiled scene as DIR/scene.xml plus its meshes "
        "(open it with: python -m mujoco.viewer --mjcf=DIR/scene.xml).",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--config", metavar="FILE", help="episode config file (.yaml, .toml or .json) whose scene to write"
    )
    _add_set(p)
    p.set_defaults(func=_cmd_model)

    p = sub.add_parser(
        "calibrate",
        help="measure the jaw byte <-> pad separation table",
        description="Sweep the jaw actuator's byte over 0..255 on the model, fit the piecewise-linear "
        "byte <-> pad separation map and write it as JSON to --out FILE. --replace-packaged instead "
        "rewrites the table the package ships (peg_ctrl/data/jaw_calibration.json; source checkouts "
        "only).",
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", metavar="FILE", help="output JSON file")
    where.add_argument(
        "--replace-packaged",
        action="store_true",
        help="rewrite the packaged calibration in this source checkout (refused in an installed copy)",
    )
    p.add_argument("--samples", type=int, default=103, help="bytes swept over 0..255 (default 103)")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser(
        "bench",
        help="time the loop against raw physics (JSON)",
        description="Loop overhead over raw physics per controller, by component, and sweep "
        "throughput, written as JSON to --out. --physics, --sweep or --qp run another benchmark instead.",
    )
    p.add_argument(
        "--out",
        default="bench.json",
        metavar="FILE",
        help="output JSON file (default: bench.json in the current directory)",
    )
    p.add_argument(
        "--controller",
        action="append",
        type=CONTROLLERS,
        choices=CONTROLLERS,
        metavar="NAME",
        help="controller to bench: %(choices)s (repeatable; default all)",
    )
    p.add_argument(
        "--task",
        action="append",
        type=BENCH_TASKS,
        choices=BENCH_TASKS,
        metavar="TASK",
        help="task: %(choices)s (repeatable; default both)",
    )
    p.add_argument(
        "--profile",
        default="seed",
        type=PROFILES,
        choices=PROFILES,
        metavar="PROFILE",
        help="physics profile of the episodes: %(choices)s (default %(default)s)",
    )
    p.add_argument("--repeats", type=int, default=3, help="interleaved repetitions (default 3)")
    p.add_argument(
        "--control-dt",
        type=float,
        action="append",
        help="control period in s to bench (repeatable; default: each controller's own)",
    )
    p.add_argument(
        "--throughput-episodes",
        type=int,
        default=20,
        help="episodes per profile in the 2-worker sweep throughput (default 20; 0: skip)",
    )
    p.add_argument("--sweep", action="store_true", help="instead: sweep speedup of 2 workers over 1")
    p.add_argument(
        "--qp",
        action="store_true",
        help="instead: solve time of the MPC's QPs by each candidate solver (CasADi, qpsolvers)",
    )
    p.add_argument(
        "--physics",
        action="store_true",
        help="instead: cost per step of each physics profile in contact (400 steps per situation)",
    )
    p.add_argument("--sweep-episodes", type=int, default=6, help="episodes per sweep timing (default 6)")
    p.set_defaults(func=_cmd_bench)

    p = sub.add_parser(
        "run",
        help="run one autonomous episode headless",
        description="Run one autonomous episode (grasp, lift, turn, align, release, settle) and write "
        "DIR/summary.json, DIR/log.jsonl, DIR/forces.npz, DIR/force_profile.png (and DIR/episode.mp4). "
        "Exit code 0 on success, 1 on a failed episode, 2 on bad input.",
    )
    p.add_argument(
        "--controller",
        type=CONTROLLERS,
        choices=CONTROLLERS,
        metavar="NAME",
        help="controller: %(choices)s (default pd, or the config file's)",
    )
    p.add_argument(
        "--planner",
        type=PLANNERS,
        choices=PLANNERS,
        metavar="NAME",
        help="planner: %(choices)s (default ruckig, or the config file's)",
    )
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
    p.add_argument(
        "--out", default="runs/episode", metavar="DIR", help="output directory (default %(default)s)"
    )
    p.add_argument("--video", action="store_true", help="also render DIR/episode.mp4 offscreen")
    p.add_argument("--viewer", action="store_true", help="show the episode in the MuJoCo viewer instead")
    p.add_argument("--config", metavar="FILE", help="episode config file (.yaml, .toml or .json)")
    _add_set(p)
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "teleop",
        help="drive the gripper from the keyboard",
        description="Teleoperation in a window (--scripted: a scripted insertion, headless). Writes "
        "DIR/summary.json (the fields of 'peg-sim run' plus attempts and end), DIR/log.jsonl and "
        "DIR/forces.npz. Keys: 4/5 +Y/-Y, 6/7 +X/-X, 8/9 +Z/-Z, Q/E roll, Up/Down pitch, "
        "Left/Right yaw, [ / ] jaw open/close, Shift fine motion, J/K/L speed 0.5x/1x/2x, -/= speed "
        "down/up, Z reset, Esc quit. Mouse: left-drag rotate, right-drag move, scroll zoom. "
        "--set takes the controller, physics profile and scene fields of 'peg-sim run' (default: seed "
        "physics); DIR/config.json and the summary record what the session ran.",
    )
    p.add_argument(
        "--controller",
        type=CONTROLLERS,
        choices=CONTROLLERS,
        metavar="NAME",
        help="controller: %(choices)s (default pd, or --set controller.name's)",
    )
    p.add_argument(
        "--seed",
        type=int,
        help="random seed of the peg's start pose (default 0; only with --randomize)",
    )
    p.add_argument("--randomize", action="store_true", help="randomise the peg's start pose (and on reset)")
    p.add_argument("--speed", type=float, default=1.0, help="initial speed multiplier, 0.1 to 5 (default 1)")
    p.add_argument(
        "--out", default="runs/teleop", metavar="DIR", help="output directory (default %(default)s)"
    )
    p.add_argument("--screenshot", help="save the last frame (with overlay) to this PNG on exit")
    p.add_argument("--scripted", action="store_true", help="run a scripted insertion headless (no window)")
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="set a controller.*, physics.* or scene.* field of the session by dotted path, value "
        "parsed as YAML (repeatable), e.g. --set physics.profile=precision "
        "--set scene.assets.clearance=1e-4 --set controller.kp_pos=[2000,2000,2000]",
    )
    p.set_defaults(func=_cmd_teleop)

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
    p.add_argument("--out", metavar="DIR", help="output directory (default runs/<experiment name>)")
    p.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    p.add_argument("--backend", choices=["local", "ray"], default="local", help="local process pool or Ray")
    p.add_argument("--address", help="Ray cluster address (with --backend ray)")
    _add_set(p, "experiment")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser(
        "validity",
        help="physical validity battery per physics profile",
        description="Held pushes per physics profile against clearance, chamfer and tilt; writes "
        "DIR/validity.md, DIR/validity.json and plots.",
    )
    p.add_argument(
        "--profile",
        action="append",
        type=PROFILES,
        choices=PROFILES,
        metavar="PROFILE",
        help="physics profile: %(choices)s (repeatable; default seed and precision)",
    )
    p.add_argument("--trials", type=int, default=10, help="pushes per clearance (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start-error draws (default 0)")
    p.add_argument(
        "--out", default="runs/validity", metavar="DIR", help="output directory (default %(default)s)"
    )
    p.set_defaults(func=_cmd_validity)

    p = sub.add_parser(
        "validate-profile",
        help="check a physics profile against a reference",
        description="Run both tasks for --seeds seeds in PROFILE and in --reference and compare success, "
        "peak force, slip and speed; writes DIR/validation.json and DIR/validation.md. Exit code 1 if "
        "a check fails.",
    )
    p.add_argument(
        "profile",
        type=PROFILES,
        choices=PROFILES,
        metavar="PROFILE",
        help="the profile to validate: %(choices)s",
    )
    p.add_argument(
        "--reference",
        default="seed",
        type=PROFILES,
        choices=PROFILES,
        metavar="PROFILE",
        help="the reference profile (default %(default)s)",
    )
    p.add_argument("--seeds", type=int, default=100, help="seeds per task and profile (default 100)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--out", metavar="DIR", help="output directory (default runs/validate-<profile>)")
    p.set_defaults(func=_cmd_validate_profile)

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
        "--speed", type=float, default=1.0, help="simulated seconds per second of replay (default 1)"
    )
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "plot",
        help="redraw a sweep's plots and report.md",
        description="Redraw the plots and report.md of a sweep from the episodes.csv it saved in DIR. "
        "An episodes.csv that is missing, cut off or behind the episodes (a killed sweep) is first "
        "rebuilt from DIR/episodes/*/summary.json, and refused when that is not possible.",
    )
    p.add_argument("dir", metavar="DIR", help="a sweep's output directory")
    p.set_defaults(func=_cmd_plot)
    return parser


def _one_line_warning(default: Callable[..., None]) -> Callable[..., None]:
    """A ``warnings.showwarning`` that prints an :class:`~peg_ctrl.errors.OutputWarning` (a plot
    or video not written) as one ``peg-sim: warning: ...`` line, and others as ``default`` does."""

    def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if issubclass(category, OutputWarning):
            print(f"peg-sim: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            default(message, category, *args, **kwargs)

    return show


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``peg-sim`` with ``argv`` (default: the process's arguments); returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(warnings.showwarning)
            return int(args.func(args))
    except KeyboardInterrupt:
        print("peg-sim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader of our output went away (`peg-sim sweep --list | head`): not an error.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except Exception as exc:
        if not _is_user_error(exc):
            raise  # a bug: keep the traceback
        print(f"peg-sim: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USER_ERROR


if __name__ == "__main__":
    sys.exit(main())
