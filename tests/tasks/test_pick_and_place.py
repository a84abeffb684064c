"""Each phase of the pick-and-place task with synthetic observations (no physics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.jaw import load_default
from peg_ctrl.planners import MotionLimits, make_planner
from peg_ctrl.scene import SceneConfig
from peg_ctrl.state import ControlState, PegObservation
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.pick_and_place import (
    PHASES,
    PickAndPlaceTask,
    RandomizationConfig,
    SuccessConfig,
    TaskConfig,
)

SCENE = SceneConfig()
Q_HOME = np.array([1.0, 0.0, 0.0, 0.0])
Q_LYING = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])  # axis along world -Y
BLOCK_TOP = SCENE.assets.block_size[2]


def make_task(**task: object) -> PickAndPlaceTask:
    return PickAndPlaceTask(
        scene=SCENE,
        config=TaskConfig(**task),  # type: ignore[arg-type]
        success=SuccessConfig(consecutive_steps=3),
        randomization=RandomizationConfig(),
        planner=make_planner("ruckig"),
        limits=MotionLimits(),
        jaw=load_default(),
    )


def peg(p, quat=Q_LYING, *, speed: float = 0.0, force: float = 0.0) -> PegObservation:  # type: ignore[no-untyped-def]
    p = np.asarray(p, float)
    w, x, y, z = quat
    axis = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
    half = 0.5 * SCENE.assets.peg_length
    bottom = p - half * axis if axis[2] >= 0 else p + half * axis
    return PegObservation(p, np.asarray(quat, float), axis, bottom, speed, force)


def obs(t: float, p_gripper, peg_obs: PegObservation, *, jaw: float = 0.085, quat=Q_HOME) -> Observation:  # type: ignore[no-untyped-def]
    z = np.zeros(3)
    return Observation(
        t, ControlState(t, np.asarray(p_gripper, float), np.asarray(quat, float), z, z, jaw), peg_obs
    )


LYING = peg((-0.2, 0.0, SCENE.assets.peg_radius))


def started() -> PickAndPlaceTask:
    task = make_task()
    task.start(obs(0.0, (-0.2, 0.0, 0.2), LYING))
    return task


def run_to(task: PickAndPlaceTask, t: float, o: Observation) -> None:
    task.target(o._replace(t=t))


def test_phase_names_match_the_table() -> None:
    assert set(make_task().phase_table()) | {"done"} == set(PHASES)


def test_approach_waits_for_the_motion_and_the_xy_error() -> None:
    task = started()
    goal = task._goal.p_world
    task.target(obs(0.01, goal, LYING))
    assert task.phase == "approach"  # motion not over yet
    far = (goal[0] + 0.01, goal[1], goal[2])
    late = task.machine.motion.duration + 0.1  # type: ignore[union-attr]
    task.target(obs(late, far, LYING))
    assert task.phase == "approach"  # 10 mm off: not aligned
    task.target(obs(late, goal, LYING))
    assert task.phase == "descend"
    assert task.records[-2].outcome == "ok"


def test_approach_times_out_after_its_settling_allowance() -> None:
    task = started()
    far = (0.5, 0.5, 0.5)
    allowance = task.machine.motion.duration + task.cfg.positioning_time  # type: ignore[union-attr]
    task.target(obs(allowance, far, LYING))
    assert task.phase == "approach"
    task.target(obs(allowance + 0.01, far, LYING))
    assert task.phase == "descend" and task.records[-2].outcome == "timeout"


def test_descend_goes_to_the_grasp_height_above_the_peg() -> None:
    task = started()
    task.target(obs(5.0, (0.5, 0.5, 0.5), LYING))  # approach timed out
    assert task.phase == "descend"
    assert task._goal.p_world[2] == pytest.approx(LYING.p_world[2] + task.cfg.grasp_height)


def _at_grasp(task: PickAndPlaceTask) -> float:
    task.target(obs(5.0, (0.5, 0.5, 0.5), LYING))
    task.target(obs(10.0, (0.5, 0.5, 0.5), LYING))
    assert task.phase == "grasp"
    return 10.0 + task.machine.motion.duration + task.cfg.grasp_time  # type: ignore[union-attr]


def test_a_jaw_closed_on_nothing_is_a_lost_grasp() -> None:
    task = started()
    t = _at_grasp(task)
    with pytest.raises(EpisodeFailure) as info:
        task.target(obs(t + 0.01, (0.5, 0.5, 0.5), LYING, jaw=0.0))  # closed all the way
    assert info.value.reason == "grasp_lost"
    assert not task.grasped


def test_a_jaw_stopped_by_the_peg_is_a_grasp() -> None:
    task = started()
    t = _at_grasp(task)
    task.target(obs(t - 0.01, (0.5, 0.5, 0.5), LYING, jaw=0.0))
    assert task.phase == "grasp"  # the wait is not over
    task.target(obs(t + 0.01, (0.5, 0.5, 0.5), LYING, jaw=2 * SCENE.assets.peg_radius))
    assert task.phase == "lift" and task.grasped and not task.released


def test_rotate_turns_the_peg_upright_about_the_gripper_x_axis() -> None:
    task = make_task()
    o = obs(0.0, (-0.2, 0.0, 0.15), LYING)
    turn = task._turn(o)
    angle = 2 * math.atan2(turn[1], turn[0])
    assert turn[2] == turn[3] == 0.0
    assert angle == pytest.approx(math.pi / 2)  # the lying peg's axis is along -Y


def test_insert_stops_on_contact_force_or_depth() -> None:
    task = make_task(force_guarded_insert=True)
    upright = peg((0.2, 0.0, BLOCK_TOP + 0.05), Q_HOME)
    task.start(obs(0.0, (0.2, 0.0, 0.3), upright))
    late = task.machine.motion.duration  # type: ignore[union-attr]
    assert task._insert_stopped(obs(0.01, (0.2, 0, 0.2), upright._replace(force_block=4.0))) is None
    assert task._insert_stopped(obs(0.01, (0.2, 0, 0.2), upright._replace(force_block=6.0))) == "contact"
    assert task._insert_stopped(obs(late, (0.2, 0, 0.2), upright)) == "depth"


def test_settle_needs_the_peg_still_for_two_tenths_of_a_second() -> None:
    task = make_task()
    still = peg((0.2, 0.0, 0.04), Q_HOME, speed=0.001)
    task.start(obs(0.0, (0.2, 0.0, 0.2), still))
    task.machine._enter("settle", obs(1.0, (0.2, 0.0, 0.2), still))
    task.target(obs(1.0, (0.2, 0.0, 0.2), still))
    task.target(obs(1.19, (0.2, 0.0, 0.2), still))
    assert task.phase == "settle"
    task.target(obs(1.201, (0.2, 0.0, 0.2), still))
    assert task.phase == "done" and task.records[-1].outcome == "ok"


def test_success_needs_release_and_consecutive_seated_steps() -> None:
    task = started()
    seated = peg((0.2, 0.0, BLOCK_TOP - 0.05 + 0.5 * SCENE.assets.peg_length), Q_HOME)
    assert not task.evaluate(obs(1.0, (0.2, 0, 0.2), seated)).done  # not released yet
    task._let_go(obs(1.0, (0.2, 0, 0.2), seated))
    verdicts = [task.evaluate(obs(1.0 + 0.001 * k, (0.2, 0, 0.2), seated)) for k in range(3)]
    assert [v.done for v in verdicts] == [False, False, True]
    assert verdicts[-1].success and verdicts[-1].metrics.depth_m == pytest.approx(0.05)
    assert task.time_to_insert == pytest.approx(1.0)


@pytest.mark.parametrize(("quat", "reason"), [(Q_HOME, "timeout"), (Q_LYING, "excessive_tilt")])
def test_a_finished_machine_without_insertion_fails(quat, reason: str) -> None:  # type: ignore[no-untyped-def]
    task = started()
    task.machine.phase = "done"
    verdict = task.evaluate(obs(1.0, (0, 0, 0.2), peg((0.0, 0.0, 0.1), quat)))
    assert verdict.done and not verdict.success and verdict.reason == reason
