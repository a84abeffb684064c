"""``probe``: flatten the peg on a datum, find the hole by landings a belief chooses, insert fast.

Made for a real wrist sensor. A force reading is noisy, late and biased; the hand's pose is
not. So the strategy *measures with the pose* wherever it can and uses the force sensor for what
only it can tell, at the level its noise allows:

- every contact is a **landing**: a force-controlled descent at the light ``land_force``,
  which stops on whatever it meets; it has landed once the hand has stopped descending (slower
  than ``stop_speed`` for ``stop_time``): no force threshold, so no noise to beat;
- how far the peg's end sank below the face at a landing says face or chamfer, and on the
  chamfer how far the hole's axis is (a 45-degree chamfer: ``clearance + chamfer - drop``);
- on the face, where the sensor's noise lets the centre of pressure stand out (a short press at
  ``press_force``, averaged over ``read_time``; a signal of 2 sigma at least), it points away
  from the hole: the face supports the peg's end on the side away from the hole;
- a :class:`~peg_ctrl.sim.belief.HoleBelief` over the hole's position (prior: a Gaussian of
  ``search_sigma`` about the observed hole, out to ``search_radius``) takes every landing and
  bearing; the next landing goes where the belief is most likely to be caught by the chamfer.

Phases:

- ``approach`` the datum, a point of the block's top face ``datum_offset`` beside the observed
  hole (along the diagonal towards -x, -y), the lower end ``touch_gap`` above it;
- ``touch``: land on it (the first contact);
- ``rock``: the tilt of the peg in the hand, from the pose alone (:class:`RockCalibration`):
  two more landings on the datum with the hand turned by +/- ``rock_angle`` about the pads'
  normal (the only axis the pads let the peg turn about); the three landing heights fix the
  tilt and the face's height (a least-squares fit); the task revises its belief of the peg's
  axis (:meth:`HeldInsertion.revise_axis`). No moment is read: about the tip, the sensor's
  force noise times its 0.17 m lever swamps the moment a flat-pressing end makes;
- ``reference``: lift, land again on the datum: the face's height for the landings to come, at
  their own force;
- ``transfer`` over the first landing point;
- ``probe``: landings and bearing presses, as above, until the lower end is believed in the bore
  (a landing on the believed axis goes on down it);
- ``centre``: the lower end, in the bore's mouth, pushed against its walls along +x, -x, +y,
  -y in turn (the stops read from the pose); the bore's axis is midway between them. A push
  that reverses the one before starts from the contact loop's command, still pressed into the
  wall just found, unless ``centre_reanchor`` (then from where the hand is: without it the
  hand can stand still at the old wall and be read there, docs/contact_real.md);
- ``insert``: ``relax_time`` still on that axis, then a jerk-limited descent at
  ``insert_speed`` to ``seat_margin`` below the seated depth, the pose tracked on every axis (a
  peg centred and upright in its bore touches no wall; with the lateral forces free the contact
  MPC's accommodation taps the walls, 60 N at friction 0.9: ``insert_free`` frees them anyway);
- ``hold`` still once the seated detection fires (depth reached, the hand at rest within the
  noise of its speed sensing), pushing no more.

The bearing press and the centring's pushes are at least twice what the task's contact detection
needs to tell a push from the sensor's noise; a landing is not: its stop is read from the pose.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import MotionLimits, Waypoint
from peg_ctrl.sim.belief import HoleBelief
from peg_ctrl.sim.rotations import quat_mul, rotate
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout, TrajectorySequence
from peg_ctrl.tasks.strategies.base import HeldInsertion, Strategy, StrategyConfig, TaskDisturbance, never
from peg_ctrl.tasks.strategies.motions import Guided, Hold, about, down

__all__ = ["ProbeConfig", "ProbeStrategy", "ProbeSearch", "Landing", "WallPush"]

_Vec = np.ndarray
PRESS_AXES = (False, False, True, False, False, False)  # press along z, the pose held otherwise
LAND_AXES = (True, True, True, False, False, False)  # press along z, lateral forces free
SLIDE_AXES = (True, True, False, False, False, False)  # lateral forces free, z and orientation tracked
NO_AXES = (False,) * 6  # the pose tracked on every axis
_BEARING_ERROR = 0.3  # the model's own error on a centre-of-pressure bearing [rad]


@dataclasses.dataclass(frozen=True)
class ProbeConfig(StrategyConfig):
    """Distances [m], forces [N], angles [rad], speeds [m/s], accelerations [m/s^2], times [s]."""

    name: ClassVar[str] = "probe"
    phases: ClassVar[tuple[str, ...]] = (
        "approach",
        "touch",
        "rock",
        "reference",
        "transfer",
        "probe",
        "centre",
        "insert",
        "hold",
    )
    datum_offset: float = 0.03  # the datum, this far from the observed hole towards -x, -y
    touch_gap: float = 0.0008  # the approach stops the lower end this far above the face
    land_force: float = 1.0  # every landing's press (lateral forces free)
    stop_speed: float = 0.0005  # a landing has stopped once it descends slower than this ...
    stop_time: float = 0.01  # ... for this long
    rock_angle: float = (
        0.05  # the calibration lands the peg turned this far either way about the pads' normal
    )
    max_tilt: float = 0.08  # the calibration looks for a tilt in the hand up to this
    rock_time: float = 1.5  # budget of the calibration
    search_radius: float = 0.0055  # the belief's extent about the observed hole
    search_sigma: float = 0.002  # its prior's standard deviation
    hover: float = 0.0002  # a landing starts with the end this far above the face
    hop_lift: float = 0.0004  # lift between landings
    hop_speed: float = 0.05  # lateral speed of a hop
    move_accel: float = 3.0  # acceleration of the transfer and the hops
    drop_min: float = 0.00004  # a landing this far below the face is on the chamfer
    drop_sigma: float = 0.000015  # how well a landing's depth below the face is known
    circle_reach: float = 0.00015  # a landing this near the axis (the chamfer says) circles round it
    circle_speed: float = 0.002  # ... at this speed, pressing
    press_force: float = 2.0  # the bearing press on the face
    settle_time: float = 0.03  # it is read once its push has risen to 70 % (or after press_time) ...
    read_time: float = 0.06  # ... over this window
    press_time: float = 0.3
    probe_time: float = 6.0  # budget of the search
    wall_force: float = 3.0  # centring: the lateral push that finds each wall of the bore's mouth
    centre_time: float = 1.0  # budget of the centring
    centre_in_mouth: bool = True  # the bore's axis from its walls (else down from where the end entered)
    centre_reanchor: bool = False  # a reversed centring push starts from where the hand is
    relax_time: float = 0.05  # on the bore's axis, still first
    insert_speed: float = 0.08  # the descent into the bore
    insert_accel: float = 2.0
    insert_free: bool = False  # the descent leaves the lateral forces free (else the pose is tracked)
    seat_margin: float = 0.0015  # the descent aims this far below the seated depth
    insert_time: float = 2.0  # budget of the descent
    hold_time: float = 1.0  # budget of the final hold

    def build(self, task: HeldInsertion) -> ProbeStrategy:
        return ProbeStrategy(task, self)

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        """The datum must lie on the top face, clear of the hole whatever the disturbance."""
        a = scene.assets
        half = 0.5 * min(a.block_size[0], a.block_size[1])
        reach = self.datum_offset / math.sqrt(2.0) + a.peg_radius
        if reach >= half - 0.002:
            raise ConfigError(
                f"task.strategy.datum_offset: the datum reaches {reach * 1e3:.1f} mm from the hole along x "
                f"and y, beyond the block's top face ({half * 1e3:.1f} mm)"
            )
        mouth = a.peg_radius + a.clearance + a.chamfer
        lean = (task.grip_above_centre + 0.5 * a.peg_length) * math.sin(task.tilt_error)
        error = task.lateral_error + lean + 3.0 * task.position_noise
        if self.datum_offset - a.peg_radius - error <= mouth + 0.001:
            raise ConfigError(
                f"task.strategy.datum_offset: {self.datum_offset!r} m puts the datum within 1 mm of the "
                f"hole's mouth for a lateral error of {error * 1e3:.2f} mm; must be > "
                f"{mouth + 0.001 + a.peg_radius + error:.4g} m"
            )
        if self.drop_min >= a.clearance + a.chamfer:
            raise ConfigError(
                f"task.strategy.drop_min must be below the chamfer's capture "
                f"({(a.clearance + a.chamfer) * 1e3:.2f} mm), got {self.drop_min!r}"
            )


class Landing:
    """A force-controlled descent at ``force`` [N] (``axes``: what else is free) from where the
    hand is; it has landed once the hand descends slower than ``stop_speed`` for ``stop_time``
    (or the noise of the speed sensing's k sigma, where that is more), after it has moved or
    after 50 ms. ``z`` and ``xy`` are then the believed lower end's mean height and position
    over that window [m]."""

    def __init__(
        self, task: HeldInsertion, cfg: ProbeConfig, obs: Observation, force: float, axes: tuple[bool, ...]
    ) -> None:
        self.task, self.cfg = task, cfg
        s = obs.gripper
        self.target = GripperTarget.trusted(
            s.p_world, s.quat_world, np.zeros(3), np.zeros(3), 0.0, down(force), wrench_axes=axes
        )
        self._t0 = obs.t
        self._moved = False
        self._still: list[tuple[float, _Vec]] = []
        self.landed = False
        self.t_landed = 0.0
        self.z = 0.0
        self.xy = np.zeros(2)
        self.p_world = np.zeros(3)  # the hand's pose when it landed (mean position)
        self.quat_world = np.array([1.0, 0.0, 0.0, 0.0])

    def update(self, obs: Observation) -> bool:
        """Whether it has landed (true from then on)."""
        if self.landed:
            return True
        task, c = self.task, self.cfg
        limit = max(c.stop_speed, task.contact.k_on * task.speed_noise)
        speed = abs(float(task.hand_velocity[2]))
        self._moved = self._moved or speed > 2.0 * limit
        if speed >= limit or not (self._moved or obs.t - self._t0 > 0.05):
            self._still = []
            return False
        self._still.append((obs.t, task.believed_bottom(obs)))
        if self._still[-1][0] - self._still[0][0] < c.stop_time:
            return False
        tips = np.array([tip for _, tip in self._still])
        self.z, self.xy = float(tips[:, 2].mean()), tips[:, :2].mean(axis=0)
        self.p_world = obs.gripper.p_world + (tips.mean(axis=0) - tips[-1])
        self.quat_world = obs.gripper.quat_world.copy()
        self.landed = True
        self.t_landed = obs.t
        return True


class ProbeStrategy(Strategy):
    cfg: ProbeConfig

    def __init__(self, task: HeldInsertion, config: ProbeConfig) -> None:
        super().__init__(task, config)
        self._hold = Hold(
            GripperTarget.trusted(np.zeros(3), (1.0, 0.0, 0.0, 0.0), np.zeros(3), np.zeros(3), 0.0)
        )
        self.rock: RockCalibration | None = None
        self.centring: Centring | None = None
        self.quat_upright = np.array([1.0, 0.0, 0.0, 0.0])  # the hand's orientation with the peg upright
        self.landing: Landing | None = None
        self.search: ProbeSearch | None = None
        self.belief: HoleBelief | None = None
        #: The believed lower end is where the peg's end is (found by touch), not only where the
        #: nominal grasp puts it: the tilt calibration then turns the axis about the end.
        self.end_known = False

    def phase_table(self) -> dict[str, PhaseSpec]:
        c, t = self.cfg, self.task
        return {
            "approach": PhaseSpec(
                self._enter_datum, self._motion_done, "touch", Timeout(1.0, True), tick=t.feel_free
            ),
            "touch": PhaseSpec(self._enter_touch, self._landed, self._after_touch, Timeout(1.0), tick=t.feel),
            "rock": PhaseSpec(
                self._enter_rock, self._rocked, "reference", Timeout(c.rock_time), tick=self._rock
            ),
            "reference": PhaseSpec(
                self._enter_reference, self._referenced, "transfer", Timeout(0.6), tick=t.feel
            ),
            "transfer": PhaseSpec(
                self._enter_transfer, self._motion_done, "probe", Timeout(0.5, True), tick=t.feel_free
            ),
            "probe": PhaseSpec(
                self._enter_probe, self._found, self._after_probe, Timeout(c.probe_time), tick=self._probe
            ),
            "centre": PhaseSpec(
                self._enter_centre, self._centred, "insert", Timeout(c.centre_time), tick=self._centring
            ),
            "insert": PhaseSpec(
                self._enter_insert, self._seated, "hold", Timeout(c.insert_time), tick=t.feel
            ),
            "hold": PhaseSpec(self._enter_hold, never, DONE, Timeout(c.hold_time), tick=t.feel),
        }

    # -- helpers ------------------------------------------------------------------------------------
    def tip_offset(self) -> _Vec:
        """The believed lower end from the pinch point, gripper frame [m]."""
        t = self.task
        return t.grasp_body - t.grip_length * t.up_body

    def tip_waypoint(self, tip: _Vec, q: _Vec) -> Waypoint:
        return Waypoint.of(self.task.pinch_for(tip, q), q, 0.0)

    def felt(self, force: float) -> float:
        """``force`` [N], or twice what the contact detection needs to see a push if that is more."""
        t = self.task
        return max(force, 2.0 * t.contact.k_on * float(t.wrist.sigma_force[2]))

    def land(self, obs: Observation, axes: tuple[bool, ...] = LAND_AXES) -> Landing:
        """A landing from where the hand is, at the landing force (its stop is read from the
        pose, so the force need not stand out of the sensor's noise: the force loop averages it)."""
        return Landing(self.task, self.cfg, obs, self.cfg.land_force, axes)

    def quick(self, v_lin: float | None = None) -> MotionLimits:
        """The task's limits with ``move_accel`` and stiff jerks: short moves near the block."""
        c, lim = self.cfg, self.task.limits
        return dataclasses.replace(
            lim, v_lin=v_lin or lim.v_lin, a_lin=c.move_accel, j_lin=100.0, a_rot=40.0, j_rot=2000.0
        )

    def landing_limits(self) -> MotionLimits:
        """The last descent onto the hover height: slow, so that the hand does not overshoot
        into the face."""
        return dataclasses.replace(self.task.limits, v_lin=0.005, a_lin=0.5, j_lin=50.0)

    def _held(self, target: GripperTarget) -> Hold:
        self._hold.target = target
        return self._hold

    def _landed(self, obs: Observation) -> str | None:
        assert self.landing is not None
        return "landed" if self.landing.update(obs) else None

    # -- datum, touch, align, reference ----------------------------------------------------------------
    def _enter_datum(self, obs: Observation) -> Motion:
        return self.task.move(self.datum_waypoint(np.asarray(self.task.goal.quat_world)))

    def datum_waypoint(self, q: _Vec) -> Waypoint:
        """The lower end ``touch_gap`` above the datum, the hand at ``q``."""
        t, c = self.task, self.cfg
        off = c.datum_offset / math.sqrt(2.0)
        tip = np.array([t.observed_hole[0] - off, t.observed_hole[1] - off, t.block_top + c.touch_gap])
        return self.tip_waypoint(tip, q)

    def _enter_touch(self, obs: Observation) -> Motion:
        self.landing = self.land(obs, PRESS_AXES)
        return self._held(self.landing.target)

    def _after_touch(self, obs: Observation) -> str:
        assert self.landing is not None
        return "rock" if self.landing.landed else DONE

    def _enter_rock(self, obs: Observation) -> Motion:
        assert self.landing is not None
        self.rock = RockCalibration(self, self.landing, obs)
        return self.rock

    def _rock(self, obs: Observation) -> None:
        self.task.feel(obs)
        assert self.rock is not None
        self.rock.step(obs)

    def _rocked(self, obs: Observation) -> str | None:
        assert self.rock is not None
        return "calibrated" if self.rock.tilt is not None else None

    def _enter_reference(self, obs: Observation) -> Motion:
        """Revise the grasp from the calibration (a timed-out one leaves it be); the orientation
        that turns the peg upright; lift off the datum, land on it again, flat."""
        t = self.task
        assert self.rock is not None
        if self.rock.tilt is not None:
            # An end located by touch stays where it was found: the grasp point moves instead.
            shift = t.grip_length * (self.rock.axis_body - t.up_body) if self.end_known else None
            t.revise_axis(self.rock.axis_body, obs.gripper, grasp_shift=shift)
        q = self.quat_upright = upright(t.up_body, self.rock.q0)
        # Up clear of the face (by as much as the turn can lower the end's rim), turn upright,
        # down to just above the face.
        c = self.cfg
        s = obs.gripper
        clear = t.radius * math.sin(c.rock_angle + c.max_tilt) + c.hover
        tip = t.believed_bottom(obs)
        lifted = tip + np.array([0.0, 0.0, clear])
        turned = np.array([*tip[:2], max(tip[2], self.rock.z_face) + clear])
        near = np.array([*tip[:2], self.rock.z_face + c.hop_lift])
        over = np.array([*tip[:2], self.rock.z_face + c.hover])  # upright, just above the face
        w = [Waypoint.of(s.p_world, s.quat_world, 0.0), self.tip_waypoint(lifted, s.quat_world)]
        w += [self.tip_waypoint(turned, q), self.tip_waypoint(near, q), self.tip_waypoint(over, q)]
        t.goal = w[-1]
        self.landing = None
        self._hold.target = GripperTarget.trusted(np.asarray(w[-1].p_world), q, np.zeros(3), np.zeros(3), 0.0)
        limits = [self.quick(), self.quick(), self.quick(), self.landing_limits()]
        parts = [t.planner.plan(a, b, lim) for a, b, lim in zip(w, w[1:], limits, strict=False)]
        return TrajectorySequence([*parts, self._hold])

    def _referenced(self, obs: Observation) -> str | None:
        """Once lifted, land; the landing's height is the face's."""
        t = self.task
        if self.landing is None:
            if not t.machine.motion_over(obs.t):
                return None
            self.landing = self.land(obs, PRESS_AXES)
            self._hold.target = self.landing.target
            return None
        if not self.landing.update(obs):
            return None
        t.z_face = self.landing.z
        return "landed"

    # -- transfer and probe ----------------------------------------------------------------------------
    def _enter_transfer(self, obs: Observation) -> Motion:
        """Lift, over the belief's first landing point, down to the hover height."""
        t, c, a = self.task, self.cfg, self.task.scene.assets
        q = np.asarray(t.goal.quat_world)
        centre, sigma, radius = self.hole_prior()
        self.belief = HoleBelief(
            (float(centre[0]), float(centre[1])),
            radius=radius,
            sigma=sigma,
            capture=a.clearance + a.chamfer - c.drop_min,
        )
        first = self.belief.best_probe()
        here = Waypoint.of(obs.gripper.p_world, q, 0.0)
        up = t.believed_bottom(obs) + np.array([0.0, 0.0, 0.0008])
        tips = [up, np.array([*first, up[2]]), np.array([*first, t.z_face + c.hop_lift])]
        hover = np.array([*first, t.z_face + c.hover])
        fast = self.quick()
        parts = [t.planner.plan(here, self.tip_waypoint(up, q), fast)]
        parts += [
            t.planner.plan(self.tip_waypoint(a, q), self.tip_waypoint(b, q), fast)
            for a, b in zip(tips, tips[1:], strict=False)
        ]
        parts.append(
            t.planner.plan(self.tip_waypoint(tips[-1], q), self.tip_waypoint(hover, q), self.landing_limits())
        )
        t.goal = self.tip_waypoint(hover, q)
        return TrajectorySequence(parts)

    def hole_prior(self) -> tuple[_Vec, float, float]:
        """The search's prior over the hole: its centre (x, y) [m], standard deviation [m] and
        extent [m]: the observed hole, ``search_sigma``, ``search_radius``."""
        t, c = self.task, self.cfg
        return np.asarray(t.observed_hole, dtype=float), c.search_sigma, c.search_radius

    def _enter_probe(self, obs: Observation) -> Motion:
        assert self.belief is not None
        self.search = ProbeSearch(self, self.belief, np.asarray(self.task.goal.quat_world), obs)
        return self.search

    def _probe(self, obs: Observation) -> None:
        self.task.feel(obs)
        assert self.search is not None
        self.search.step(obs)

    def _found(self, obs: Observation) -> str | None:
        return self.task.in_bore(obs)

    def _after_probe(self, obs: Observation) -> str:
        if not self.task.in_bore(obs):
            return DONE
        return "centre" if self.cfg.centre_in_mouth else "insert"

    # -- centre in the bore's mouth -----------------------------------------------------------------------
    def _enter_centre(self, obs: Observation) -> Motion:
        self.centring = Centring(self, obs)
        return self.centring

    def _centring(self, obs: Observation) -> None:
        self.task.feel(obs)
        assert self.centring is not None
        self.centring.step(obs)

    def _centred(self, obs: Observation) -> str | None:
        assert self.centring is not None
        return "centred" if self.centring.centre is not None else None

    # -- insert and hold ----------------------------------------------------------------------------
    def _enter_insert(self, obs: Observation) -> Motion:
        """Still and laterally free for ``relax_time``, then down the bore at ``insert_speed``."""
        t, c = self.task, self.cfg
        q = np.asarray(t.goal.quat_world)
        # Start where the lower end is, upright (the relax dwell turns the hand about the end, whose
        # mouth holds it), then straight down: the pinch moves along the peg's axis only.
        tip = t.believed_bottom(obs)
        if self.centring is not None and self.centring.centre is not None:
            tip[:2] = self.centring.centre
        here = self.tip_waypoint(tip, q)
        tip[2] = t.block_top - t.min_depth - c.seat_margin
        goal = self.tip_waypoint(tip, q)
        limits = dataclasses.replace(t.limits, v_lin=c.insert_speed, a_lin=c.insert_accel)
        t.goal = goal
        return Guided(t.planner.plan(here, goal, limits), self._insert_axes, delay=c.relax_time)

    @property
    def _insert_axes(self) -> tuple[bool, ...]:
        return SLIDE_AXES if self.cfg.insert_free else NO_AXES

    def _seated(self, obs: Observation) -> str | None:
        t = self.task
        return "seated" if t.machine.motion_over(obs.t) and t.seated_detected(obs) else None

    def _enter_hold(self, obs: Observation) -> Motion:
        s = obs.gripper
        return self._held(
            GripperTarget.trusted(
                s.p_world,
                self.task.goal.quat_world,
                np.zeros(3),
                np.zeros(3),
                0.0,
                wrench_axes=self._insert_axes,
            )
        )


class RockCalibration:
    """The peg's tilt in the hand from the heights at which it lands (module docstring).

    The pads let the peg turn only about their normal (the gripper's x): its axis is the
    nominal one turned by ``theta`` about it. A peg tilted in total by ``a`` lands with its end's
    centre ``R sin a`` above the face, and the hand's pose says where that centre is for a given
    ``theta``; three landings (the touch, and the hand turned by +/- ``rock_angle`` about the
    pads' normal through the believed lower end) fix ``theta`` and the face's height. Each
    landing starts from just above the highest height the touch allows for it.

    Attributes:
        tilt: the fitted ``theta`` [rad], None until the third landing; ``axis_body``: the
            peg's axis in the gripper frame; ``z_face``: the face's height the fit gives [m];
            ``q0``: the hand's orientation at the touch.
    """

    duration = 0.0
    #: The believed lower end is the true one (found by touch): the fit turns the axis about it.
    end_known = False

    def __init__(self, strategy: ProbeStrategy, touch: Landing, obs: Observation) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        self.end_known = strategy.end_known
        self.q0 = touch.quat_world.copy()
        self.landings = [touch]
        self.tilt: float | None = None
        self.axis_body = self.task.up_body
        self.z_face = self.task.block_top
        self._angles = [self.cfg.rock_angle, -self.cfg.rock_angle]
        self._thetas = np.linspace(-self.cfg.max_tilt, self.cfg.max_tilt, 321)
        self._next(obs)

    def sample(self, t: float) -> GripperTarget:
        return self._target

    def _model(self, q: _Vec, theta: float) -> tuple[_Vec, float]:
        """For a tilt ``theta`` in the hand at orientation ``q``: the true lower end's offset
        from the believed one (world) [m], and how far the end's lowest point is below its
        centre [m]."""
        t = self.task
        up = _turned(t.up_body, PAD_NORMAL, theta)
        # An end located by touch is where the task believes it, whatever the tilt.
        offset = np.zeros(3) if self.end_known else rotate(q, t.grip_length * (t.up_body - up))
        a = rotate(q, up)
        return offset, t.radius * math.sqrt(max(0.0, 1.0 - a[2] * a[2]))

    def _faces(self, landing: Landing) -> _Vec:
        """The face's height each tilt of the grid implies for ``landing`` [m]."""
        tip = landing.p_world + rotate(
            landing.quat_world, self.task.grasp_body - self.task.grip_length * self.task.up_body
        )
        out = np.empty(len(self._thetas))
        for k, theta in enumerate(self._thetas):
            offset, rim = self._model(landing.quat_world, float(theta))
            out[k] = tip[2] + offset[2] - rim
        return out

    def _next(self, obs: Observation) -> None:
        """Lift, turn to the next angle about the believed lower end, down to just above the
        highest contact the landings so far allow, then land."""
        t, c, st = self.task, self.cfg, self.strategy
        angle = self._angles[len(self.landings) - 1]
        q = quat_mul(about(rotate(self.q0, PAD_NORMAL), angle), self.q0)
        # The tilts the landings so far allow, given the face's height on the drawing (to within
        # how far a landing presses into it) and that it is one face: the next landing starts
        # just above the highest of them.
        faces = np.array([self._faces(landing) for landing in self.landings])
        allowed = np.all(np.abs(faces - (t.block_top - 0.5 * _FACE_TOLERANCE)) <= _FACE_TOLERANCE, axis=0)
        allowed &= np.ptp(faces, axis=0) <= 0.5 * _FACE_TOLERANCE
        pick = allowed if allowed.any() else np.ones(len(self._thetas), dtype=bool)
        candidates = zip(self._thetas[pick], faces[0, pick], strict=True)
        highest = max(
            z_face + self._model(q, float(theta))[1] - self._model(q, float(theta))[0][2]
            for theta, z_face in candidates
        )
        # Up clear of the face first (by as much as the turn can lower the end's rim), turn
        # about the pinch point (the end moves a few millimetres over the datum's face, which has
        # room for it), down to just above the contact.
        s = obs.gripper
        clear = t.radius * math.sin(abs(angle) + c.max_tilt) + c.hover
        lifted = s.p_world + np.array([0.0, 0.0, clear])
        turned = lifted.copy()
        turned[2] = max(highest, t.believed_bottom(obs)[2]) + clear - rotate(q, st.tip_offset())[2]
        near, above = turned.copy(), turned.copy()
        near[2] = highest + c.hop_lift - rotate(q, st.tip_offset())[2]
        above[2] = highest + c.hover - rotate(q, st.tip_offset())[2]
        w = [Waypoint.of(s.p_world, s.quat_world, 0.0), Waypoint.of(lifted, s.quat_world, 0.0)]
        w += [Waypoint.of(turned, q, 0.0), Waypoint.of(near, q, 0.0), Waypoint.of(above, q, 0.0)]
        limits = [st.quick(), st.quick(), st.quick(), st.landing_limits()]
        self._trajectory = TrajectorySequence(
            [t.planner.plan(a, b, lim) for a, b, lim in zip(w, w[1:], limits, strict=False)]
        )
        self._target = self._trajectory.sample(0.0)
        self._state, self._t0 = "move", obs.t

    def step(self, obs: Observation) -> None:
        if self.tilt is not None:
            return
        if self._state == "move":
            self._target = self._trajectory.sample(obs.t - self._t0)
            if obs.t - self._t0 >= self._trajectory.duration:
                self._landing = self.strategy.land(obs, PRESS_AXES)
                self._target, self._state = self._landing.target, "land"
            return
        if not self._landing.update(obs):
            return
        self.landings.append(self._landing)
        if len(self.landings) <= len(self._angles):
            self._next(obs)
            return
        self._fit()

    def _fit(self) -> None:
        """Least squares over the tilt grid (the face's height the same for every landing),
        refined by a parabola through the best three."""
        faces = np.array([self._faces(landing) for landing in self.landings])
        cost = faces.var(axis=0)
        k = int(np.clip(np.argmin(cost), 1, len(cost) - 2))
        c0, c1, c2 = cost[k - 1 : k + 2]
        curve = c0 - 2.0 * c1 + c2
        step = float(self._thetas[1] - self._thetas[0])
        self.tilt = float(self._thetas[k]) + (0.5 * step * (c0 - c2) / curve if curve > 0 else 0.0)
        self.axis_body = _turned(self.task.up_body, PAD_NORMAL, self.tilt)
        self.z_face = float(np.mean(faces[:, k]))


_FACE_TOLERANCE = 0.0002  # a landing's height on the face matches the drawing's to this [m]
PAD_NORMAL = np.array([1.0, 0.0, 0.0])  # the jaw's closing direction, gripper frame: the peg turns about it


def _turned(v: _Vec, axis: _Vec, angle: float) -> _Vec:
    """``v`` turned by ``angle`` [rad] about unit ``axis``."""
    return rotate(about(axis, angle), v)


def upright(up_body: _Vec, q0: _Vec) -> _Vec:
    """The hand orientation nearest ``q0`` that points the peg's axis ``up_body`` straight up."""
    up_world = rotate(q0, up_body)
    axis = np.cross(up_world, np.array([0.0, 0.0, 1.0]))
    n = float(np.linalg.norm(axis))
    if n < 1e-12:
        return np.asarray(q0, dtype=float)
    return quat_mul(about(axis / n, math.atan2(n, float(up_world[2]))), q0)


class Centring:
    """The lower end, in the bore's mouth, to the bore's axis: pushed laterally (``wall_force``)
    against the wall along +x, -x, +y, -y in turn, the height held; each push has found its wall
    once the hand stops moving (the pose, not the force, tells). The centre is midway between the
    walls; a push that finds no wall within ``centre_time`` leaves the centre where the end was.

    Attributes:
        walls: the lower end's position (x, y) [m] at each wall found; ``centre``: the bore's axis
            at the mouth, None until all four are found.
    """

    duration = 0.0
    _DIRECTIONS = (np.array([1.0, 0.0]), np.array([-1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.0, -1.0]))

    def __init__(self, strategy: ProbeStrategy, obs: Observation) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        self.walls: list[_Vec] = []
        self.centre: _Vec | None = None
        self._start = obs.gripper.p_world.copy()
        self._p: _Vec = self._start.copy()  # the pushes' held position
        self._reanchored = False  # the pose held for a tick before a reversed push
        self._push(obs)

    def sample(self, t: float) -> GripperTarget:
        return self._target

    def _push(self, obs: Observation) -> None:
        """Along the next direction, the other lateral axis held (at the middle of the x walls,
        once found: a chord through the axis). With ``centre_reanchor``, a push that reverses
        the last one is preceded by one tick of the pose held where the hand is: the axis stays
        force-controlled across a reversal, so the contact loop would go on from its command,
        pressed into the wall just found, and the hand would stand still there (a wall read on
        the wrong side) while the command backs out."""
        n = len(self.walls)
        p = obs.gripper.p_world.copy()
        p[2] = self._start[2]
        if n == 2:  # the x walls found: over to the middle between them
            p[0] += 0.5 * (self.walls[0][0] + self.walls[1][0]) - self.task.believed_bottom(obs)[0]
        self._p = p if n != 3 else self._p
        anchor = self._p
        if n % 2 and self.cfg.centre_reanchor:
            anchor = self._p.copy()
            anchor[n // 2] = obs.gripper.p_world[n // 2]  # along the push: where the hand is
            if not self._reanchored:
                quat = self.strategy.quat_upright
                self._target = GripperTarget.trusted(anchor, quat, np.zeros(3), np.zeros(3), 0.0)
                self._reanchored = True
                return
        self._reanchored = False
        self._wall = WallPush(self.strategy, obs, anchor, self.strategy.quat_upright, self._DIRECTIONS[n])
        self._target = self._wall.target

    def step(self, obs: Observation) -> None:
        if self.centre is not None:
            return
        if self._reanchored:  # the tick with the pose held is over: push
            self._push(obs)
            return
        wall = self._wall.update(obs)
        if wall is None:
            return
        self.walls.append(wall)
        if len(self.walls) < len(self._DIRECTIONS):
            self._push(obs)
            return
        w = self.walls
        self.centre = np.array([0.5 * (w[0][0] + w[1][0]), 0.5 * (w[2][1] + w[3][1])])


class WallPush:
    """The hand at ``p_world`` and ``quat``, pushing along the horizontal unit ``direction``
    (x or y) at the wall force (that lateral axis free, the rest held): a wall is found once the
    hand has been still (its filtered speed within the stop speed's half, or k sigma of the speed
    sensing's noise) for twice the landings' stop time, after ``_WALL_SETTLE``. :meth:`update`
    then gives the believed lower end's mean (x, y) [m] over that stillness."""

    def __init__(
        self, strategy: ProbeStrategy, obs: Observation, p_world: _Vec, quat: _Vec, direction: _Vec
    ) -> None:
        self.task, self.cfg = strategy.task, strategy.cfg
        axes = (bool(direction[0]), bool(direction[1]), False, False, False, False)
        force = np.array([*(strategy.felt(self.cfg.wall_force) * direction), 0.0])
        self.target = GripperTarget.trusted(
            p_world, quat, np.zeros(3), np.zeros(3), 0.0, force, wrench_axes=axes
        )
        self._t0 = obs.t
        self._still: list[_Vec] = []

    def update(self, obs: Observation) -> _Vec | None:
        c, task = self.cfg, self.task
        v = float(np.hypot(*task.hand_velocity[:2]))
        limit = max(0.5 * c.stop_speed, task.contact.k_on * task.speed_noise)
        if v >= limit or obs.t - self._t0 < _WALL_SETTLE:
            self._still = []
            return None
        self._still.append(task.believed_bottom(obs)[:2])
        if len(self._still) * task.control_dt < 2.0 * c.stop_time:
            return None
        return np.mean(self._still, axis=0)


class PressedCircle:
    """A circle of ``radius`` [m] about the lower end's position ``tip`` in the horizontal plane,
    at ``speed`` [m/s], once round, pressing down with ``force`` [N] (the height free)."""

    def __init__(
        self, task: HeldInsertion, tip: _Vec, radius: float, quat: _Vec, speed: float, force: float
    ) -> None:
        self.task, self.tip, self.radius, self.quat = task, np.asarray(tip, dtype=float), radius, quat
        self.rate = speed / radius  # [rad/s]
        self.duration = 2.0 * math.pi / self.rate + 0.5 * radius / speed
        self._force = down(force)

    def sample(self, t: float) -> GripperTarget:
        # out to the circle along x first (a quarter of the duration's lead-in), then round it
        lead = 0.5 * self.radius / (self.rate * self.radius)
        if t < lead:
            r, a, w = self.radius * t / lead, 0.0, 0.0
        else:
            r, a, w = self.radius, self.rate * (t - lead), self.rate
        p_tip = self.tip + np.array([r * math.cos(a), r * math.sin(a), 0.0])
        v = np.array([-r * w * math.sin(a), r * w * math.cos(a), 0.0])
        p = self.task.pinch_for(p_tip, self.quat)
        return GripperTarget.trusted(p, self.quat, v, np.zeros(3), 0.0, self._force)


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

    def __init__(self, strategy: ProbeStrategy, belief: HoleBelief, quat: _Vec, obs: Observation) -> None:
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
            again = self._last_drop is not None and _distance(landing.xy, self._last_drop) < c.circle_reach
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


_WALL_SETTLE = 0.04  # a push for a wall is watched for a stop only after this long [s]
_FACE_GAIN = 0.3  # how far a landing surely on the face moves the face's height towards its own
_SURE = 0.9  # the belief is sure a landing point is on the chamfer above this capture mass
_PEAK_RADIUS = 0.0002  # the belief's mode: the mean of its particles this near the likeliest [m]
_BEARING_USEFUL = 0.003  # a bearing press is worth its time while its centre of pressure is this sure [m]


def _distance(a: _Vec, b: _Vec) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))


def _angle(a: _Vec, b: _Vec) -> float:
    """The angle between two orientations [rad]."""
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(a, b)))))
