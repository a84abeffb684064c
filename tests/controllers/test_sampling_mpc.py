"""The sampling MPC: its configuration, the belief model it plans on, and its planning in free space."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.controllers.belief_model import HAND_JOINTS, BeliefModelSpec, build_belief_model
from peg_ctrl.controllers.sampling_mpc import (
    METHODS,
    SamplingMPCConfig,
    SamplingMPCController,
    _quat_to_turn,
    _turn_to_quat,
)
from peg_ctrl.errors import ConfigError
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.rotations import rotate

from ..conftest import HOME, target

TIP = (0.0, -0.07, -0.01)
Q_REF = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])  # the held grasp's turn
BELIEF = Belief(
    hole_xy=(0.2, 0.0),
    hole_sigma=0.0,
    face_z=0.05,
    hole_radius=0.01005,
    chamfer=0.001,
    block_size=(0.08, 0.08, 0.05),
    peg_radius=0.01,
    peg_length=0.1,
    tip_body=TIP,
    axis_body=tuple(rotate(np.array([Q_REF[0], -Q_REF[1], 0.0, 0.0]), np.array([0.0, 0.0, 1.0])).tolist()),  # type: ignore[arg-type]
)
SPEC = BeliefModelSpec(
    0.002, 0.6, (3000.0,) * 3 + (30.0,) * 3, (150.0,) * 3 + (3.0,) * 3, (10.0,) * 3 + (5.0,) * 3
)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        (
            {"method": "gradient"},
            "sampling_mpc.method: must be one of predictive_sampling, mppi, cem, got 'gradient'",
        ),
        ({"samples": 1}, "sampling_mpc.samples: must be an integer >= 2, got 1"),
        ({"replan_dt": 0.0015}, "sampling_mpc.replan_dt: must be a whole multiple of control_dt"),
        ({"elites": 20}, "sampling_mpc.elites: must be <= samples (12), got 20"),
        ({"horizon": 0.001}, "sampling_mpc.horizon: must cover at least 2 model steps"),
    ],
)
def test_bad_settings_are_named(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        SamplingMPCConfig(**fields)  # type: ignore[arg-type]


def test_turns_are_the_hinge_chain() -> None:
    turn = np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(_quat_to_turn(_turn_to_quat(turn)), turn, atol=1e-12)


def test_the_belief_model_puts_the_hand_at_the_believed_tip(model: mujoco.MjModel) -> None:
    m = build_belief_model(model, BELIEF, Q_REF, SPEC)
    d = mujoco.MjData(m)
    assert [m.joint(i).name for i in range(m.njnt)] == list(HAND_JOINTS)
    assert m.nu == 6 and m.nsensordata == 6 and m.opt.gravity.tolist() == [0.0, 0.0, 0.0]
    turn = np.array([0.01, -0.02, 0.3])
    d.qpos[:3] = [0.19, 0.01, 0.06]
    d.qpos[3:] = turn
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(d.xquat[m.body("hand").id], _turn_to_quat(turn), atol=1e-12)
    np.testing.assert_allclose(d.site_xpos[m.site("tip").id], [0.19, 0.01, 0.06], atol=1e-12)
    # The peg points up from the tip, as the belief holds it, turned with the hand.
    d.qpos[3:] = 0.0
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(d.xmat[m.body("peg").id].reshape(3, 3)[:, 2], [0.0, 0.0, 1.0], atol=1e-12)
    # The block stands with its hole where the task believes it, its top face at face_z.
    np.testing.assert_allclose(d.xpos[m.body("block").id], [0.2, 0.0, 0.025], atol=1e-12)


def test_the_belief_model_predicts_a_press_on_the_face(model: mujoco.MjModel) -> None:
    """The tip 5 mm beside the hole, its setpoint 1 mm into the face: the sensors report the
    inner loop's spring, kp times the depth, pushing the hand up."""
    m = build_belief_model(model, BELIEF, Q_REF, SPEC)
    d = mujoco.MjData(m)
    d.qpos[:3] = [0.2 - 0.025, 0.0, 0.05]
    d.ctrl[:3] = [0.2 - 0.025, 0.0, 0.049]
    for _ in range(500):
        mujoco.mj_step(m, d)
    contact_on_hand = -d.sensordata[:3]
    assert contact_on_hand[2] == pytest.approx(3000.0 * 0.001, rel=0.05)


@pytest.mark.parametrize("method", METHODS)
def test_every_method_holds_a_pose_in_free_space(method: str, model: mujoco.MjModel) -> None:
    """No belief (a tracking task states none): the model is the hand alone, and the plan holds
    the target; the planning time of every replan is kept."""
    config = SamplingMPCConfig(method=method, samples=6, replan_dt=0.02)
    controller = SamplingMPCController(model, config)
    tracker = Tracker(model, controller)
    goal = target(HOME + np.array([0.01, 0.0, -0.01]))
    tracker.hold(goal, 1.0)
    assert np.linalg.norm(tracker.state().p_world - goal.p_world) < 2e-3
    (timing,) = controller.timings()
    assert timing.name == "plan" and timing.period_s == 0.02
    assert len(timing.times_s) == pytest.approx(50, abs=2)


def test_a_turning_target_is_followed_without_lag(model: mujoco.MjModel) -> None:
    """A target turning at 1.5 rad/s about x (its angular velocity as feed-forward): the plan's
    reference turns ahead with it, so the hand stays within 20 mrad of it. A reference that held
    the turn over the horizon lagged by 0.3 rad (pick-and-place's rotate, then a peg released
    4 mm off the hole)."""
    controller = SamplingMPCController(model, SamplingMPCConfig(samples=6))
    tracker = Tracker(model, controller)
    rate, dt = 1.5, controller.config.control_dt
    worst = 0.0
    for k in range(int(0.4 / dt)):
        angle = rate * k * dt
        q = np.array([np.cos(angle / 2), np.sin(angle / 2), 0.0, 0.0])
        tracker.control_step(target(HOME, q, w=(rate, 0.0, 0.0)))
        err = np.zeros(3)
        mujoco.mju_subQuat(err, q, tracker.state().quat_world)
        worst = max(worst, float(np.linalg.norm(err))) if k * dt > 0.1 else worst
    assert worst < 0.02


def test_rollout_threads_change_the_speed_not_the_plan(model: mujoco.MjModel) -> None:
    """Rollouts on two threads (one MjData each) give the trajectory of one thread, to the bit."""
    finals = []
    for threads in (1, 2):
        controller = SamplingMPCController(model, SamplingMPCConfig(samples=6, threads=threads))
        tracker = Tracker(model, controller)
        tracker.hold(target(HOME + np.array([0.005, 0.0, -0.005])), 0.2)
        finals.append(tracker.state().p_world.copy())
    np.testing.assert_array_equal(finals[0], finals[1])


def test_a_reset_forgets_the_belief(model: mujoco.MjModel) -> None:
    """The task states its belief again after a reset; until then the plan turns about the
    configured centre, not the last episode's believed tip."""
    controller = SamplingMPCController(model, SamplingMPCConfig(compliance_center=(0.0, 0.0, 0.01)))
    controller.observe_belief(BELIEF)
    np.testing.assert_allclose(controller.tip_body, TIP)
    controller.reset(Tracker(model, controller).state())
    np.testing.assert_allclose(controller.tip_body, [0.0, 0.0, 0.01])
