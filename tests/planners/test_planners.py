"""Planners: boundary states, limits along the whole trajectory, synchronisation, rotation path."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.planners import (
    FixedSpeedPlanner,
    MotionLimits,
    RuckigPlanner,
    UnknownPlanner,
    Waypoint,
    make_planner,
)

LIMITS = MotionLimits()
CASES = {
    "translate": (
        Waypoint.of([0, 0, 0.2], [1, 0, 0, 0], 0.085),
        Waypoint.of([0.3, -0.1, 0.1], [1, 0, 0, 0], 0.085),
    ),
    "turn": (
        Waypoint.of([0, 0, 0.2], [1, 0, 0, 0], 0.0),
        Waypoint.of([0, 0, 0.2], euler_to_quat(1.6, 0, 0.2), 0.0),
    ),
    "all": (
        Waypoint.of([-0.2, 0.05, 0.15], euler_to_quat(0, 0, 0.3), 0.085),
        Waypoint.of([0.2, 0.0, 0.1], euler_to_quat(1.5, 0.1, -0.2), 0.0),
    ),
    "jaw only": (Waypoint.of([0, 0, 0.2], [1, 0, 0, 0], 0.085), Waypoint.of([0, 0, 0.2], [1, 0, 0, 0], 0.0)),
}


def _angle(qa: np.ndarray, qb: np.ndarray) -> float:
    err = np.zeros(3)
    mujoco.mju_subQuat(err, qa, qb)
    return float(np.linalg.norm(err))


# Planner classes, built in the test: an instance made at collection would live (with its
# Ruckig) until the interpreter exits, and nanobind reports it as a leak.
@pytest.mark.parametrize("make_planner", [RuckigPlanner, FixedSpeedPlanner], ids=["ruckig", "fixed_speed"])
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_boundary_states_are_exact(make_planner, case) -> None:
    start, goal = case
    traj = make_planner().plan(start, goal, LIMITS)
    s0, s1 = traj.sample(0.0), traj.sample(traj.duration)
    np.testing.assert_allclose(s0.p_world, start.p_world, atol=1e-12)
    np.testing.assert_allclose(s1.p_world, goal.p_world, atol=1e-12)
    assert _angle(s0.quat_world, np.asarray(start.quat_world)) < 1e-12
    assert _angle(s1.quat_world, np.asarray(goal.quat_world)) < 1e-12
    assert s0.jaw_sep_m == pytest.approx(start.jaw_sep_m, abs=1e-12)
    assert s1.jaw_sep_m == pytest.approx(goal.jaw_sep_m, abs=1e-12)
    np.testing.assert_array_equal(s1.v_world, 0.0)
    np.testing.assert_array_equal(s1.omega_body, 0.0)
    # Past the end it stays at the goal.
    np.testing.assert_allclose(traj.sample(traj.duration + 5.0).p_world, goal.p_world, atol=1e-12)


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_ruckig_limits_hold_along_the_whole_trajectory(case) -> None:
    start, goal = case
    traj = RuckigPlanner().plan(start, goal, LIMITS)
    t = np.linspace(0.0, traj.duration, 4001)
    pos, vel, acc = (np.array(x) for x in zip(*(traj.state_at(ti) for ti in t), strict=True))
    v_max = np.array([LIMITS.v_lin] * 3 + [LIMITS.v_rot, LIMITS.v_jaw])
    a_max = np.array([LIMITS.a_lin] * 3 + [LIMITS.a_rot, LIMITS.a_jaw])
    j_max = np.array([LIMITS.j_lin] * 3 + [LIMITS.j_rot, LIMITS.j_jaw])
    assert np.all(np.abs(vel) <= v_max * (1 + 1e-9) + 1e-12)
    assert np.all(np.abs(acc) <= a_max * (1 + 1e-9) + 1e-12)
    jerk = np.diff(acc, axis=0) / np.diff(t)[:, None]
    assert np.all(np.abs(jerk) <= j_max * (1 + 1e-6) + 1e-9)
    # Starts and ends at rest.
    np.testing.assert_allclose(vel[[0, -1]], 0.0, atol=1e-12)
    np.testing.assert_allclose(acc[[0, -1]], 0.0, atol=1e-9)


def test_ruckig_degrees_of_freedom_finish_together() -> None:
    start, goal = CASES["all"]
    traj = RuckigPlanner().plan(start, goal, LIMITS)
    _, vel, _ = traj.state_at(0.98 * traj.duration)
    moving = np.abs(
        np.array([*goal.p_world, 1.0, goal.jaw_sep_m]) - np.array([*start.p_world, 0.0, start.jaw_sep_m])
    )
    assert np.all(np.abs(np.array(vel))[moving > 1e-9] > 0), "a DoF finished early (not time-synchronised)"


# Planner classes, built in the test: an instance made at collection would live (with its
# Ruckig) until the interpreter exits, and nanobind reports it as a leak.
@pytest.mark.parametrize("make_planner", [RuckigPlanner, FixedSpeedPlanner], ids=["ruckig", "fixed_speed"])
def test_angular_velocity_matches_the_orientation_path(make_planner) -> None:
    """omega_body is the derivative of the sampled orientation (finite differences)."""
    start, goal = CASES["all"]
    traj = make_planner().plan(start, goal, LIMITS)
    dt = 1e-6
    for t in np.linspace(0.05, traj.duration - 0.05, 25):
        a, b = traj.sample(t), traj.sample(t + dt)
        fd = np.zeros(3)
        mujoco.mju_subQuat(fd, b.quat_world, a.quat_world)
        np.testing.assert_allclose(fd / dt, a.omega_body, atol=1e-4)
        np.testing.assert_allclose((b.p_world - a.p_world) / dt, a.v_world, atol=1e-4)


def test_rotation_takes_the_short_way() -> None:
    start = Waypoint.of([0, 0, 0.2], [1, 0, 0, 0], 0.0)
    goal = Waypoint.of([0, 0, 0.2], euler_to_quat(0, 0, math.radians(179)), 0.0)
    traj = RuckigPlanner().plan(start, goal, LIMITS)
    assert traj.rotation_angle == pytest.approx(math.radians(179))
    goal = Waypoint.of([0, 0, 0.2], euler_to_quat(0, 0, math.radians(181)), 0.0)
    assert RuckigPlanner().plan(start, goal, LIMITS).rotation_angle == pytest.approx(math.radians(179))


def test_fixed_speed_moves_at_the_set_speed() -> None:
    start, goal = CASES["translate"]
    traj = FixedSpeedPlanner().plan(start, goal, LIMITS)
    dist = np.linalg.norm(np.subtract(goal.p_world, start.p_world))
    assert traj.duration == pytest.approx(dist / LIMITS.v_lin)
    for t in (0.0, 0.3 * traj.duration, 0.9 * traj.duration):
        assert np.linalg.norm(traj.sample(t).v_world) == pytest.approx(LIMITS.v_lin)


def test_bad_limits_and_names() -> None:
    with pytest.raises(ValueError, match="v_lin"):
        MotionLimits(v_lin=0.0)
    with pytest.raises(ValueError, match="j_rot"):
        MotionLimits(j_rot=math.nan)
    with pytest.raises(UnknownPlanner, match="known: fixed_speed, ruckig"):
        make_planner("rrt")
