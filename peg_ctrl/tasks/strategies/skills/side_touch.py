"""The side touches: the peg's end pushed against the block's sides, straight and with the hand
turned, which place the end in the hand and the hole in the world (``locate``, docs/contact_real.md)."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.sim.rotations import quat_mul, rotate, yaw_quat
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, TrajectorySequence
from peg_ctrl.tasks.strategies.skills.centring import WallPush
from peg_ctrl.tasks.strategies.skills.rock import PAD_NORMAL

if TYPE_CHECKING:
    from peg_ctrl.tasks.strategies.locate import LocateStrategy

__all__ = ["SideTouches", "locate_across", "locate_end", "pair_offset", "turn"]

_Vec = np.ndarray
_AXES = (np.array([1.0, 0.0]), np.array([0.0, 1.0]))
_BLOCKED_AFTER = 0.1  # [s] an approach whose hand has not followed its command by then is blocked


def locate_end(touches: list[_Vec], yaw: float) -> _Vec:
    """The true end's horizontal offset from the believed one at yaw 0, world (x, y) [m], from
    four touches: the believed end's (x, y) at the -x side (yaw 0, then ``yaw``), at the -y
    side (yaw 0, then ``yaw``). A turn by ``yaw`` about the believed end swings the true one
    from ``d`` to ``R(yaw) d``; each side's two touches meet it at the same coordinate."""
    c, s = math.cos(yaw), math.sin(yaw)
    a = np.array([[1.0 - c, s], [-s, 1.0 - c]])
    b = np.array([touches[1][0] - touches[0][0], touches[3][1] - touches[2][1]])
    return np.linalg.solve(a, b)


def turn(v: _Vec, angle: float) -> _Vec:
    """The horizontal vector ``v`` (x, y) turned by ``angle`` [rad] about the vertical."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def pair_offset(touches: list[_Vec], legs: list[tuple[int, bool]], across: _Vec, yaw: float) -> float:
    """The true end's offset from the believed one along ``across`` [m] (the unit direction
    across the pads at yaw 0, world x, y), from the two touches of the side that ``legs[1]``
    touches: ``legs`` gives each touch's (side, turned by ``yaw``), ``touches`` the believed
    end's (x, y) at each. Both meet the same wall: ``believed + s * across`` along that axis."""
    side = legs[1][0]  # the pair is the first two legs or the last two
    a, b = (k for k, (leg_side, _) in enumerate(legs) if leg_side == side)
    u_a, u_b = (turn(across, yaw if legs[k][1] else 0.0)[side] for k in (a, b))
    return float((touches[a][side] - touches[b][side]) / (u_b - u_a))


def locate_across(
    touches: list[_Vec], legs: list[tuple[int, bool]], across: _Vec, yaw: float
) -> tuple[float, _Vec]:
    """Three touches (:func:`pair_offset`'s): the end's offset along ``across`` [m], and where
    the true end met each side, (x at the -x side, y at the -y side) [m], from that side's first
    touch."""
    s = pair_offset(touches, legs, across, yaw)
    met = np.zeros(2)
    for side in (0, 1):
        k = next(k for k, (leg_side, _) in enumerate(legs) if leg_side == side)
        met[side] = touches[k][side] + s * turn(across, yaw if legs[k][1] else 0.0)[side]
    return s, met


