"""One autonomous episode: its configuration, and the driver that runs it through the loop.

The driver compiles the scene (cached per process), applies the per-seed domain draw, builds the
controller, the task (``task.name``: pick-and-place by default, or held insertion), the monitors
and the recorders, runs :class:`~peg_ctrl.run.loop.Loop`
and writes ``summary.json``, ``config.json``, ``log.jsonl``, ``forces.npz``, ``states.npz`` (and
the force plot and video) into the output directory. Success and failure are the task's and the monitors'
(see :mod:`peg_ctrl.tasks.pick_and_place`, :mod:`peg_ctrl.tasks.held_insertion` and
:mod:`peg_ctrl.tasks.monitors`).

Random streams, all from ``seed``: the task's start pose ``default_rng(seed)``, the domain draw
``default_rng([seed, 1])``, sensor noise ``default_rng([seed, 2])``.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from peg_ctrl.config import ConfigError, load, to_dict
from peg_ctrl.controllers import PDConfig
from peg_ctrl.controllers.base import ControllerConfig
from peg_ctrl.environment import environment_id
from peg_ctrl.errors import FAILURE_REASONS, OutputError, OutputWarning
from peg_ctrl.io import atomic_write_text, remove_stale_temps, to_json
from peg_ctrl.planners import PLANNERS, MotionLimits, make_planner
from peg_ctrl.progress import progress_bar
from peg_ctrl.run.episode_log import EpisodeLogger
from peg_ctrl.run.loop import Loop, LoopOutcome, Recorder, SensorNoise
from peg_ctrl.run.recorders import (
    CallbackRecorder,
    StateRecorder,
    StepLogRecorder,
    TraceRecorder,
    VideoRecorder,
)
from peg_ctrl.run.result import COST_FIELDS, WALL_CLOCK_FIELDS, EpisodeResult
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.ft_model import FT_DOMAIN_FIELDS, FTSensorModel, ft_preset
from peg_ctrl.sim.jaw import load_default
from peg_ctrl.sim.physics import PhysicsConfig, PhysicsProfile
from peg_ctrl.sim.physics import profile as physics_profile
from peg_ctrl.sim.scene import SceneConfig, build_model, check_scene
from peg_ctrl.tasks.base import TaskContext, TaskSpec, insertion_task, skill_task
from peg_ctrl.tasks.monitors import ContactMonitor, GraspMonitor, InsertionMeasure
from peg_ctrl.tasks.pick_and_place import RandomizationConfig, SuccessConfig, TaskConfig
from peg_ctrl.tasks.strategies import strategy_name
from peg_ctrl.timing import control_decimation

__all__ = [
    "COST_FIELDS",
    "WALL_CLOCK_FIELDS",
    "RandomizationConfig",
    "LogConfig",
    "EpisodeConfig",
    "EpisodeResult",
    "run_episode",
    "episode_config_from_mapping",
    "FAILURE_REASONS",
    "DomainConfig",
    "DomainDraw",
    "domain_draw",
    "compiled_model",
    "prepare_model",
    "build_loop",
    "contact_fields",
]


EPISODE_TIME = 20.0  # default episode length [s of sim]: SPEC's 20,000 steps of 1 ms


@dataclasses.dataclass(frozen=True)
class DomainConfig:
    """Domain randomization beyond the start pose, drawn per seed (ranges are [low, high]), and
    the sensors' noise.

    The wrist force/torque sensor is either a preset (``ft_sensor``, see
    :data:`~peg_ctrl.sim.ft_model.FT_PRESETS`) or the five fields ``force_noise``,
    ``torque_noise``, ``ft_latency``, ``ft_bias_drift`` and ``ft_rate`` (:class:`FTSensorModel`'s, see
    docs/sensing.md); :attr:`ft_model` is the model in effect.
    """

    peg_mass_scale: tuple[float, float] = (1.0, 1.0)  # factor on the peg's mass and inertia
    friction_scale: tuple[float, float] = (1.0, 1.0)  # factor on the peg's and block's friction
    gain_scale: tuple[float, float] = (1.0, 1.0)  # factor on each of the controller's GAINS
    position_noise: float = 0.0  # std of noise on the measured gripper position [m]
    velocity_noise: float = 0.0  # std of noise on the measured gripper velocity [m/s, rad/s]
    orientation_noise: float = 0.0  # std of the measured gripper orientation's error about each axis [rad]
    # > 0: the position's error is a robot's repeatability, not white: a slowly varying error of
    # std position_noise, correlated over this time [s] (it holds over a touch), plus the white
    # position_white_noise [m]; the linear velocity is then differenced from the sensed positions
    # (velocity_noise stays on the angular velocity). 0: white noise at every reading.
    position_error_time: float = 0.0
    position_white_noise: float = 0.0
    force_noise: float = 0.0  # std of noise on each F/T force channel [N] (torques: torque_noise)
    torque_noise: float = 0.0  # std of noise on each F/T torque channel [N m]
    ft_latency: float = 0.0  # the F/T reading arrives this late [s]
    ft_bias_drift: float = 0.0  # random walk of the F/T force bias [N/sqrt(s)]
    ft_rate: float = 0.0  # the F/T sensor's sample rate [Hz], held between samples; 0: every control period
    ft_sensor: str = ""  # an F/T preset (ideal, wrist, mini45, forge) instead of the five fields above

    def __post_init__(self) -> None:
        for name in ("peg_mass_scale", "friction_scale", "gain_scale"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
                raise ConfigError(f"domain.{name} must be [low, high] with 0 < low <= high, got {[lo, hi]}")
        if self.position_white_noise and not self.position_error_time:
            raise ConfigError(
                "domain.position_white_noise is the white part of a robot's position error: set "
                "domain.position_error_time > 0 too (0: position_noise is white already)"
            )
        kinematic = ("position_noise", "velocity_noise", "orientation_noise")
        for name in (*kinematic, "position_error_time", "position_white_noise", *FT_DOMAIN_FIELDS):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"domain.{name} must be finite and >= 0, got {value!r}")
        if self.ft_sensor:
            ft_preset(self.ft_sensor, where="domain.ft_sensor")
            for name in FT_DOMAIN_FIELDS:
                if getattr(self, name) != 0:
                    raise ConfigError(
                        f"domain.{name}: set either domain.ft_sensor (a preset) or the sensor's "
                        "noise fields, not both"
                    )

    @property
    def ft_model(self) -> FTSensorModel:
        """The wrist F/T sensor in effect: the preset ``ft_sensor``, else the five fields."""
        if self.ft_sensor:
            return ft_preset(self.ft_sensor, where="domain.ft_sensor")
        return FTSensorModel(
            force_noise=self.force_noise,
            torque_noise=self.torque_noise,
            latency=self.ft_latency,
            bias_drift=self.ft_bias_drift,
            rate=self.ft_rate,
        )

    @property
    def noisy(self) -> bool:
        """Whether any sensor noise is on (an ``ideal`` F/T preset is none)."""
        kinematic = (
            self.position_noise,
            self.velocity_noise,
            self.orientation_noise,
            self.position_white_noise,
        )
        return any(v > 0 for v in kinematic) or self.ft_model.noisy

    @property
    def random(self) -> bool:
        """Whether the seed changes anything here: a range wider than a point, or sensor noise."""
        ranges = (self.peg_mass_scale, self.friction_scale, self.gain_scale)
        return self.noisy or any(lo < hi for lo, hi in ranges)


@dataclasses.dataclass(frozen=True)
class LogConfig:
    interval: int = 50  # physics steps between step records (SPEC: 50)
    contact_threshold: float = 0.01  # pair forces below this are not logged [N]
    trace: bool = True  # write the full-rate force trace

    def __post_init__(self) -> None:
        if self.interval < 1:
            raise ConfigError(f"log.interval must be >= 1, got {self.interval}")
        if not self.contact_threshold >= 0:
            raise ConfigError(f"log.contact_threshold must be >= 0, got {self.contact_threshold}")


@dataclasses.dataclass(frozen=True)
class EpisodeConfig:
    """Everything one autonomous episode depends on."""

    controller: ControllerConfig = PDConfig()
    planner: str = "ruckig"
    seed: int = 0
    max_steps: int | None = None  # physics steps; None: EPISODE_TIME of sim (SPEC: 20,000 at 1 ms)
    limits: MotionLimits = MotionLimits()
    task: TaskSpec = TaskConfig()  # pick_and_place (default) or held_insertion, by ``name``
    success: SuccessConfig = SuccessConfig()
    randomization: RandomizationConfig = RandomizationConfig()
    domain: DomainConfig = DomainConfig()
    log: LogConfig = LogConfig()
    scene: SceneConfig = SceneConfig()
    physics: PhysicsConfig = PhysicsConfig()

    def __post_init__(self) -> None:
        check_scene(self.physics.profile, self.scene)
        # Refused here, before an episode writes anything, rather than when the loop is built.
        _ = self.decimation
        self.task.check(self.scene)
        if self.planner not in PLANNERS:
            raise ConfigError(f"unknown planner {self.planner!r}; known: {', '.join(sorted(PLANNERS))}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ConfigError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")

    @property
    def decimation(self) -> int:
        """Physics steps per control step: the controller's period over the profile's timestep
        (a :class:`ConfigError` when it does not divide it)."""
        return control_decimation(self.controller.control_dt, physics_profile(self.physics.profile).timestep)

    @property
    def seeded(self) -> bool:
        """Whether ``seed`` changes the episode: the task draws its start from it (pick and place
        only with ``randomization.enabled``, held insertion always), or the domain is random."""
        return self.task.draws_from_seed(self.randomization) or self.domain.random

    def step_limit(self, timestep: float) -> int:
        """Physics steps the episode may take: ``max_steps``, else :data:`EPISODE_TIME` worth."""
        return self.max_steps if self.max_steps is not None else round(EPISODE_TIME / timestep)


def episode_config_from_mapping(data: dict[str, Any]) -> EpisodeConfig:
    """Build an :class:`EpisodeConfig` from plain data; ``controller: {name: pd, kp_pos: ...}``."""
    return load(EpisodeConfig, data)


def compiled_model(scene: SceneConfig, physics: str | PhysicsProfile = "seed") -> mujoco.MjModel:
    """One compiled model per scene and physics profile per process (sweep workers reuse it); a
    profile's name and the profile itself are the same model."""
    return _compiled_model(scene, physics_profile(physics))


