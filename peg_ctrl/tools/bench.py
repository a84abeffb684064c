"""Benchmarks: the loop's overhead over raw physics, by component, and sweep throughput.

Method (``peg-sim bench``):

- **The same trajectory.** A whole episode (the task's phases, its contacts included) runs once
  through the loop with a recorder of its controls; its raw replay is bare ``mj_step`` on the
  same controls from the same initial state, which reproduces the trajectory bit for bit
  (checked: the final state must be equal, or the benchmark refuses to report).
- **Interleaved repeats.** Each repetition runs, back to back: the loop with its default
  recording (force trace and step log, as ``peg-sim run`` writes them), the raw replay, and the
  loop once more with each section timed (:class:`~peg_ctrl.run.loop.LoopTimer`, which costs a few
  clock reads per control step, so it is kept out of the first measurement). Machine load hits
  all three alike; min and median are reported.
- **Clocks.** Loop and replay times are CPU time of the benchmarking process
  (``time.process_time``: the logger's writer thread included). Sweep throughput is wall time
  of a real sweep with 2 worker processes (start-up, model compilation and file writing
  included).

Overhead = loop time / replay time - 1, the median of the paired ratios of the repetitions.
Efficiency = replay time / loop time (the share of the loop's time that is physics), and the
loop's own work per control step = (loop time - replay time) per control step - the controller's
compute (from the timed run): everything the loop adds to the physics and the control law
(task, monitors, sensors, observations, recording, the phantom-contact guard, bookkeeping);
each the median over the repetitions of its paired value.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from peg_ctrl.run.episode_log import EpisodeLogger
from peg_ctrl.run.loop import Loop, LoopTimer, Recorder, StepInfo
from peg_ctrl.run.recorders import StepLogRecorder, TraceRecorder

if TYPE_CHECKING:
    from peg_ctrl.run.episode import EpisodeConfig

__all__ = ["bench_episode", "bench_throughput", "bench_profiles", "bench_qp", "run_benchmarks", "BENCH_TASKS"]

BENCH_TASKS = ("default", "contact")  # peg_ctrl.tools.profile_check.TASKS
TARGET_OVERHEAD = 0.10


class _ControlLog:
    """Recorder: the controls of every control step."""

    def __init__(self) -> None:
        self.ctrl: list[np.ndarray] = []

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.ctrl.append(np.array(info.output.ctrl, dtype=float))


def _episode_config(controller: str, task: str, profile: str, seed: int, control_dt: float | None) -> Any:
    import dataclasses

    from peg_ctrl.controllers import REGISTRY
    from peg_ctrl.tools.profile_check import task_config

    cfg = task_config(task, profile, seed)
    if cfg.controller.name != controller:  # the task's controller settings are for its own
        cfg = dataclasses.replace(cfg, controller=REGISTRY[controller]())
    if control_dt is not None:
        cfg = dataclasses.replace(cfg, controller=dataclasses.replace(cfg.controller, control_dt=control_dt))
    return cfg


def _run(loop: Loop, cfg: Any, recorders: list[Recorder], *, reset: bool = True) -> tuple[float, float, int]:
    """One episode through ``loop``: (CPU s, wall s, physics steps)."""
    loop.recorders = recorders
    if reset:
        loop.reset(np.random.default_rng(cfg.seed))
    limit = cfg.step_limit(loop.model.opt.timestep)
    c0, w0 = time.process_time(), time.perf_counter()
    loop.run(limit)
    for r in recorders:
        if isinstance(r, StepLogRecorder):
            r.flush(loop)
        elif isinstance(r, TraceRecorder):
            r.flush()
    return time.process_time() - c0, time.perf_counter() - w0, loop.steps


def _recording(loop: Loop, tmp: Path) -> tuple[list[Recorder], EpisodeLogger]:
    logger = EpisodeLogger(tmp)
    return [TraceRecorder(logger, loop.task.phases), StepLogRecorder(logger, 50)], logger


def bench_episode(
    controller: str,
    *,
    task: str = "default",
    profile: str = "seed",
    seed: int = 0,
    repeats: int = 5,
    control_dt: float | None = None,
    on_repeat: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """One whole episode of ``task`` with ``controller`` in the loop vs its raw replay;
    ``on_repeat`` is called after each repetition (for a progress bar)."""
    from peg_ctrl.run.episode import build_loop

    cfg = _episode_config(controller, task, profile, seed, control_dt)
    loop = build_loop(cfg)
    times = _Timings()
    with tempfile.TemporaryDirectory(prefix="peg_ctrl_bench_") as tmp:
        _run(loop, cfg, [])  # warm-up (caches, solver set-up)
        for rep in range(repeats):
            _time_repeat(loop, cfg, Path(tmp), rep, times, controller)
            if on_repeat is not None:
                on_repeat()
    outcome = loop.last
    return {
        "controller": controller,
        "task": task,
        "profile": profile,
        "seed": seed,
        "status": ("success" if outcome.success else "failure") if outcome is not None else "",
        "reason": outcome.reason if outcome is not None else "",
        "control_hz": 1.0 / loop.control_dt,
        **times.summary(loop.decimation, repeats),
    }


@dataclasses.dataclass
class _Timings:
    """Each repetition's CPU and wall seconds, loop and raw replay, its step count, and the
    loop's sections per physics step [us] from its timed run."""

    loop_cpu: list[float] = dataclasses.field(default_factory=list)
    loop_wall: list[float] = dataclasses.field(default_factory=list)
    raw_cpu: list[float] = dataclasses.field(default_factory=list)
    raw_wall: list[float] = dataclasses.field(default_factory=list)
    steps: list[int] = dataclasses.field(default_factory=list)
    sections: list[dict[str, float]] = dataclasses.field(default_factory=list)

    def summary(self, k: int, repeats: int) -> dict[str, Any]:
        """The medians and minimums (``k``: physics steps per control step)."""
        # per physics step: each repetition's own step count
        loop_us = [c / n * 1e6 for c, n in zip(self.loop_cpu, self.steps, strict=True)]
        raw_us = [c / n * 1e6 for c, n in zip(self.raw_cpu, self.steps, strict=True)]
        ratios = [a / b - 1.0 for a, b in zip(self.loop_cpu, self.raw_cpu, strict=True)]
        efficiency = [b / a for a, b in zip(self.loop_cpu, self.raw_cpu, strict=True)]
        components = {name: statistics.median(s[name] for s in self.sections) for name in LoopTimer.SECTIONS}
        # The loop's own work per control step: what it adds to the raw physics, less the control law.
        own = [
            (lp - raw - s["controller"]) * k
            for lp, raw, s in zip(loop_us, raw_us, self.sections, strict=True)
        ]
        walls = zip(self.loop_wall, self.raw_wall, strict=True)
        return {
            "physics_steps": statistics.median(self.steps),
            "physics_steps_per_control_step": k,
            "repeats": repeats,
            "raw_us_per_step": {"min": min(raw_us), "median": statistics.median(raw_us)},
            "loop_us_per_step": {"min": min(loop_us), "median": statistics.median(loop_us)},
            "overhead": {
                "median": statistics.median(ratios),
                "min": min(ratios),
                "of_minimums": min(loop_us) / min(raw_us) - 1.0,
            },
            "wall_overhead_median": statistics.median(a / b - 1.0 for a, b in walls),
            "efficiency": statistics.median(efficiency),
            "loop_own_us_per_control_step": statistics.median(own),
            # Per physics step, from the timed runs: sections of the loop (physics = the in-loop
            # physics steps with their sensor copies).
            "components_us_per_step": components,
            "python_us_per_control_step": sum(v for n, v in components.items() if n != "physics") * k,
            "within_target": statistics.median(ratios) <= TARGET_OVERHEAD,
        }


