"""One autonomous episode: the loop that owns time.

Physics steps at the model timestep (1 ms); the controller runs every ``decimation`` steps (its
period must be a whole multiple of the timestep); the state machine and the planner are sampled
at the control rate; success and failure are checked and the force trace recorded every control
step; the SPEC §7 step record is logged every ``log.interval`` physics steps.

Success
    Peg depth ≥ ``success.min_depth``, lateral error at the mouth ≤ ``success.max_lateral_error``
    and tilt ≤ ``success.max_tilt``, after release, for ``success.consecutive_steps`` control
    steps in a row.

Failures (``reason``)
    ``timeout`` (step limit, or the peg never went in before the settle timeout),
    ``force_spike`` (any contact force above ``success.force_spike``), ``excessive_tilt`` (the
    peg turned in the pads, or lies tilted at the end), ``grasp_lost`` (closed on nothing or
    dropped), ``diverged`` (non-finite state or a MuJoCo warning).

Randomizations
    With ``randomization.enabled``: peg start position ± ``peg_xy`` [m] in x and y, and its yaw
    ± ``peg_yaw`` [rad], drawn from ``numpy.random.default_rng(seed)``. The hole is fixed.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from controllers import REGISTRY, make_controller
from peg_ctrl.commands import quat_to_euler
from peg_ctrl.config import load, to_dict
from peg_ctrl.episode_log import EpisodeLogger
from peg_ctrl.jaw import load_default
from peg_ctrl.scene import GRIPPER_PREFIX, PEG_LYING_QUAT, SceneConfig, build_model
from peg_ctrl.sim import control_decimation
from peg_ctrl.state import PAIRS, StateReader
from peg_ctrl.task import (
    PHASE_ORDER,
    GraspLost,
    InsertionStateMachine,
    PegObservation,
    Phase,
    SuccessConfig,
    TaskConfig,
)
from planners import PLANNERS, MotionLimits, make_planner

__all__ = [
    "ControllerSpec",
    "RandomizationConfig",
    "LogConfig",
    "EpisodeConfig",
    "EpisodeResult",
    "run_episode",
    "episode_config_from_mapping",
    "FAILURE_REASONS",
    "DomainConfig",
    "prepare_model",
]

FAILURE_REASONS = ("timeout", "force_spike", "excessive_tilt", "grasp_lost", "diverged")
_BLOCK_PEG = PAIRS.index(("block", "peg"))


@dataclasses.dataclass(frozen=True)
class ControllerSpec:
    """A registered controller name and its config fields (see ``controllers.REGISTRY``)."""

    name: str = "pd"
    params: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in REGISTRY:
            raise ValueError(f"unknown controller {self.name!r}; known: {', '.join(sorted(REGISTRY))}")
        config_cls = REGISTRY[self.name][0]
        known = {f.name for f in dataclasses.fields(config_cls)}
        for key in self.params:
            if key not in known:
                raise ValueError(
                    f"{key}: unknown field of controller {self.name!r}; known: {', '.join(sorted(known))}"
                )
        load(config_cls, self.params, prefix="controller.")  # type and range checks, named


@dataclasses.dataclass(frozen=True)
class RandomizationConfig:
    enabled: bool = False
    peg_xy: float = 0.015  # +- range of the peg's start x and y [m]
    peg_yaw: float = 0.2  # +- range of the peg's start yaw [rad]

    def __post_init__(self) -> None:
        for name in ("peg_xy", "peg_yaw"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"randomization.{name} must be finite and >= 0, got {value!r}")


@dataclasses.dataclass(frozen=True)
class DomainConfig:
    """Domain randomization beyond the start pose, drawn per seed (ranges are [low, high])."""

    peg_mass_scale: tuple[float, float] = (1.0, 1.0)  # factor on the peg's mass and inertia
    friction_scale: tuple[float, float] = (1.0, 1.0)  # factor on the peg's and block's friction
    gain_scale: tuple[float, float] = (1.0, 1.0)  # factor on each of the controller's GAINS
    position_noise: float = 0.0  # std of noise on the measured gripper position [m]
    velocity_noise: float = 0.0  # std of noise on the measured gripper velocity [m/s, rad/s]
    force_noise: float = 0.0  # std of noise on the force/torque sensor [N, N m]

    def __post_init__(self) -> None:
        for name in ("peg_mass_scale", "friction_scale", "gain_scale"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
                raise ValueError(f"domain.{name} must be [low, high] with 0 < low <= high, got {[lo, hi]}")
        for name in ("position_noise", "velocity_noise", "force_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"domain.{name} must be finite and >= 0, got {value!r}")

    @property
    def noisy(self) -> bool:
        return self.position_noise > 0 or self.velocity_noise > 0 or self.force_noise > 0


@dataclasses.dataclass(frozen=True)
class LogConfig:
    interval: int = 50  # physics steps between step records (SPEC: 50)
    contact_threshold: float = 0.01  # pair forces below this are not logged [N]
    trace: bool = True  # write the full-rate force trace

    def __post_init__(self) -> None:
        if self.interval < 1:
            raise ValueError(f"log.interval must be >= 1, got {self.interval}")
        if not self.contact_threshold >= 0:
            raise ValueError(f"log.contact_threshold must be >= 0, got {self.contact_threshold}")


@dataclasses.dataclass(frozen=True)
class EpisodeConfig:
    """Everything one autonomous episode depends on."""

    controller: ControllerSpec = ControllerSpec()
    planner: str = "ruckig"
    seed: int = 0
    max_steps: int = 20_000  # physics steps (SPEC: 20,000)
    limits: MotionLimits = MotionLimits()
    task: TaskConfig = TaskConfig()
    success: SuccessConfig = SuccessConfig()
    randomization: RandomizationConfig = RandomizationConfig()
    domain: DomainConfig = DomainConfig()
    log: LogConfig = LogConfig()
    scene: SceneConfig = SceneConfig()

    def __post_init__(self) -> None:
        if self.planner not in PLANNERS:
            raise ValueError(f"unknown planner {self.planner!r}; known: {', '.join(sorted(PLANNERS))}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")


def episode_config_from_mapping(data: dict[str, Any]) -> EpisodeConfig:
    """Build an :class:`EpisodeConfig` from plain data; ``controller: {name: pd, kp_pos: ...}``."""
    data = dict(data)
    ctrl = data.get("controller")
    if isinstance(ctrl, str):
        data["controller"] = {"name": ctrl, "params": {}}
    elif isinstance(ctrl, dict) and "params" not in ctrl:
        ctrl = dict(ctrl)
        name = ctrl.pop("name", "pd")
        data["controller"] = {"name": name, "params": ctrl}
    return load(EpisodeConfig, data)


@dataclasses.dataclass
class EpisodeResult:
    """The episode record (also written as ``summary.json``)."""

    status: str  # "success" or "failure" ("interrupted" on Ctrl-C)
    reason: str  # "" on success, else one of FAILURE_REASONS
    phase: str  # phase when the episode ended
    controller: str
    planner: str
    seed: int
    total_timesteps: int
    sim_time_s: float
    wall_time_s: float
    peak_contact_force_n: float  # peg-block
    peak_any_contact_force_n: float
    insertion_depth_m: float
    lateral_error_m: float
    tilt_rad: float
    max_penetration_m: float  # peg-block and peg-table, whole episode
    resting_penetration_m: float  # peg's contacts at the end
    grip_penetration_m: float  # pads into the peg, whole episode
    peg_slip_m: float  # peg motion relative to the pad while held
    time_to_insert_s: float | None
    detail: str
    log_path: str
    trace_path: str
    plot_path: str | None = None
    video_path: str | None = None
    phases: list[dict[str, Any]] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def one_line(self) -> str:
        head = (
            "SUCCESS"
            if self.status == "success"
            else f"{self.status.upper()} ({self.reason} in {self.phase})"
        )
        tti = f", inserted at {self.time_to_insert_s:.2f} s" if self.time_to_insert_s is not None else ""
        return (
            f"{head}: {self.controller}+{self.planner} seed {self.seed}, {self.total_timesteps} steps "
            f"({self.sim_time_s:.2f} s sim, {self.wall_time_s:.1f} s wall){tti}, "
            f"depth {self.insertion_depth_m * 1e3:.1f} mm, "
            f"peak peg-block force {self.peak_contact_force_n:.2f} N"
        )


@functools.lru_cache(maxsize=8)
def _compiled(scene: SceneConfig) -> mujoco.MjModel:
    """One compiled model per scene per process (sweep workers reuse it across episodes)."""
    return build_model(scene)


def _domain_draw(cfg: EpisodeConfig) -> dict[str, float]:
    """The per-seed domain factors (a random stream separate from the start pose's)."""
    d = cfg.domain
    rng = np.random.default_rng([cfg.seed, 1])
    return {
        "peg_mass_scale": float(rng.uniform(*d.peg_mass_scale)),
        "friction_scale": float(rng.uniform(*d.friction_scale)),
        "gain_scale": float(rng.uniform(*d.gain_scale)),
    }


def prepare_model(cfg: EpisodeConfig) -> tuple[mujoco.MjModel, dict[str, float]]:
    """A private copy of the scene's model with the domain randomization applied."""
    model = copy.copy(_compiled(cfg.scene))
    draw = _domain_draw(cfg)
    peg = model.body("peg").id
    model.body_mass[peg] *= draw["peg_mass_scale"]
    model.body_inertia[peg] *= draw["peg_mass_scale"]
    for g in range(model.ngeom):
        if model.geom_bodyid[g] in (peg, model.body("block").id):
            model.geom_friction[g, 0] *= draw["friction_scale"]
    mujoco.mj_setConst(model, mujoco.MjData(model))
    return model, draw


def controller_params(cfg: EpisodeConfig, gain_scale: float) -> dict[str, Any]:
    """The controller's parameters with every gain in its config's ``GAINS`` scaled."""
    config_cls = REGISTRY[cfg.controller.name][0]
    params = dict(cfg.controller.params)
    if gain_scale != 1.0:
        defaults = config_cls()
        for name in getattr(config_cls, "GAINS", ()):
            value = params.get(name, getattr(defaults, name))
            if isinstance(value, tuple):
                params[name] = tuple(v * gain_scale for v in value)
            else:
                params[name] = value * gain_scale
    return params


def initial_qpos(model: mujoco.MjModel, cfg: EpisodeConfig) -> np.ndarray:
    """Home keyframe with the peg's start pose randomised from ``cfg.seed`` if enabled."""
    qpos = model.key("home").qpos.copy()
    rz = cfg.randomization
    adr = model.joint("peg_free").qposadr[0]
    x, y = cfg.scene.peg_xy
    yaw = 0.0
    if rz.enabled:
        rng = np.random.default_rng(cfg.seed)
        dx, dy = rng.uniform(-rz.peg_xy, rz.peg_xy, size=2)
        yaw = float(rng.uniform(-rz.peg_yaw, rz.peg_yaw))
        x, y = x + dx, y + dy
    q_yaw = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    q = np.empty(4)
    mujoco.mju_mulQuat(q, q_yaw, np.asarray(PEG_LYING_QUAT))
    qpos[adr : adr + 3] = [x, y, cfg.scene.assets.peg_radius]
    qpos[adr + 3 : adr + 7] = q
    return qpos


class _Failure(Exception):
    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


def _round(values: Any, digits: int = 6) -> list[float]:
    return [round(float(v), digits) for v in values]


def run_episode(
    cfg: EpisodeConfig,
    out_dir: Path,
    *,
    video: bool = False,
    plot: bool = True,
    on_step: Callable[[mujoco.MjModel, mujoco.MjData], None] | None = None,
) -> EpisodeResult:
    """Run one episode headless, writing ``summary.json``, ``config.json``, logs, plot (and video).

    ``on_step`` (e.g. a viewer sync) is called after every control step.
    """
    import json

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.json").write_text(json.dumps(to_dict(cfg), indent=2) + "\n")
    model, draw = prepare_model(cfg)
    data = mujoco.MjData(model)
    controller = make_controller(cfg.controller.name, model, **controller_params(cfg, draw["gain_scale"]))
    noise_rng = np.random.default_rng([cfg.seed, 2]) if cfg.domain.noisy else None
    decimation = control_decimation(controller.control_dt, model.opt.timestep)
    reader = StateReader(model, contact_threshold_n=cfg.log.contact_threshold)
    fsm = InsertionStateMachine(
        scene=cfg.scene,
        task=cfg.task,
        planner=make_planner(cfg.planner),
        limits=cfg.limits,
        jaw=load_default(),
    )
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    data.qpos[:] = initial_qpos(model, cfg)
    mujoco.mj_forward(model, data)

    logger = EpisodeLogger(out_dir)
    recorder = _VideoRecorder(model, out_dir / "episode.mp4") if video else None
    peg_adr = model.joint("peg_free").qposadr[0]
    peg_dof = model.joint("peg_free").dofadr[0]
    half_len = 0.5 * cfg.scene.assets.peg_length
    block_top = cfg.scene.assets.block_size[2]
    hx, hy = cfg.scene.hole_xy
    pad_body = model.body(GRIPPER_PREFIX + "left_pad").id
    peg_body = model.body("peg").id
    succ = cfg.success
    phase_index = {p: float(i) for i, p in enumerate(PHASE_ORDER)}

    def observe(mags: list[float]) -> PegObservation:
        # Plain floats: this runs every control step.
        px, py, pz, w, x, y, z = data.qpos[peg_adr : peg_adr + 7].tolist()
        vx, vy, vz = data.qvel[peg_dof : peg_dof + 3].tolist()
        axis = np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])
        sign = -1.0 if axis[2] >= 0.0 else 1.0  # towards the lower end
        p = np.array([px, py, pz])
        bottom = p + (sign * half_len) * axis
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        return PegObservation(p, np.array([w, x, y, z]), axis, bottom, speed, mags[_BLOCK_PEG])

    controller.reset(reader.control_state(data))
    mags, pens = reader.pair_forces(data)
    peg = observe(mags)
    fsm.start(float(data.time), reader.control_state(data), peg)

    status, reason, detail = "failure", "timeout", "step limit reached"
    peak_block = peak_any = max_pen = grip_pen = slip = 0.0
    inserted_steps = 0
    time_to_insert: float | None = None
    slip_ref: np.ndarray | None = None
    axis_ref: np.ndarray | None = None
    warnings0 = int(data.warning.number.sum())
    depth = lateral = tilt = 0.0
    step = 0
    next_log = cfg.log.interval
    logged_phases = 0
    wall0 = time.perf_counter()
    try:
        while step < cfg.max_steps:
            t = float(data.time)
            cs = reader.control_state(data)
            if noise_rng is not None:
                cs = _noisy(cs, cfg.domain, noise_rng)
            try:
                target = fsm.update(t, cs, peg)
            except GraspLost as exc:
                raise _Failure("grasp_lost", str(exc)) from None
            try:
                out = controller.compute(cs, target)
            except ValueError as exc:  # a non-finite state reaches the controller first
                raise _Failure("diverged", f"controller rejected the state: {exc}") from None
            data.ctrl[:] = out.ctrl
            mujoco.mj_step(model, data, nstep=decimation)
            step += decimation

            # -- observations after the step ------------------------------------------------
            mags, pens = reader.pair_forces(data)
            peg = observe(mags)
            peak_block = max(peak_block, mags[_BLOCK_PEG])
            peak_any = max(peak_any, max(mags))
            max_pen = max(max_pen, pens[0], pens[2])
            grip_pen = max(grip_pen, pens[1])
            if cfg.log.trace:
                logger.trace((float(data.time), phase_index[fsm.phase], *mags, max(pens)))

            # -- failure checks ---------------------------------------------------------------
            if step % (10 * decimation) == 0 and (
                int(data.warning.number.sum()) != warnings0
                or not math.isfinite(float(data.qpos.sum() + data.qvel.sum()))
            ):  # checked every 10 control steps: MuJoCo's own warnings catch blow-ups at once
                raise _Failure("diverged", "non-finite state or MuJoCo warning")
            if max(mags) > succ.force_spike:
                pair = "-".join(PAIRS[int(np.argmax(mags))])
                raise _Failure(
                    "force_spike", f"{pair} contact force {max(mags):.1f} N > {succ.force_spike} N"
                )
            if fsm.grasped:
                r_pad = data.xmat[pad_body].reshape(3, 3)
                rel = r_pad.T @ (data.xpos[peg_body] - data.xpos[pad_body])
                axis_pad = r_pad.T @ peg.axis_world
                if slip_ref is None or axis_ref is None:
                    slip_ref, axis_ref = rel, axis_pad
                slip = max(slip, float(np.linalg.norm(rel - slip_ref)))
                if float(np.linalg.norm(peg.p_world - cs.p_world)) > succ.grasp_lost_distance:
                    raise _Failure("grasp_lost", "peg left the pads while held")
                in_hand = math.acos(min(1.0, abs(float(axis_pad @ axis_ref))))
                if in_hand > succ.max_in_hand_tilt:
                    raise _Failure("excessive_tilt", f"peg turned {in_hand:.2f} rad in the pads")

            # -- success ----------------------------------------------------------------------
            axis = peg.axis_world
            depth = block_top - float(peg.bottom_world[2])
            tilt = math.acos(min(1.0, abs(float(axis[2]))))
            if abs(axis[2]) > 1e-6:
                s = (block_top - peg.p_world[2]) / axis[2]
                lateral = math.hypot(peg.p_world[0] + s * axis[0] - hx, peg.p_world[1] + s * axis[1] - hy)
            else:
                lateral = math.inf
            ok = depth >= succ.min_depth and lateral <= succ.max_lateral_error and tilt <= succ.max_tilt
            if ok and fsm.released:
                inserted_steps += 1
                if time_to_insert is None:
                    time_to_insert = float(data.time)
            else:
                inserted_steps = 0
                time_to_insert = None

            # -- logging ----------------------------------------------------------------------
            while len(fsm.records) > logged_phases + 1 or (
                fsm.phase is Phase.DONE and len(fsm.records) > logged_phases
            ):
                rec = fsm.records[logged_phases]
                if rec.t_end is None:
                    break
                logger.record({"event": "phase", **dataclasses.asdict(rec)})
                logged_phases += 1
            if step >= next_log:
                next_log += cfg.log.interval
                logger.record(_step_record(step, fsm.phase.value, target, cs, reader, data, peg, out))
            if recorder is not None:
                recorder.maybe_capture(data)
            if on_step is not None:
                on_step(model, data)

            if inserted_steps >= succ.consecutive_steps:
                status, reason, detail = "success", "", "inserted"
                fsm.finish(float(data.time), "inserted")
                break
            if fsm.phase is Phase.DONE:
                if tilt > succ.max_tilt:
                    reason, detail = "excessive_tilt", f"peg came to rest tilted {tilt:.2f} rad"
                else:
                    reason, detail = (
                        "timeout",
                        f"peg not inserted (depth {depth * 1e3:.1f} mm, lateral {lateral * 1e3:.1f} mm)",
                    )
                break
    except _Failure as failure:
        reason, detail = failure.reason, failure.detail
        fsm.finish(float(data.time), failure.reason)
    except KeyboardInterrupt:
        status, reason, detail = "interrupted", "interrupted", "Ctrl-C"
        fsm.finish(float(data.time), "interrupted")
        raise
    finally:
        wall = time.perf_counter() - wall0
        if status != "success" and step >= cfg.max_steps:
            fsm.finish(float(data.time), "timeout")
        for rec in fsm.records[logged_phases:]:
            logger.record({"event": "phase", **dataclasses.asdict(rec)})
        _, resting_pens = reader.pair_forces(data)
        result = EpisodeResult(
            status=status,
            reason=reason,
            phase=fsm.phase.value if fsm.phase is not Phase.DONE else fsm.records[-1].phase,
            controller=cfg.controller.name,
            planner=cfg.planner,
            seed=cfg.seed,
            total_timesteps=step,
            sim_time_s=float(data.time),
            wall_time_s=wall,
            peak_contact_force_n=peak_block,
            peak_any_contact_force_n=peak_any,
            insertion_depth_m=depth,
            lateral_error_m=lateral,
            tilt_rad=tilt,
            max_penetration_m=max_pen,
            resting_penetration_m=max(resting_pens),
            grip_penetration_m=grip_pen,
            peg_slip_m=slip,
            time_to_insert_s=time_to_insert,
            detail=detail,
            log_path=str(logger.log_path),
            trace_path=str(logger.npz_path),
            phases=[dataclasses.asdict(r) for r in fsm.records],
        )
        logger.close({"event": "end", **result.to_dict()})
        if recorder is not None:
            result.video_path = recorder.close()
        if plot:
            from peg_ctrl.plots import plot_force_profile

            result.plot_path = str(
                plot_force_profile(logger.npz_path, result.phases, out_dir / "force_profile.png")
            )
        (out_dir / "summary.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    return result


def _noisy(cs: Any, domain: DomainConfig, rng: np.random.Generator) -> Any:
    """The control state as a noisy sensor suite would report it."""
    return cs._replace(
        p_world=cs.p_world + rng.normal(0.0, domain.position_noise, 3),
        v_world=cs.v_world + rng.normal(0.0, domain.velocity_noise, 3),
        omega_body=cs.omega_body + rng.normal(0.0, domain.velocity_noise, 3),
        ft_wrench=cs.ft_wrench + rng.normal(0.0, domain.force_noise, 6),
    )


def _step_record(
    step: int,
    phase: str,
    target: Any,
    cs: Any,
    reader: StateReader,
    data: mujoco.MjData,
    peg: PegObservation,
    out: Any,
) -> dict[str, Any]:
    """The SPEC §7 per-step record."""
    return {
        "event": "step",
        "step": step,
        "t": round(float(data.time), 6),
        "phase": phase,
        "command": {
            "position": _round(target.p_world),
            "quat": _round(target.quat_world),
            "omega_body": _round(target.omega_body),
            "jaw_sep_m": round(float(target.jaw_sep_m), 6),
        },
        "gripper": {
            "position": _round(cs.p_world),
            "euler": _round(quat_to_euler(cs.quat_world)),
            "quat": _round(cs.quat_world),
            "jaw_sep_m": round(float(cs.jaw_sep_m), 6),
        },
        "peg": {"position": _round(peg.p_world), "quat": _round(peg.quat_world)},
        "contacts": [c.to_dict() for c in reader.contacts(data)],
        "controller": {
            "solve_time_s": out.diagnostics.solve_time_s,
            "status": out.diagnostics.status,
            "iterations": out.diagnostics.iterations,
        },
    }


class _VideoRecorder:
    """Offscreen frames from the ``insertion`` camera at ``fps``, written as MP4 at the end."""

    def __init__(
        self, model: mujoco.MjModel, path: Path, *, fps: int = 30, size: tuple[int, int] = (480, 640)
    ) -> None:
        import imageio.v2 as imageio

        self.path = path
        self.fps = fps
        self._period = 1.0 / fps
        self._next = 0.0
        self._renderer = mujoco.Renderer(model, *size)
        self._writer = imageio.get_writer(str(path), fps=fps, codec="libx264", quality=7, macro_block_size=8)

    def maybe_capture(self, data: mujoco.MjData) -> None:
        if data.time + 1e-9 < self._next:
            return
        self._next += self._period
        self._renderer.update_scene(data, camera="insertion")
        self._writer.append_data(self._renderer.render())

    def close(self) -> str:
        self._writer.close()
        self._renderer.close()
        return str(self.path)