class SideTouches:
    """The ``sides`` phase, as a motion the strategy plays and steps (module docstring).

    Four legs: (-x side, yaw 0), (-x, ``yaw``), (-y, yaw 0), (-y, ``yaw``); three (``side_touches:
    3``, :meth:`_plan_legs`): one side twice, the other once, turned. Per leg: ``move`` (a planned
    path to the approach's start), ``approach`` (guarded, pose-tracked), ``press`` (the lateral
    push until the hand is still); then ``leave`` (back off, turn back, up clear of the face;
    with ``quick_datum`` the move to the datum turns back).

    Attributes:
        touched: the believed lower end's (x, y) [m] at each touch; ``delta``: the true end's
            offset from the believed one at yaw 0 (world x, y) [m]; ``hole``: the hole's axis
            (x, y) [m], as the revised belief sees it (both None unless every side was found);
            ``done``: the end is back above the face; ``quat``: the hand's orientation at yaw 0.
    """

    duration = 0.0

    def __init__(
        self, strategy: LocateStrategy, obs: Observation, gaps: tuple[float, float] | None = None
    ) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        t, c = self.task, self.cfg
        # How far beyond the side the first approach starts, and the second side's beyond where
        # the end will meet it (by default the config's side_gap and camera_gap; a belief of
        # where the sides are can tell less).
        self._gaps = gaps if gaps is not None else (c.side_gap, c.camera_gap)
        self.quat = np.asarray(t.goal.quat_world, dtype=float)
        self._turned = quat_mul(yaw_quat(c.yaw), self.quat)
        # Horizontal in the pads' plane, square to their closing direction, at yaw 0 (world x, y):
        # the only direction in which the end can sit off the believed one ("across" the jaw).
        closing = rotate(self.quat, PAD_NORMAL)
        across = np.array([-closing[1], closing[0]])
        self._across = across / np.linalg.norm(across)
        self._legs = self._plan_legs()
        self.touched: list[_Vec] = []
        self.delta: _Vec | None = None
        self.hole: _Vec | None = None
        self.done = False
        # The datum's corner of the face, seen from the camera's hole: the touches' other
        # coordinate (clear of the block's corners).
        off = c.datum_offset / math.sqrt(2.0)
        self._along = np.asarray(t.observed_hole, dtype=float) - off
        self._z_low = t.z_face - c.side_depth
        self._z_high = t.z_face + c.side_lift
        sides = np.asarray(t.drawing_sides, dtype=float)
        self._side_at = (t.observed_hole[0] - sides[1], t.observed_hole[1] - sides[3])
        self._distance = (float(sides[1]), float(sides[3]))
        self._state = "move"
        self._t0 = obs.t
        self._wall: WallPush | None = None
        self._at_speed = False
        self._moving_since: float | None = None  # when the approach's command got going
        self._trajectory: Motion | None = None
        self._target = GripperTarget.trusted(obs.gripper.p_world, self.quat, np.zeros(3), np.zeros(3), 0.0)

    def sample(self, t: float) -> GripperTarget:
        return self._target  # set by step(), which keeps the episode's clock

    # -- legs ----------------------------------------------------------------------------------------
    def _plan_legs(self) -> list[tuple[int, bool]]:
        """(side, turned) per touch. Four: each side at yaw 0, then turned. Three: the end's
        offset lies across the pads (``_across``), so one scalar: the side on which a turn moves
        the end most along the approach is touched twice, the other once, one turn in all."""
        if self.cfg.side_touches == 4:
            return [(0, False), (0, True), (1, False), (1, True)]
        swing = np.abs(self._across - self._across_at(True))
        return (
            [(0, False), (0, True), (1, True)]
            if swing[0] >= swing[1]
            else [(0, False), (1, False), (1, True)]
        )

    def _across_at(self, turned: bool) -> _Vec:
        """The across-the-pads direction with the hand at yaw 0 or turned (world x, y)."""
        return turn(self._across, self.cfg.yaw if turned else 0.0)

    def _leg(self, n: int | None = None) -> tuple[int, _Vec]:
        """Leg ``n``'s (by default the present one's) side (0: -x, 1: -y) and the hand's orientation."""
        side, turned = self._legs[len(self.touched) if n is None else n]
        return side, (self._turned if turned else self.quat)

    def _offset_along(self, n: int) -> float:
        """The true end's offset from the believed one along leg ``n``'s side's axis, with the
        hand as in leg ``n``, from the touches so far (three-touch mode; the -x side's first
        touch and the camera's side if its pair is not yet touched)."""
        side, turned = self._legs[n]
        if len(self.touched) >= 2 and self._legs[1][0] == 0:
            s = pair_offset(self.touched, self._legs, self._across, self.cfg.yaw)
        else:  # one touch of the -x side: its wall where the camera and the drawing put it
            s = (self._side_at[0] - self.task.radius - self.touched[0][0]) / self._across[0]
        return float(s * self._across_at(turned)[side])

    # -- paths ---------------------------------------------------------------------------------------

    def _start_of(self, side: int) -> _Vec:
        """Where the approach to ``side`` starts: ``side_gap`` beyond the side the drawing gives,
        one radius out, at the datum corner's other coordinate, below the face. The -y side's,
        once the -x side's two touches have told the end's offset along y (a turn about z moves
        the end across the approach mostly): ``camera_gap`` beyond where the end will meet it.
        With three touches, the end's offset in the pads' plane from the -x side's pair, or, if
        the -y side takes the pair, from its one touch against the side the camera and the
        drawing put there (:meth:`_offset_along`)."""
        c = self.cfg
        side_gap, camera_gap = self._gaps
        start = np.array([*self._along, self._z_low])
        start[side] = self._side_at[side] - self.task.radius - side_gap
        if side == 1 and c.side_touches == 3:
            d_y = self._offset_along(len(self.touched))
            start[1] = self._side_at[1] - d_y - self.task.radius - camera_gap
        elif side == 1 and len(self.touched) >= 2:
            # (1 - cos yaw) d_x + sin(yaw) d_y: d_x's share is within a millimetre of d_y
            d_y = (self.touched[1][0] - self.touched[0][0]) / math.sin(c.yaw)
            start[1] = self._side_at[1] - d_y - self.task.radius - camera_gap
        return start

    def _plan(self, tips: list[_Vec], quats: list[_Vec]) -> Motion:
        st, c = self.strategy, self.cfg
        pairs = [
            (tip, q)
            for k, (tip, q) in enumerate(zip(tips, quats, strict=True))
            if k == 0 or not (np.array_equal(tip, tips[k - 1]) and np.array_equal(q, quats[k - 1]))
        ]
        w = [st.tip_waypoint(tip, q) for tip, q in pairs]
        limits = st.quick() if not c.turn_speed else dataclasses.replace(st.quick(), v_rot=c.turn_speed)
        parts = [self.task.planner.plan(a, b, limits) for a, b in zip(w, w[1:], strict=False)]
        self.task.goal = w[-1]
        return TrajectorySequence(parts)

    def path_to_first(self, obs: Observation) -> Motion:
        tip = self.task.believed_bottom(obs)
        start = self._start_of(0)
        up = np.array([*tip[:2], max(tip[2], self._z_high)])
        tips = [tip, up, np.array([*start[:2], up[2]]), start]
        return self._plan(tips, [self.quat] * 4)

    def begin(self, obs: Observation) -> None:
        self._approach(obs)

    # -- the states ------------------------------------------------------------------------------------
    def step(self, obs: Observation) -> None:
        if self.done:
            return
        if self._state == "press":
            self._read(obs)
            return
        assert self._trajectory is not None
        self._target = self._trajectory.sample(obs.t - self._t0)
        over = obs.t - self._t0 >= self._trajectory.duration
        if self._state == "approach" and self._stalled(obs):
            self._press(obs)
        elif over and self._state == "move":
            self._approach(obs)
        elif over and self._state == "approach":  # no side where it should be: give up locating
            self._leave(obs)
        elif over:
            self.done = True

    def _approach(self, obs: Observation) -> None:
        c, st = self.cfg, self.strategy
        side, q = self._leg()
        tip = self.task.believed_bottom(obs)
        goal = tip.copy()
        goal[side] += 2.0 * (self._gaps[1] if side == 1 else self._gaps[0])
        limits = dataclasses.replace(self.task.limits, v_lin=c.touch_speed, a_lin=c.move_accel)
        self._trajectory = self.task.planner.plan(st.tip_waypoint(tip, q), st.tip_waypoint(goal, q), limits)
        self._state, self._t0, self._at_speed, self._moving_since = "approach", obs.t, False, None

    def _stalled(self, obs: Observation) -> bool:
        """The hand's filtered speed along the approach below ``stall_fraction`` of the
        command's, while the command still moves at half its speed or more, once the hand has
        followed it (a deceleration at the end is no stall), or if it never follows it: still
        that slow ``_BLOCKED_AFTER`` after the command got going (the end met the side as the
        approach began: a turn can swing it there). Whether the hand follows is judged only
        once the command moves: before, the hand's sway after the move that brought it here
        can pass for speed (and a dip of it then for a stall)."""
        c = self.cfg
        axis = _AXES[self._leg()[0]]
        v = float(np.dot(self.task.hand_velocity[:2], axis))
        v_cmd = float(np.dot(self._target.v_world[:2], axis))
        moving = v_cmd > 0.5 * c.touch_speed
        if not self._at_speed:
            self._at_speed = moving and v > 2.0 * c.stall_fraction * c.touch_speed
            if moving and self._moving_since is None:
                self._moving_since = obs.t
            blocked = self._moving_since is not None and obs.t - self._moving_since > _BLOCKED_AFTER
            return not self._at_speed and blocked and moving and v < c.stall_fraction * v_cmd
        return moving and v < c.stall_fraction * v_cmd

    def _press(self, obs: Observation) -> None:
        """Hold here, pushing on into the side at the wall force (that lateral axis free)."""
        side, q = self._leg()
        self._wall = WallPush(self.strategy, obs, obs.gripper.p_world, q, _AXES[side])
        self._target = self._wall.target
        self._state = "press"  # the push keeps its own clock

    def _read(self, obs: Observation) -> None:
        """Once the hand is still: where the believed end is; on to the next leg."""
        c, task = self.cfg, self.task
        assert self._wall is not None
        wall = self._wall.update(obs)
        if wall is None:
            return
        side, q = self._leg()
        self.touched.append(wall)
        if len(self.touched) == len(self._legs):
            self._locate()
            self._leave(obs)
            return
        tip = task.believed_bottom(obs)
        back = tip.copy()
        back[side] -= c.side_backoff
        next_side, next_q = self._leg()
        if next_side == side:  # turn about the believed end, then approach again
            self._trajectory = self._plan([tip, back, back], [q, q, next_q])
        else:  # turn back, round the corner (below the face, outside the block)
            start = self._start_of(next_side)
            corner = back.copy()
            corner[next_side] = start[next_side]
            self._trajectory = self._plan([tip, back, back, corner, start], [q, q, next_q, next_q, next_q])
        self._state, self._t0 = "move", obs.t

    def _locate(self) -> None:
        """The end against the hand, then the hole against the end (yaw 0)."""
        r = self.task.radius
        if self.cfg.side_touches == 4:
            delta = locate_end(self.touched, self.cfg.yaw)
            self.delta = delta
            x = self.touched[0][0] + delta[0] + r + self._distance[0]
            y = self.touched[2][1] + delta[1] + r + self._distance[1]
            self.hole = np.array([x, y])
            return
        s, met = locate_across(self.touched, self._legs, self._across, self.cfg.yaw)
        self.delta = s * self._across
        self.hole = met + r + np.asarray(self._distance)

    def _leave(self, obs: Observation) -> None:
        """Back off the side, turn back, up clear of the face."""
        n = min(len(self.touched), len(self._legs) - 1)  # the leg met, or the one given up
        side, q = self._leg(n)
        tip = self.task.believed_bottom(obs)
        back = tip.copy()
        back[side] -= self.cfg.side_backoff
        up = np.array([*back[:2], self._z_high])
        if self.cfg.quick_datum:  # the move to the datum turns back, clear of the face
            self._trajectory = self._plan([tip, back, up], [q, q, q])
        else:
            self._trajectory = self._plan([tip, back, back, up], [q, q, self.quat, self.quat])
        self._state, self._t0 = "leave", obs.t
