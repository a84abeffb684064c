"""Benchmarks: the loop's overhead over raw physics, measured as a ratio in one run.

Method (so that both sides do exactly the same physics): a run of the one loop (a
:class:`~peg_ctrl.tasks.tracking.TrackingTask`, or a whole episode) records the control
sequence; the same sequence is then replayed with bare ``mj_step`` from the same initial state,
which reproduces the trajectory bit for bit. Both are timed in alternating repetitions and the
medians compared, so machine load affects both sides alike.
"""

from __future__ import annotations

import copy
import json
import platform
import statistics
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget, euler_to_quat
from peg_ctrl.controllers import make_controller
from peg_ctrl.loop import Loop, StepInfo
from peg_ctrl.scene import SceneConfig, build_model
from peg_ctrl.tasks.tracking import TrackingTask
from peg_ctrl.timing import control_decimation

__all__ = ["bench_controller", "bench_profiles", "run_benchmarks"]


def _solver_period_us(controller: Any) -> float:
    """The period at which a controller runs its solver (its control period if it has none)."""
    cfg = getattr(controller, "config", None)
    for name in ("mpc_dt", "ik_dt"):
        if cfg is not None and hasattr(cfg, name):
            return float(getattr(cfg, name)) * 1e6
    return float(controller.control_dt) * 1e6


def _targets(n_steps: int) -> list[GripperTarget]:
    """A representative motion: translate 10 cm and turn 95 degrees about X, then hold."""
    out = []
    start = np.array([-0.2, 0.0, 0.2])
    for k in range(n_steps):
        s = min(1.0, k / (0.6 * n_steps))
        blend = 3 * s * s - 2 * s**3
        p = start + blend * np.array([0.1, 0.05, -0.05])
        out.append(
            GripperTarget(
                p_world=p, quat_world=euler_to_quat(blend * np.radians(95), 0.0, 0.0), jaw_sep_m=0.04
            )
        )
    return out


class _ControlLog:
    """Recorder: the controls and diagnostics of every step."""

    def __init__(self) -> None:
        self.ctrl: list[np.ndarray] = []
        self.solve_times: list[float] = []
        self.solver_calls: list[float] = []

    def record(self, loop: Loop, info: StepInfo) -> None:
        d = info.output.diagnostics
        self.ctrl.append(np.asarray(info.output.ctrl))
        self.solve_times.append(d.solve_time_s)
        if d.status != "hold":  # a call that ran the controller's own solver
            self.solver_calls.append(d.solve_time_s)