@functools.lru_cache(maxsize=8)
def _compiled_model(scene: SceneConfig, physics: PhysicsProfile) -> mujoco.MjModel:
    return build_model(scene, physics)


@dataclasses.dataclass(frozen=True)
class DomainDraw:
    """One seed's domain factors."""

    peg_mass_scale: float
    friction_scale: float
    gain_scale: float


def domain_draw(seed: int, domain: DomainConfig) -> DomainDraw:
    """The per-seed domain factors (a random stream separate from the start pose's)."""
    rng = np.random.default_rng([seed, 1])
    return DomainDraw(
        peg_mass_scale=float(rng.uniform(*domain.peg_mass_scale)),
        friction_scale=float(rng.uniform(*domain.friction_scale)),
        gain_scale=float(rng.uniform(*domain.gain_scale)),
    )


def prepare_model(cfg: EpisodeConfig, draw: DomainDraw) -> mujoco.MjModel:
    """A private copy of the scene's model with the domain draw applied."""
    model = copy.copy(compiled_model(cfg.scene, cfg.physics.resolved()))
    peg = model.body("peg").id
    model.body_mass[peg] *= draw.peg_mass_scale
    model.body_inertia[peg] *= draw.peg_mass_scale
    for g in range(model.ngeom):
        if model.geom_bodyid[g] in (peg, model.body("block").id):
            model.geom_friction[g, 0] *= draw.friction_scale
    block = model.body("block").id
    for i in range(model.npair):  # explicit peg-block pairs (precision profile)
        if block in (model.geom_bodyid[model.pair_geom1[i]], model.geom_bodyid[model.pair_geom2[i]]):
            model.pair_friction[i, :2] *= draw.friction_scale
    mujoco.mj_setConst(model, mujoco.MjData(model))
    return model


