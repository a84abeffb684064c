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
- ``rock``: the tilt of the peg in the hand from the pose alone, two more landings turned by
  +/- ``rock_angle`` about the pads' normal (:class:`RockCalibration`); the task revises its
  belief of the axis. No moment is read: the sensor's noise at its 0.17 m lever swamps it;
- ``reference``: lift, land again on the datum: the face's height for the landings to come, at
  their own force;
- ``transfer`` over the first landing point;
- ``probe``: landings and bearing presses, as above, until the lower end is believed in the bore
  (a landing on the believed axis goes on down it);
- ``centre``: the lower end, in the bore's mouth, pushed against its walls (:class:`Centring`,
  ``centre_reanchor``: docs/contact_real.md); the bore's axis is midway between them;
- ``insert``: ``relax_time`` still on that axis, then down at ``insert_speed`` to ``seat_margin``
  below the seated depth, the pose tracked (``insert_free`` frees the lateral forces: the contact
  MPC's accommodation then taps the walls, 60 N at friction 0.9);
- ``hold`` still once the seated detection fires (depth reached, the hand at rest within the
  noise of its speed sensing), pushing no more.

The bearing press and the centring's pushes are at least twice what the task's contact detection
needs to tell a push from the sensor's noise; a landing is not: its stop is read from the pose.
The touches are skills of their own (:mod:`peg_ctrl.tasks.strategies.skills`): this plays them.
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
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout, TrajectorySequence
from peg_ctrl.tasks.strategies.base import HeldInsertion, Strategy, StrategyConfig, TaskDisturbance, never
from peg_ctrl.tasks.strategies.motions import Guided, Hold
from peg_ctrl.tasks.strategies.skills import (
    LAND_AXES,
    NO_AXES,
    PRESS_AXES,
    SLIDE_AXES,
    Centring,
    Landing,
    ProbeSearch,
    RockCalibration,
    upright,
)
from peg_ctrl.tasks.strategies.skills.models import SkillNoise, observe

__all__ = ["ProbeConfig", "ProbeStrategy"]

_Vec = np.ndarray


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

    def noise(self) -> SkillNoise:
        """What the skills' readings' noise is made of (:mod:`~peg_ctrl.tasks.strategies.skills.models`)."""
        return SkillNoise.of(self.task, self.cfg.rock_angle)

    def observe(self, skill: str, value: _Vec | list[float], obs: Observation) -> None:
        """``skill``'s reading into the task's belief, through its measurement model."""
        observe(self.task, skill, value, obs.t, self.noise())

    def observe_rock(self, obs: Observation) -> None:
        """The rock's reading into the task's belief (the tilt and the face's height)."""
        assert self.rock is not None and self.rock.tilt is not None
        self.observe("rock", [self.rock.tilt, self.rock.z_face], obs)

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
            self.observe_rock(obs)
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
            if not self.motion_over(obs):
                return None
            self.landing = self.land(obs, PRESS_AXES)
            self._hold.target = self.landing.target
            return None
        if not self.landing.update(obs):
            return None
        self.observe("face", [self.landing.z], obs)
        t.z_face = self.landing.z
        return "landed"

    # -- transfer and probe ----------------------------------------------------------------------------
    def _enter_transfer(self, obs: Observation) -> Motion:
        """Lift, over the belief's first landing point, down to the hover height."""
        t, c = self.task, self.cfg
        q = np.asarray(t.goal.quat_world)
        self.belief = self.search_belief()
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

    def capture(self) -> float:
        """How far from the axis a landing is caught by the chamfer, as the search sees it [m]."""
        a = self.task.scene.assets
        return a.clearance + a.chamfer - self.cfg.drop_min

    def search_belief(self) -> HoleBelief:
        """The search's belief over where the end must go, from :meth:`hole_prior`."""
        centre, sigma, radius = self.hole_prior()
        return HoleBelief(
            (float(centre[0]), float(centre[1])), radius=radius, sigma=sigma, capture=self.capture()
        )

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
        self.observe("mouth", self.task.believed_bottom(obs)[:2], obs)
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
        if self.centring.centre is None:
            return None
        self.observe("centre", self.centring.centre, obs)
        return "centred"

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
        return "seated" if self.motion_over(obs) and self.task.seated_detected(obs) else None

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