def bench_controller(
    name: str, *, n_steps: int = 2000, repeats: int = 5, control_dt: float | None = None
) -> dict[str, Any]:
    """Time ``n_steps`` of physics with controller ``name`` in the loop vs the same physics alone.

    ``control_dt`` [s] overrides the controller's default control period.
    """
    model = build_model()
    params = {} if control_dt is None else {"control_dt": control_dt}
    controller = make_controller(name, model, **params)
    decimation = control_decimation(controller.control_dt, model.opt.timestep)
    targets = _targets(n_steps // decimation)
    log = _ControlLog()
    closed = Loop(
        model=model, controller=controller, task=TrackingTask(sequence=targets), scene=SceneConfig()
    )
    closed.recorders = [log]
    loop_times, raw_times = [], []
    for rep in range(repeats):
        closed.reset(np.random.default_rng(0))
        qpos0 = closed.data.qpos.copy()
        log.ctrl = []
        t0 = time.thread_time()
        for _ in targets:
            closed.step()
        loop_times.append(time.thread_time() - t0)
        final_loop = closed.data.qpos.copy()
        ctrl_log = log.ctrl

        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        data.qpos[:] = qpos0
        mujoco.mj_forward(model, data)
        t0 = time.thread_time()
        for ctrl in ctrl_log:
            data.ctrl[:] = ctrl
            mujoco.mj_step(model, data, nstep=closed.decimation)
        raw_times.append(time.thread_time() - t0)
        if rep == 0 and not np.array_equal(final_loop, data.qpos):
            raise RuntimeError("replay diverged from the closed-loop run; benchmark is not comparable")
    loop = statistics.median(loop_times)
    raw = statistics.median(raw_times)
    steps = len(targets) * closed.decimation
    solve = np.asarray(log.solve_times)
    solver_calls = log.solver_calls
    return {
        "controller": name,
        "physics_steps": steps,
        "repeats": repeats,
        "raw_step_us_median": raw / steps * 1e6,
        "loop_step_us_median": loop / steps * 1e6,
        # Median of paired ratios: each repetition's loop and replay ran back to back.
        "overhead_ratio": statistics.median(a / b for a, b in zip(loop_times, raw_times, strict=True)) - 1.0,
        "solve_time_us_median": float(np.median(solve) * 1e6),
        "solve_time_us_p99": float(np.percentile(solve, 99) * 1e6),
        # Calls that solved (diffik's IK, mpc's QP) rather than held the last solution.
        "solver_call_us_median": float(np.median(solver_calls) * 1e6) if solver_calls else None,
        "solver_call_us_p99": float(np.percentile(solver_calls, 99) * 1e6) if solver_calls else None,
        "solver_period_us": _solver_period_us(controller),
        "control_period_us": controller.control_dt * 1e6,
    }


def bench_episode(
    *, controller: str = "pd", planner: str = "ruckig", seed: int = 0, repeats: int = 3
) -> dict[str, Any]:
    """A whole autonomous episode (controller + state machine + planner + logging) vs raw physics.

    Each repetition runs the episode three ways on the same steps: with full logging, with
    logging off (no trace, no step records), and as a bare ``mj_step`` replay of the episode's
    own controls. ``logging_share`` is the part of the loop overhead that logging accounts for.
    """
    import dataclasses
    import tempfile

    from peg_ctrl.controllers import REGISTRY
    from peg_ctrl.episode import EpisodeConfig, LogConfig, RandomizationConfig, run_episode
    from peg_ctrl.tasks.pick_and_place import initial_qpos

    cfg = EpisodeConfig(
        controller=REGISTRY[controller](),
        planner=planner,
        seed=seed,
        randomization=RandomizationConfig(enabled=True),
    )
    quiet = dataclasses.replace(cfg, log=LogConfig(interval=10**9, trace=False))
    model = build_model(cfg.scene)
    full_t, quiet_t, raw_t = [], [], []
    steps = 0
    status = ""
    for _ in range(repeats):
        ctrls: list[np.ndarray] = []
        decimation = [1]

        def record(m: mujoco.MjModel, d: mujoco.MjData, ctrls: list[np.ndarray] = ctrls) -> None:
            ctrls.append(d.ctrl.copy())

        with tempfile.TemporaryDirectory() as tmp:
            # Wall time of the loop itself (the writer thread works concurrently).
            result = run_episode(cfg, Path(tmp) / "full", plot=False)
            full_t.append(result.wall_time_s)
            quiet_t.append(run_episode(quiet, Path(tmp) / "quiet", plot=False, on_step=record).wall_time_s)
        steps, status = result.total_timesteps, result.status
        decimation[0] = steps // max(1, len(ctrls))
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        data.qpos[:] = initial_qpos(model, cfg.scene, cfg.randomization, np.random.default_rng(cfg.seed))
        mujoco.mj_forward(model, data)
        t0 = time.perf_counter()
        for ctrl in ctrls:
            data.ctrl[:] = ctrl
            mujoco.mj_step(model, data, nstep=decimation[0])
        raw_t.append(time.perf_counter() - t0)
    full, quiet_time, raw = (statistics.median(x) for x in (full_t, quiet_t, raw_t))
    return {
        "what": "episode",
        "controller": controller,
        "planner": planner,
        "status": status,
        "physics_steps": steps,
        "repeats": repeats,
        "raw_step_us_median": raw / steps * 1e6,
        "episode_step_us_median": full / steps * 1e6,
        "episode_without_logging_step_us_median": quiet_time / steps * 1e6,
        "overhead_ratio": statistics.median(a / b for a, b in zip(full_t, raw_t, strict=True)) - 1.0,
        "logging_share_of_overhead": (full - quiet_time) / max(full - raw, 1e-12),
        "note": "wall time of the loops; the quiet run also records its controls for the replay",
    }


# Held pushes (peg_ctrl.validity) after whose end each profile is timed. Named by the push, not
# by the outcome: the profiles may end differently (the seed inserts the 0-clearance and the
# tilted peg, the precision profile stops both at the mouth / wedges the tilted one).
_CONTACT_SITUATIONS = {
    "on top face": {"clearance": 0.1e-3, "lateral_error": 0.025},
    "0 clearance": {"clearance": 0.0},
    "1 deg tilt": {"clearance": 0.1e-3, "tilt": 0.0175},
    "chamfer rim": {"clearance": 0.1e-3, "chamfer": 1e-3, "lateral_error": 1.25e-3},
}


def bench_profiles(
    profiles: tuple[str, ...] = ("seed", "precision"), *, n_steps: int = 400, repeats: int = 5
) -> dict[str, Any]:
    """Cost of a physics step per profile in contact: each profile's held push is run into each
    situation of ``_CONTACT_SITUATIONS``; ``n_steps`` steps from the final state (same controls)
    are then timed, profiles alternating within every repetition, medians taken."""
    import dataclasses

    from peg_ctrl.validity import PushCase, held_push

    states: dict[tuple[str, str], tuple[mujoco.MjModel, mujoco.MjData]] = {}
    for name in profiles:  # held_push rejects an unknown profile name before any work
        for situation, fields in _CONTACT_SITUATIONS.items():

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
        "method": "held push (peg_ctrl.validity) into each situation, then n_steps of bare mj_step "
        "from its final state; profiles alternate within each repetition; medians of CPU time",
        "n_steps": n_steps,
        "repeats": repeats,
        "rows": rows,
    }


def run_benchmarks(
    out: Path,
    *,
    controllers: list[str],
    n_steps: int,
    repeats: int,
    control_dts: list[float | None] | None = None,
    episode: bool = True,
) -> dict[str, Any]:
    """Run the benchmarks (each controller at each control period) and write JSON to ``out``."""
    entries = []
    for c in controllers:
        for dt in control_dts or [None]:
            entries.append(bench_controller(c, n_steps=n_steps, repeats=repeats, control_dt=dt))
    episodes = (
        [bench_episode(controller=c, repeats=max(1, repeats // 2)) for c in controllers] if episode else []
    )
    physics = bench_profiles(repeats=repeats) if episode else None
    results = {
        "machine": {
            "python": platform.python_version(),
            "mujoco": mujoco.__version__,
            "cpu": platform.machine(),
        },
        "method": "closed loop vs replay of its own control sequence with bare mj_step; "
        "alternating repetitions, medians of CPU time",
        "target": "overhead_ratio <= 0.05",
        "controllers": entries,
        "episodes": episodes,
        "physics_profiles": physics,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    return results