def build_loop(cfg: EpisodeConfig, recorders: list[Recorder] | None = None) -> Loop:
    """The loop of one episode: model with the domain draw, scaled controller, task, monitors."""
    draw = domain_draw(cfg.seed, cfg.domain)
    model = prepare_model(cfg, draw)
    task = cfg.task.build(
        TaskContext(
            scene=cfg.scene,
            success=cfg.success,
            randomization=cfg.randomization,
            planner=make_planner(cfg.planner),
            limits=cfg.limits,
            jaw=load_default(),
            control_dt=cfg.controller.control_dt,
        )
    )
    d, s = cfg.domain, cfg.success
    noise = None
    if d.noisy:
        noise = SensorNoise(
            position=d.position_noise,
            velocity=d.velocity_noise,
            orientation=d.orientation_noise,
            position_error_time=d.position_error_time,
            position_white=d.position_white_noise,
            ft=d.ft_model,
            dt=cfg.controller.control_dt,  # one F/T reading per control period
            rng=np.random.default_rng([cfg.seed, 2]),
        )
    return Loop(
        model=model,
        controller=cfg.controller.scaled(draw.gain_scale).build(model),
        task=task,
        scene=cfg.scene,
        contact=ContactMonitor(force_spike=s.force_spike),
        grasp=GraspMonitor(model, lost_distance=s.grasp_lost_distance, max_in_hand_tilt=s.max_in_hand_tilt),
        noise=noise,
        recorders=recorders or [],
        contact_threshold_n=cfg.log.contact_threshold,
        phantom_depth=physics_profile(cfg.physics.profile).phantom_depth,
    )