def _time_repeat(
    loop: Loop, cfg: EpisodeConfig, tmp: Path, rep: int, times: _Timings, controller: str
) -> None:
    """One repetition: the loop with its recording, plus a recorder of its controls (one array
    copy per control step, counted against the loop), then the raw replay of exactly those;
    then a run with the loop's section timer."""
    model = loop.model
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    recorders, logger = _recording(loop, tmp / f"loop{rep}")
    log = _ControlLog()
    loop.recorders = []
    loop.reset(np.random.default_rng(cfg.seed))
    mujoco.mj_getState(model, loop.data, state0, spec)
    cpu, wall, steps = _run(loop, cfg, [*recorders, log], reset=False)
    logger.close()
    times.loop_cpu.append(cpu)
    times.loop_wall.append(wall)
    times.steps.append(steps)
    cpu, wall, q = _replay_raw(loop, state0, log.ctrl)
    if not np.array_equal(q, loop.data.qpos):
        raise RuntimeError(f"{controller}: the raw replay diverged from the loop; not comparable")
    times.raw_cpu.append(cpu)
    times.raw_wall.append(wall)
    recorders, logger = _recording(loop, tmp / f"timed{rep}")
    loop.timer = LoopTimer()
    _, _, timed_steps = _run(loop, cfg, recorders)
    logger.close()
    times.sections.append({name: sec / timed_steps * 1e6 for name, sec in loop.timer.seconds.items()})
    loop.timer = None


