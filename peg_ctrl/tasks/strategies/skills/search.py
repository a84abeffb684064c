"""The probe's search: landings and bearing presses a belief chooses until the end is over the bore."""

from __future__ import annotations

import math

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.sim.belief import HoleBelief
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, TrajectorySequence
from peg_ctrl.tasks.strategies.motions import down
from peg_ctrl.tasks.strategies.skills.centring import PressedCircle
from peg_ctrl.tasks.strategies.skills.common import (
    PRESS_AXES,
    distance,
)
from peg_ctrl.tasks.strategies.skills.landing import ProbeHost

_Vec = np.ndarray


__all__ = ["ProbeSearch"]

_BEARING_ERROR = 0.3  # the model's own error on a centre-of-pressure bearing [rad]
_FACE_GAIN = 0.3  # how far a landing surely on the face moves the face's height towards its own
_SURE = 0.9  # the belief is sure a landing point is on the chamfer above this capture mass
_PEAK_RADIUS = 0.0002  # the belief's mode: the mean of its particles this near the likeliest [m]
_BEARING_USEFUL = 0.003  # a bearing press is worth its time while its centre of pressure is this sure [m]


class ProbeSearch:
    """The ``probe`` phase, as a motion the strategy plays and steps (module docstring).

    States: ``land`` (a :class:`Landing`, the lateral axes free), ``press`` (on the face, the
    lateral axes held, at the press force: the centre of pressure averaged over ``read_time``),
    ``hop`` (lift, over the next landing point, down to the hover height).

    Attributes:
        landings: landings so far; ``drops``: those that met the chamfer; ``bearings``: the
            bearing presses whose centre of pressure stood out of the noise.
    """

    duration = 0.0

    def __init__(self, strategy: ProbeHost, belief: HoleBelief, quat: _Vec, obs: Observation) -> None:
        self.strategy = strategy
        self.task = strategy.task
        self.cfg = strategy.cfg
        self.belief = belief
        self.quat = quat
        self.landings = self.drops = self.bearings = 0
        self._last_drop: _Vec | None = None  # where the last landing on the chamfer was
        self._trajectory: Motion | None = None
        self._reads: list[tuple[_Vec, _Vec]] = []  # (force, moment) while reading a press
        self._state = "land"
        self._t0 = obs.t
        self._landing = strategy.land(obs)
        self._target = self._landing.target

    def sample(self, t: float) -> GripperTarget:
        return self._target  # set by step(), which keeps the episode's clock

    def step(self, obs: Observation) -> None:
        t = obs.t
        if self._state == "hop":
            assert self._trajectory is not None
            self._target = self._trajectory.sample(t - self._t0)
            if t - self._t0 >= self._trajectory.duration:
                self._landing = self.strategy.land(obs)
                self._target, self._state, self._t0 = self._landing.target, "land", t
        elif self._state == "land":
            if self._landing.update(obs):
                self._landed(obs)
        else:
            self._read(obs)

    def _landed(self, obs: Observation) -> None:
        """Into the belief: how far the landing sank. On the chamfer, on to its believed axis; on
        the face, a bearing press where the sensor can tell one, else the next landing."""
        c, belief, landing, task = self.cfg, self.belief, self._landing, self.task
        a = task.scene.assets
        drop = task.z_face - landing.z
        self.landings += 1
        if drop < c.drop_min and belief.capture_mass(landing.xy) < 1.0 - _SURE:
            # Surely on the face: the face's height, followed (the sensor's drift moves what a
            # landing's force presses into it).
            task.z_face += _FACE_GAIN * (landing.z - task.z_face)
            drop = task.z_face - landing.z
        belief.landing(landing.xy, drop, reach=a.clearance + a.chamfer, sigma=c.drop_sigma)
        if drop >= c.drop_min:
            self.drops += 1
            gap = a.clearance + a.chamfer - drop  # how far the axis is, the chamfer says
            # Back where the last drop was: the chamfer slid the end back from the belief's peak,
            # so the peak is on the wrong side of the ring the drops draw. Circle round it too.
            again = self._last_drop is not None and distance(landing.xy, self._last_drop) < c.circle_reach
            self._last_drop = landing.xy.copy()
            if gap < c.circle_reach or again:  # the axis is close, in some direction: circle round it
                self._circle(obs, max(gap, a.clearance))
            else:
                self._hop(obs, belief.peak(_PEAK_RADIUS))
            return
        if self._bearing_sigma(self.strategy.felt(c.press_force)) < _BEARING_USEFUL:
            s = obs.gripper
            self._target = GripperTarget.trusted(
                s.p_world,
                self.quat,
                np.zeros(3),
                np.zeros(3),
                0.0,
                down(self.strategy.felt(c.press_force)),
                wrench_axes=PRESS_AXES,
            )
            self._state, self._t0, self._reads = "press", obs.t, []
            return
        self._hop(obs, belief.best_probe())

    def _read(self, obs: Observation) -> None:
        """The bearing press: once its push has risen, average the wrench over ``read_time``."""
        task, c = self.task, self.cfg
        force = self.strategy.felt(c.press_force)
        if not self._reads and task.wrist.force[2] < 0.7 * force and obs.t - self._t0 < c.press_time:
            return
        if self._reads or obs.t - self._t0 >= c.settle_time:
            self._reads.append(task.wrist.raw(obs.gripper))
        if len(self._reads) * task.control_dt < c.read_time:
            return
        self._take_bearing(self._reads)
        self._hop(obs, self.belief.best_probe())

    def _take_bearing(self, reads: list[tuple[_Vec, _Vec]]) -> None:
        """The centre of pressure of ``reads`` (force, moment), into the belief where it stands
        out of the noise."""
        f = np.mean([r[0] for r in reads], axis=0)
        m = np.mean([r[1] for r in reads], axis=0)
        towards, kappa = self._bearing(f, m, len(reads))
        if kappa > 0:
            self.bearings += 1
            self.belief.bearing(self._landing.xy, towards, kappa=kappa)

    def _circle(self, obs: Observation, radius: float) -> None:
        """Round a circle of ``radius`` [m] about where the end is, pressing down at the landing
        force: the circle passes over the axis, and there the end drops into the bore."""
        tip = self.task.believed_bottom(obs)
        self._trajectory = PressedCircle(
            self.task, tip, radius, self.quat, self.cfg.circle_speed, self.cfg.land_force
        )
        self._target = self._trajectory.sample(0.0)
        self._state, self._t0 = "hop", obs.t

    def _hop(self, obs: Observation, xy: _Vec) -> None:
        """Lift just enough, over ``xy``, and down to just above where the belief expects the end
        to land there (on the chamfer a move of ``d`` needs a lift of ``d``: its slope is 45 degrees)."""
        task, c, q = self.task, self.cfg, self.quat
        a = task.scene.assets
        tip = task.believed_bottom(obs)
        # Where the end should land: on the chamfer, where the belief is sure of it (else it
        # may meet the face, and must be slow when it does).
        near = float(np.linalg.norm(self.belief.peak(_PEAK_RADIUS) - xy))
        sure = self.belief.capture_mass(xy) > _SURE
        expect = task.z_face - (max(0.0, a.clearance + a.chamfer - near) if sure else 0.0)
        move = float(np.linalg.norm(xy - tip[:2]))
        up = min(task.z_face + c.hop_lift, max(tip[2], expect) + move + c.hover)
        up = max(up, tip[2] + c.hover)
        points = [
            tip,
            np.array([*tip[:2], up]),
            np.array([*xy, up]),
            np.array([*xy, max(expect + c.hover, up - c.hop_lift)]),
        ]
        w = [Waypoint.of(task.pinch_for(p, q), q, 0.0) for p in points]
        fast = self.strategy.quick(c.hop_speed)
        limits = [fast, fast, self.strategy.landing_limits()]
        self._trajectory = TrajectorySequence(
            [task.planner.plan(a0, b0, lim) for a0, b0, lim in zip(w, w[1:], limits, strict=False)]
        )
        self._target = self._trajectory.sample(0.0)
        self._state, self._t0 = "hop", obs.t

    def _bearing_sigma(self, force: float) -> float:
        """The standard deviation of a bearing press's centre of pressure at ``force`` [m]."""
        n = max(1, round(self.cfg.read_time / self.task.control_dt))
        return float(np.hypot(*self.task.wrist.noise_moment[:2])) / math.sqrt(n) / force

    def _bearing(self, force: _Vec, moment: _Vec, n: int) -> tuple[_Vec, float]:
        """Towards the hole from the centre of pressure (unit (2,)), and its concentration: 0
        where the centre of pressure does not stand out of the noise by 2 sigma."""
        fz = float(force[2])
        if fz <= 0.0:
            return np.zeros(2), 0.0
        cop = np.array([-moment[1], moment[0]]) / fz  # from the lower end [m]
        sigma = max(float(np.hypot(*self.task.wrist.noise_moment[:2])) / math.sqrt(n) / fz, 1e-6)
        size = float(np.linalg.norm(cop))
        if size < 2.0 * sigma:
            return np.zeros(2), 0.0
        spread = math.hypot(sigma / size, _BEARING_ERROR)
        return -cop / size, 1.0 / (spread * spread)