def run_episode(
    cfg: EpisodeConfig,
    out_dir: Path,
    *,
    video: bool = False,
    plot: bool = True,
    on_step: Callable[[mujoco.MjModel, mujoco.MjData], None] | None = None,
    progress: bool = True,
) -> EpisodeResult:
    """Run one episode headless, writing ``summary.json``, ``config.json``, logs, ``states.npz``
    (for :mod:`peg_ctrl.tools.replay`), plot (and video).

    ``on_step`` (e.g. a viewer sync) is called after every control step. Ctrl-C writes the
    results so far (status ``interrupted``) and re-raises :class:`KeyboardInterrupt`. With
    ``video`` (rendering makes the episode several times slower) and ``progress``, a bar counts
    the video's frames (see :mod:`peg_ctrl.progress`).

    Every file is complete or absent. ``summary.json`` is written as soon as the episode ends,
    before the force trace is packed and before the optional plot and video, and rewritten when
    they are done; a plot or video that fails leaves its path None in the summary, with an
    :class:`~peg_ctrl.errors.OutputWarning`.

    Raises:
        OutputError: a file could not be written (no space left, read-only, ...), naming it;
            raised after ``summary.json`` is written if the episode ended by then.
    """
    out_dir = _prepare_output(cfg, Path(out_dir))
    logger = EpisodeLogger(out_dir)
    rec: _Recording | None = None
    try:
        loop = build_loop(cfg)
        rec = _Recording.attach(loop, cfg, logger, out_dir, video=video, on_step=on_step, progress=progress)
        loop.reset(np.random.default_rng(cfg.seed))
        rec.states.start(loop.data)
        wall0 = time.perf_counter()
        outcome = loop.run(cfg.step_limit(loop.model.opt.timestep))
        wall = time.perf_counter() - wall0
        result = _write_records(cfg, loop, outcome, wall, logger, rec, plot=plot)
    finally:
        logger.abort()
        if rec is not None:
            rec.discard()
    if outcome.status == "interrupted":
        raise KeyboardInterrupt
    return result


def _prepare_output(cfg: EpisodeConfig, out_dir: Path) -> Path:
    """Create ``out_dir``, clear the temporaries of a killed earlier run, write ``config.json``."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {str(out_dir)!r}: {exc.strerror or exc}") from None
    remove_stale_temps(out_dir)  # of an earlier run of this episode, killed while writing
    atomic_write_text(out_dir / "config.json", to_json(to_dict(cfg), indent=2) + "\n")
    return out_dir


@dataclasses.dataclass
class _Recording:
    """The recorders an episode writes its files with, and its video's progress bar."""

    out_dir: Path
    steps_log: StepLogRecorder
    states: StateRecorder
    trace: TraceRecorder | None
    camera: VideoRecorder | None = None
    bar: Any = None

    @classmethod
    def attach(
        cls,
        loop: Loop,
        cfg: EpisodeConfig,
        logger: EpisodeLogger,
        out_dir: Path,
        *,
        video: bool,
        on_step: Callable[[mujoco.MjModel, mujoco.MjData], None] | None,
        progress: bool,
    ) -> _Recording:
        """Build the recorders of ``cfg.log`` (and ``video``, ``on_step``) and give them to ``loop``."""
        steps_log = StepLogRecorder(logger, cfg.log.interval)
        states = StateRecorder(out_dir / "states.npz", loop.model.nq)
        rec = cls(
            out_dir, steps_log, states, TraceRecorder(logger, loop.task.phases) if cfg.log.trace else None
        )
        recorders: list[Recorder] = [steps_log, states]
        if rec.trace is not None:
            recorders.insert(0, rec.trace)
        if video:
            rec.camera = VideoRecorder(loop.model, out_dir / "episode.mp4")
            dt = float(loop.model.opt.timestep)
            # A bar of the frames rendered so far (one per 1/fps s of simulated time), up to the
            # step limit's worth.
            frames_max = math.floor(cfg.step_limit(dt) * dt * rec.camera.fps) + 1
            rec.bar = progress_bar(total=frames_max, desc="video", unit="frame", enabled=progress)
            recorders += [rec.camera, _frame_counter(rec.camera, rec.bar)]
        if on_step is not None:
            recorders.append(CallbackRecorder(on_step))
        loop.recorders = recorders
        return rec

    def close_video(self, failed: list[OutputError]) -> str | None:
        """Finish the video (its path, or None when writing it failed) and its bar."""
        if self.camera is None:
            return None
        path = _artefact("video", self.camera.close, failed)
        if path is not None:  # whole, though the episode ended before its limit
            self.bar.total = self.bar.n
        self.bar.close()
        self.camera = self.bar = None
        return path

    def discard(self) -> None:
        """Close the bar and drop a video not finished (an episode that raised)."""
        if self.bar is not None:
            self.bar.close()
        if self.camera is not None:
            self.camera.discard()