def _replay_raw(loop: Loop, state0: np.ndarray, ctrls: list[np.ndarray]) -> tuple[float, float, np.ndarray]:
    """Bare ``mj_step`` from ``state0`` through the controls ``ctrls``: CPU and wall seconds,
    and the final ``qpos``."""
    model = loop.model
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state0, mujoco.mjtState.mjSTATE_INTEGRATION)
    c0, w0 = time.process_time(), time.perf_counter()
    for ctrl in ctrls:
        data.ctrl[:] = ctrl
        mujoco.mj_step(model, data, nstep=loop.decimation)
    return time.process_time() - c0, time.perf_counter() - w0, data.qpos


def bench_throughput(
    profiles: tuple[str, ...] = ("seed", "fast", "precision"), *, episodes: int = 20, workers: int = 2
) -> list[dict[str, Any]]:
    """Episodes per hour of a real sweep of the default task per profile on ``workers`` processes
    (wall time; process start-up, compilation and file writing included)."""
    from peg_ctrl.run.batch import run_batch
    from peg_ctrl.tools.profile_check import task_config

    rows = []
    for name in profiles:
        with tempfile.TemporaryDirectory(prefix="peg_ctrl_bench_") as tmp:
            jobs = [(task_config("default", name, s), Path(tmp) / f"e{s}") for s in range(episodes)]
            t0 = time.perf_counter()
            results = run_batch(jobs, workers=workers, desc=f"sweep / {name}")
            wall = time.perf_counter() - t0
        rows.append(
            {
                "profile": name,
                "task": "default",
                "episodes": episodes,
                "workers": workers,
                "successes": sum(r["status"] == "success" for r in results),
                "wall_s": wall,
                "episodes_per_hour": 3600.0 * episodes / wall,
            }
        )
    return rows


# Held pushes (peg_ctrl.sim.validity) after whose end each profile is timed. Named by the push, not
# by the outcome: the profiles may end differently (the seed inserts the 0-clearance and the
# tilted peg, the precision profile stops both at the mouth / wedges the tilted one).
_CONTACT_SITUATIONS = {
    "on top face": {"clearance": 0.1e-3, "lateral_error": 0.025},
    "0 clearance": {"clearance": 0.0},
    "1 deg tilt": {"clearance": 0.1e-3, "tilt": 0.0175},
    "chamfer rim": {"clearance": 0.1e-3, "chamfer": 1e-3, "lateral_error": 1.25e-3},
}


def bench_profiles(
    profiles: tuple[str, ...] = ("seed", "precision"),
    *,
    n_steps: int = 400,
    repeats: int = 5,
    progress: bool = True,
) -> dict[str, Any]:
    """Cost of a physics step per profile in contact: each profile's held push is run into each
    situation of ``_CONTACT_SITUATIONS``; ``n_steps`` steps from the final state (same controls)
    are then timed, profiles alternating within every repetition, medians taken. A progress bar
    follows the held pushes (see :mod:`peg_ctrl.progress`) when ``progress``."""
    import dataclasses
    import itertools

    from peg_ctrl.progress import progress as with_bar
    from peg_ctrl.sim.validity import PushCase, held_push

    states: dict[tuple[str, str], tuple[mujoco.MjModel, mujoco.MjData]] = {}
    pushes = list(itertools.product(profiles, _CONTACT_SITUATIONS.items()))
    # held_push rejects an unknown profile name before any work
    shown = with_bar(pushes, desc="held pushes", unit="push", enabled=progress, lines="pushes")
    for name, (situation, fields) in shown:

        def keep(m: mujoco.MjModel, d: mujoco.MjData, key: tuple[str, str] = (name, situation)) -> None:
            states[key] = (m, copy.copy(d))

        held_push(dataclasses.replace(PushCase(duration=1.0), **fields), name, on_finish=keep)
    times: dict[tuple[str, str], list[float]] = {key: [] for key in states}
    for _ in range(repeats):
        for key, (model, start) in states.items():
            data = copy.copy(start)
            t0 = time.thread_time()
            mujoco.mj_step(model, data, nstep=n_steps)
            times[key].append((time.thread_time() - t0) / n_steps)
    rows = []
    for (name, situation), samples in times.items():
        model, start = states[(name, situation)]
        step_us = statistics.median(samples) * 1e6
        rows.append(
            {
                "profile": name,
                "situation": situation,
                "timestep_ms": model.opt.timestep * 1e3,
                "contacts": int(start.ncon),
                "constraint_rows": int(start.nefc),
                "step_us_median": step_us,
                "us_per_simulated_ms": step_us * 1e-3 / model.opt.timestep,
            }
        )
    base = {r["situation"]: r["us_per_simulated_ms"] for r in rows if r["profile"] == profiles[0]}
    for r in rows:
        r[f"cost_vs_{profiles[0]}"] = r["us_per_simulated_ms"] / base[r["situation"]]
    return {
        "what": "physics profiles in contact",
        "method": "held push (peg_ctrl.sim.validity) into each situation, then n_steps of bare mj_step "
        "from its final state; profiles alternate within each repetition; medians of CPU time",
        "n_steps": n_steps,
        "repeats": repeats,
        "rows": rows,
    }