def _write_records(
    cfg: EpisodeConfig,
    loop: Loop,
    outcome: LoopOutcome,
    wall: float,
    logger: EpisodeLogger,
    rec: _Recording,
    *,
    plot: bool,
) -> EpisodeResult:
    """The episode's result, written: ``summary.json`` first (nothing written after it, the
    packed trace, plot and video, can lose it), then the rest, then the summary again."""
    rec.steps_log.flush(loop)
    if rec.trace is not None:
        rec.trace.flush()
    logger.sync()  # the log and the trace on disk before summary.json (the writer has its own thread)
    result = _result(cfg, loop, outcome, wall, logger)
    summary = rec.out_dir / "summary.json"
    result.trace_path = str(logger.trace_path)
    _write_summary(summary, result)
    result.trace_path = str(logger.npz_path)
    logger.close({"event": "end", **result.to_dict()})
    rec.states.close()
    failed: list[OutputError] = []
    if rec.camera is not None:
        result.video_path = rec.close_video(failed)
    if plot:
        from peg_ctrl.run.plots import plot_force_profile

        png = rec.out_dir / "force_profile.png"
        result.plot_path = _artefact(
            "force plot", lambda: str(plot_force_profile(logger.npz_path, result.phases, png)), failed
        )
    _write_summary(summary, result)
    if failed:
        raise failed[0]
    return result


def _frame_counter(camera: VideoRecorder, bar: Any) -> CallbackRecorder:
    """A recorder that brings ``bar`` (a :func:`~peg_ctrl.progress.progress_bar`) to the number
    of frames ``camera`` has rendered."""
    return CallbackRecorder(lambda model, data: bar.update(camera.frames - bar.n))


def _write_summary(path: Path, result: EpisodeResult) -> None:
    atomic_write_text(path, to_json(result.to_dict(), indent=2) + "\n")


def _artefact(what: str, make: Callable[[], str], failed: list[OutputError]) -> str | None:
    """The path of an optional output made by ``make``, or None if it failed: an
    :class:`OutputError` (no space, read-only) is kept in ``failed`` (and no further output is
    tried), anything else is an :class:`OutputWarning`."""
    if failed:
        return None
    try:
        return make()
    except OutputError as exc:
        failed.append(exc)
    except Exception as exc:
        warnings.warn(
            f"{what} not written: {' '.join(str(exc).split()) or type(exc).__name__}",
            OutputWarning,
            stacklevel=2,
        )
    return None


def contact_fields(
    loop: Loop, m: InsertionMeasure | None, *, seated: bool, assets: AssetParams
) -> dict[str, Any]:
    """The summary fields that the loop's monitors and the insertion measure ``m`` give, by
    their :class:`EpisodeResult` names: peak forces and penetrations, the resting penetration
    now, the hole metrics (None when the peg is not at the hole), the contact history (first
    contact, impulse, largest tilt in contact, search distance) and the end state. Autonomous
    episodes and teleoperation write them alike."""
    from peg_ctrl.tasks.monitors import episode_end_state

    depth, lateral, tilt = m.hole_metrics() if m is not None else (None, None, None)
    _, resting = loop.reader.pair_forces(loop.data)
    contact, history = loop.contact, loop.history
    first = history.first_contact
    return {
        "peak_contact_force_n": contact.peak_block,
        "peak_force_10ms_n": contact.peak_block_sustained,
        "peak_any_contact_force_n": contact.peak_any,
        "insertion_depth_m": depth,
        "lateral_error_m": lateral,
        "tilt_rad": tilt,
        "max_penetration_m": contact.max_penetration,
        "resting_penetration_m": max(resting),
        "grip_penetration_m": contact.grip_penetration,
        "first_contact_s": first,
        "contact_impulse_ns": history.impulse,
        "max_tilt_rad": history.max_tilt if first is not None else None,
        "search_distance_m": history.travel,
        "end_state": episode_end_state(
            m, seated=seated, clearance=assets.clearance, chamfer=assets.chamfer, radius=assets.peg_radius
        ),
    }


def _result(
    cfg: EpisodeConfig, loop: Loop, outcome: LoopOutcome, wall: float, logger: EpisodeLogger
) -> EpisodeResult:
    task = loop.task
    inserting = insertion_task(task)
    m = inserting.insertion.last if inserting is not None else None
    records = task.records
    playing = skill_task(task)
    grasp = loop.grasp
    time_to_insert = inserting.time_to_insert if inserting is not None else None
    fields = contact_fields(loop, m, seated=outcome.status == "success", assets=cfg.scene.assets)
    first = fields["first_contact_s"]
    return EpisodeResult(
        status=outcome.status,
        reason=outcome.reason,
        phase=task.phase if task.phase != "done" else records[-1].phase,
        controller=cfg.controller.name,
        planner=cfg.planner,
        physics=cfg.physics.profile,
        friction_time_s=cfg.physics.friction_time,
        task=cfg.task.name,
        strategy=strategy_name(cfg.task),
        seed=cfg.seed,
        total_timesteps=loop.steps,
        sim_time_s=float(loop.data.time),
        wall_time_s=wall,
        **fields,
        peg_slip_m=grasp.slip if grasp is not None else 0.0,
        time_to_insert_s=time_to_insert,
        contact_to_seat_s=contact_to_seat(first, time_to_insert),
        detail=outcome.detail,
        log_path=str(logger.log_path),
        trace_path=str(logger.npz_path),
        phases=[r.to_dict() for r in records],
        belief=playing.readings if playing is not None else [],
        skills=playing.skill_log if playing is not None else [],
        **loop_fields(loop),
        environment=environment_id(),
    )


def contact_to_seat(first_contact_s: float | None, seated_s: float | None) -> float | None:
    """Time from the first peg-block contact to seated [s]; None unless the peg touched the
    block before it was seated (a peg dropped into a wide hole may touch the bore only after)."""
    if first_contact_s is None or seated_s is None or first_contact_s > seated_s:
        return None
    return seated_s - first_contact_s


def loop_fields(loop: Loop) -> dict[str, Any]:
    """The summary's fields the loop itself measured: timing (:func:`timing_fields`) and the
    phantom contacts its guard removed."""
    return {**timing_fields(loop), "phantom_contacts": loop.guard.count if loop.guard is not None else 0}


def timing_fields(loop: Loop) -> dict[str, Any]:
    """The summary's timing fields (see :class:`EpisodeResult`) from the loop and its controller."""
    fields: dict[str, Any] = dict.fromkeys(COST_FIELDS)
    if loop.compute_times:
        p50, p99 = np.percentile(loop.compute_times, [50, 99])
        fields.update(control_time_p50_s=float(p50), control_time_p99_s=float(p99))
    solvers: dict[str, dict[str, float]] = {}
    for timing in loop.controller.timings():
        if not timing.times_s:
            continue
        times = np.asarray(timing.times_s)
        p50, p99 = np.percentile(times, [50, 99])
        solvers[timing.name] = {
            "period_s": timing.period_s,
            "count": int(times.size),
            "p50_s": float(p50),
            "p99_s": float(p99),
            "max_s": float(times.max()),
            "real_time_factor": float(times.mean() / timing.period_s),
        }
    fields["solver_timing"] = solvers
    if solvers:
        first = next(iter(solvers.values()))
        fields.update(
            solve_time_p50_s=first["p50_s"],
            solve_time_p99_s=first["p99_s"],
            solve_period_s=first["period_s"],
            solve_real_time_factor=first["real_time_factor"],
        )
    return fields