def run_benchmarks(
    out: Path,
    *,
    controllers: list[str],
    tasks: list[str],
    repeats: int,
    profile: str = "seed",
    control_dts: list[float | None] | None = None,
    throughput: bool = True,
    throughput_episodes: int = 20,
    physics: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the benchmarks and write JSON to ``out``; a progress bar counts the repetitions of
    every task x controller x control period (see :mod:`peg_ctrl.progress`) when ``progress``."""
    from peg_ctrl.io import atomic_write_text, to_json
    from peg_ctrl.progress import progress_bar

    cases = [(t, c, dt) for t in tasks for c in controllers for dt in control_dts or [None]]
    entries = []
    with progress_bar(
        total=len(cases) * repeats, desc="bench", unit="rep", enabled=progress, lines="repetitions"
    ) as bar:
        for t, c, dt in cases:
            bar.set_postfix_str(f"{c} / {t}")
            entries.append(
                bench_episode(
                    c, task=t, profile=profile, repeats=repeats, control_dt=dt, on_repeat=bar.update
                )
            )
    results = {
        "machine": {
            "python": platform.python_version(),
            "mujoco": mujoco.__version__,
            "cpu": platform.machine(),
        },
        "method": __doc__,
        "clock": "CPU time of the process for loop and replay; wall time for sweep throughput",
        "target": f"overhead median <= {TARGET_OVERHEAD:.2f}",
        "episodes": entries,
        "throughput": bench_throughput(episodes=throughput_episodes) if throughput else [],
        "physics_profiles": bench_profiles(repeats=repeats, progress=progress) if physics else None,
    }
    atomic_write_text(out, to_json(results, indent=2) + "\n")
    return results


# -- the MPC's QPs: which solver is fastest on them ---------------------------------------------


def _contact_instances(count: int, seed: int) -> list[tuple[Any, Any, Any]]:
    """Contact-QP instances like an insertion's: (axes, measured, wanted), 1 to 5 active axes."""
    rng = np.random.default_rng(seed)
    masks = [
        (False, False, True, False, False, False),  # press
        (False, False, True, True, True, False),  # press and turn flat
        (True, True, True, False, False, False),  # press, guided laterally
        (True, True, True, True, True, False),
    ]
    out = []
    for i in range(count):
        axes = np.array(masks[i % len(masks)])
        measured = np.concatenate(
            [rng.normal(0.0, 1.0, 2), [rng.uniform(0.0, 12.0)], rng.normal(0.0, 0.02, 3)]
        )
        wanted = np.array([0.0, 0.0, rng.choice([0.6, 3.0]), 0.0, 0.0, 0.0])
        out.append((axes, measured, wanted))
    return out


def _casadi_contact_solver(qp: Any, name: str) -> Callable[[Any, Any, Any], Any]:
    """A CasADi ``conic`` solving the same QP as ``qp`` (one per active-axis count, built once)."""
    import casadi as ca

    from peg_ctrl.controllers.mpc import _quiet_stdout

    cache: dict[int, Any] = {}

    def solve(axes: Any, measured: Any, wanted: Any) -> Any:
        idx = np.flatnonzero(axes)
        hess, rows = qp._matrices(idx.size)
        if idx.size not in cache:
            options = {"printLevel": "none"} if name == "qpoases" else {"osqp": {"verbose": False}}
            with _quiet_stdout():
                cache[idx.size] = ca.conic(
                    "contact", name, {"h": ca.DM(hess).sparsity(), "a": ca.DM(rows).sparsity()}, options
                )
        lin, lo, hi, cap = qp.problem(axes, measured, wanted)
        with _quiet_stdout():
            sol = cache[idx.size](h=hess, g=lin, a=rows, lbx=lo, ubx=hi, lba=-cap, uba=cap)
        return np.asarray(sol["x"]).reshape(-1)

    return solve


def bench_qp(*, instances: int = 200, repeats: int = 5, seed: int = 0) -> dict[str, Any]:
    """Solve time of the contact MPC's QP (:mod:`peg_ctrl.controllers.contact_mpc`) and of the
    effort MPC's QP by each candidate solver, on the same instances, backends interleaved
    within every repetition; wall time per solve, p50 and p99 over all repetitions."""
    contact_backends = _contact_backends()
    effort = _effort_backends()
    problems = _contact_instances(instances, seed)
    rng = np.random.default_rng(seed)
    errors = [np.concatenate([rng.normal(0.0, [0.003, 0.02], (6, 2)).ravel()]) for _ in range(instances)]
    times: dict[str, list[float]] = {f"contact {k}": [] for k in contact_backends}
    times.update({f"effort {k}": [] for k in effort})
    for _ in range(repeats):
        for label, solve in contact_backends.items():
            for axes, measured, wanted in problems:
                t0 = time.perf_counter()
                solve(axes, measured, wanted)
                times[f"contact {label}"].append(time.perf_counter() - t0)
        for label, controller in effort.items():
            _time_effort(controller, errors, times[f"effort {label}"], quiet=label.endswith("osqp"))
    rows = []
    for label, samples in times.items():
        p50, p99 = np.percentile(samples, [50, 99])
        qp, backend = label.split(" ", 1)
        rows.append({"qp": qp, "backend": backend, "p50_us": float(p50) * 1e6, "p99_us": float(p99) * 1e6})
    return {
        "what": "MPC QP solve time by backend",
        "method": f"{instances} instances per QP (seed {seed}), {repeats} interleaved repetitions; wall "
        "time per solve including the interface's own setup; contact QP: horizon 10, 1 to 5 active "
        "axes (peg_ctrl.controllers.contact_mpc); effort QP: the condensed 15-step QP of "
        "peg_ctrl.controllers.mpc (90 variables), warm-started",
        "machine": platform.processor() or platform.machine(),
        "rows": rows,
    }


def _contact_backends() -> dict[str, Callable[[Any, Any, Any], Any]]:
    """The contact QP's solve, by backend: DAQP directly, qpsolvers' OSQP and ProxQP (when
    installed), CasADi's qpOASES and OSQP."""
    import dataclasses as dc

    import qpsolvers

    from peg_ctrl.controllers.contact_mpc import ContactQP, ContactSettings

    settings = ContactSettings(
        centre_body=(0.0, -0.07, -0.01),
        stiffness=(4447.0,) * 3 + (2.0,) * 3,
        damping=(2000.0, 2000.0, 400.0) + (0.5,) * 3,
        rate_cap=(0.01,) * 3 + (0.05,) * 3,
        rate_min=(1e-4,) * 3 + (5e-4,) * 3,
        budget=10.0,
        smoothing=0.1,
        horizon=10,
        dt=0.002,
        solver="daqp",
        tare_time=0.0,
        force_filter_hz=20.0,
        moment_filter_hz=5.0,
    )
    backends: dict[str, Callable[[Any, Any, Any], Any]] = {}
    qp_backends = (("daqp (direct)", "daqp"), ("qpsolvers: osqp", "osqp"), ("qpsolvers: proxqp", "proxqp"))
    for label, solver in qp_backends:
        if solver == "daqp" or solver in qpsolvers.available_solvers:
            backends[label] = ContactQP(dc.replace(settings, solver=solver)).solve
    reference = ContactQP(settings)
    backends["casadi: qpoases"] = _casadi_contact_solver(reference, "qpoases")
    backends["casadi: osqp"] = _casadi_contact_solver(reference, "osqp")
    return backends


def _effort_backends() -> dict[str, Any]:
    """The effort MPC (its condensed QP) with CasADi's qpOASES and OSQP, by backend."""
    from peg_ctrl.controllers.mpc import MPCConfig, MPCController, _quiet_stdout
    from peg_ctrl.sim.scene import SceneConfig, build_model

    model = build_model(SceneConfig(), "precision")
    effort: dict[str, Any] = {}
    with _quiet_stdout():
        for solver in ("qpoases", "osqp"):
            effort[f"casadi: {solver}"] = MPCController(model, MPCConfig(solver=solver, control_dt=0.001))
    return effort


def _time_effort(controller: Any, errors: list[np.ndarray], times: list[float], *, quiet: bool) -> None:
    """Append the wall time of each warm-started solve from each error state in ``errors``."""
    from peg_ctrl.controllers.mpc import _quiet_stdout

    controller.reset_warm_start()
    for z0 in errors:
        t0 = time.perf_counter()
        with _quiet_stdout() if quiet else contextlib.nullcontext():
            controller.solve(z0, np.zeros(6), np.zeros(6))
        times.append(time.perf_counter() - t0)
