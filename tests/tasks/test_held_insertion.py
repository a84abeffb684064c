"""The held-insertion task: its config, its start state, and its strategies run in the physics."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from peg_ctrl.config import ConfigError, apply_overrides
from peg_ctrl.errors import UnknownComponent
from peg_ctrl.run.episode import EpisodeResult, build_loop, episode_config_from_mapping, run_episode
from peg_ctrl.sim.rotations import rotate_inv
from peg_ctrl.tasks import TASKS, HeldInsertionConfig
from peg_ctrl.tasks.monitors import InsertionMeasure, classify_end_state
from peg_ctrl.tasks.pick_and_place import TaskConfig

#: The peg's lower end in the gripper frame for the held grasp: a remote centre of compliance.
TIP = [0.0, -0.07, -0.01]
RCC = {"name": "impedance", "compliance_center": TIP, "k_pos": [1000, 1000, 1500], "k_rot": [2, 2, 2]}
BASE: dict[str, Any] = {
    "task": {"name": "held_insertion"},
    "physics": {"profile": "precision"},
    "scene": {
        "assets": {"clearance": 0.0001, "chamfer": 0.001},
        "peg_friction": [0.3, 0.1, 1e-4],
        "block_friction": [0.3, 0.1, 1e-4],
    },
}


def config(*sets: str, **extra: Any) -> Any:
    data = apply_overrides({**BASE, **extra}, list(sets))
    return episode_config_from_mapping(data)


def run(tmp_path: Path, *sets: str, **extra: Any) -> EpisodeResult:
    return run_episode(config(*sets, **extra), tmp_path / "ep", plot=False)


# -- config ------------------------------------------------------------------------------------
def test_the_task_family_is_chosen_by_name() -> None:
    assert set(TASKS) == {"pick_and_place", "held_insertion"}
    assert isinstance(config().task, HeldInsertionConfig)
    default = episode_config_from_mapping({"task": {"force_guarded_insert": True}})
    assert isinstance(default.task, TaskConfig) and default.task.force_guarded_insert


@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (
            ["task.strategy=wiggle"],
            "task.strategy: unknown strategy 'wiggle'; known: align, force, handover, locate, plan, probe, "
            "spiral, straight, tilt",
        ),
        (["task.lateral_error=-0.001"], "task.lateral_error must be >= 0, got -0.001"),
        (["task.tilt_error=0.3"], "task.tilt_error must be below 0.2 rad, got 0.3"),
        (
            ["task.strategy=spiral", "task.strategy.spiral_pitch=0"],
            "task.strategy.spiral_pitch must be > 0, got 0",
        ),
        (
            ["task.strategy=spiral", "task.strategy.search_force=oops"],
            "task.strategy.search_force: expected a number, got 'oops'",
        ),
        (["task.strategy.spiral_pitch=0.001"], "task.strategy.spiral_pitch: unknown field; known:"),
    ],
)
def test_bad_task_values_are_named(sets: list[str], message: str) -> None:
    with pytest.raises(ConfigError) as err:
        config(*sets)
    assert message in str(err.value)


def test_an_unknown_task_lists_the_known_ones() -> None:
    with pytest.raises(
        UnknownComponent, match="task.name: unknown task 'peel'; known: held_insertion, pick_and_place"
    ):
        episode_config_from_mapping({"task": {"name": "peel"}})


# -- the start state ---------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_start_has_the_configured_lateral_error_and_tilt(seed: int) -> None:
    cfg = config(f"seed={seed}", "task.lateral_error=0.002", "task.tilt_error=0.02618")
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(seed))
    m = loop.task.insertion.measure(loop.peg)  # type: ignore[attr-defined]
    assert loop.data.time == 0.0
    assert m.lateral_error_m == pytest.approx(0.002, abs=2e-5)  # the jaw closing moves it by microns
    assert m.tilt_rad == pytest.approx(0.02618, abs=2e-3)
    assert -m.depth_m == pytest.approx(0.003, abs=1e-4)  # start_height above the mouth
    jaw = loop.state().jaw_sep_m
    assert jaw == pytest.approx(2 * cfg.scene.assets.peg_radius, abs=2e-3)  # closed on the peg


def test_directions_are_drawn_per_seed_and_repeat_with_it() -> None:
    def draw(seed: int) -> tuple[float, float, float]:
        loop = build_loop(config(f"seed={seed}"))
        loop.reset(np.random.default_rng(seed))
        d = loop.task.disturbance  # type: ignore[attr-defined]
        return d.lateral_direction, d.yaw, d.tilt_sign

    assert draw(3) == draw(3)
    assert len({draw(s)[0] for s in range(4)}) == 4


def test_position_noise_moves_the_observed_hole() -> None:
    loops = []
    for noise in (0.0, 0.001):
        loop = build_loop(config("seed=5", f"task.position_noise={noise}"))
        loop.reset(np.random.default_rng(5))
        loops.append(loop.task)
    d = loops[1].disturbance  # type: ignore[attr-defined]
    shift = loops[1].observed_hole - loops[0].observed_hole  # type: ignore[attr-defined]
    np.testing.assert_allclose(shift, d.noise, atol=1e-12)
    assert 0.0 < float(np.hypot(*shift)) < 0.005


@pytest.mark.parametrize("seed", [0, 1])
def test_a_start_over_the_observed_hole_tells_nothing_of_the_true_one(seed: int) -> None:
    """With ``start_over_observed`` the believed lower end starts over the camera's hole, and the
    true end is the grasp's offset off that, not off the true hole; the task's belief starts
    there, with the cell's spreads."""
    sets = [
        f"seed={seed}",
        "task.lateral_error=0.002",
        "task.position_noise=0.001",
        "task.start_over_observed=true",
    ]
    loop = build_loop(config(*sets))
    loop.reset(np.random.default_rng(seed))
    task: Any = loop.task
    from peg_ctrl.tasks.base import Observation

    task.start(Observation(0.0, loop.state(), loop.peg))
    believed = task.believed_bottom(Observation(0.0, loop.state(), loop.peg))
    np.testing.assert_allclose(believed[:2], task.observed_hole, atol=1e-4)  # the jaw moves it by microns
    true_end = loop.peg.bottom_world[:2]
    assert float(np.hypot(*(true_end - task.observed_hole))) == pytest.approx(0.002, abs=5e-5)
    d = task.disturbance
    assert float(np.hypot(*d.noise)) > 1e-4  # the camera is off, so the two starts differ
    b = task.knowledge
    np.testing.assert_allclose([b.value("hole_x"), b.value("hole_y")], task.observed_hole)
    assert b.sigma("hole_x") == pytest.approx(0.001) and b.sigma("face_z") == pytest.approx(1e-6)
    with pytest.raises(ConfigError, match="task.start_over_observed: expected true or false, got 1"):
        config("task.start_over_observed=1")


@pytest.mark.parametrize("seed", [0, 4])
def test_the_hole_is_observed_in_the_world_and_the_offset_is_in_the_hand(seed: int) -> None:
    """The observed hole is the true hole plus the camera's noise; the lateral error is the
    grasp's (the believed lower end is it off the true one); recalibrating the axis in the
    hand moves neither the observed hole nor that offset."""
    cfg = config(
        f"seed={seed}", "task.lateral_error=0.003", "task.tilt_error=0.0349", "task.position_noise=0.001"
    )
    loop = build_loop(cfg)
    obs = loop.reset(np.random.default_rng(seed))
    task: Any = loop.task
    hole = np.asarray(cfg.scene.hole_xy)
    np.testing.assert_allclose(task.observed_hole, hole + np.asarray(task.disturbance.noise), atol=1e-12)
    true_tip = obs.peg.bottom_world
    # Before calibration: the offset in the hand plus the tilt's shift of the lower end.
    tilt_shift = task.grip_length * math.sin(0.0349)
    shift = float(np.hypot(*(task.believed_bottom(obs) - true_tip)[:2]))
    assert 0.003 - tilt_shift - 1e-4 < shift < 0.003 + tilt_shift + 1e-4
    before = task.observed_hole.copy()
    axis = obs.peg.axis_world if obs.peg.axis_world[2] > 0 else -obs.peg.axis_world
    task.revise_axis(rotate_inv(obs.gripper.quat_world, axis), obs.gripper)  # the true axis
    np.testing.assert_array_equal(task.observed_hole, before)
    offset = (task.believed_bottom(obs) - true_tip)[:2]
    assert float(np.hypot(*offset)) == pytest.approx(0.003, abs=1e-4)  # the grasp's offset alone


def test_the_block_sits_off_its_drawing_within_the_tolerance() -> None:
    tops = []
    for seed in range(6):
        loop = build_loop(config(f"seed={seed}", "task.drawing_tolerance=0.0001", "task.lateral_error=0.0"))
        loop.reset(np.random.default_rng(seed))
        task: Any = loop.task
        monitor = task.insertion
        true = np.array([monitor.hole_x, monitor.hole_y, monitor.block_top])
        nominal = np.array([*loop.task.scene.hole_xy, task.block_top])  # the drawing
        assert np.all(np.abs(true - nominal) <= 0.0001) and np.any(true != nominal)
        np.testing.assert_allclose(loop.data.body("block").xpos[:2], true[:2], atol=1e-12)
        # The peg starts start_height above the true mouth, on the true hole's axis.
        assert -monitor.measure(loop.peg).depth_m == pytest.approx(0.003, abs=1e-4)
        assert monitor.measure(loop.peg).lateral_error_m < 5e-5
        # The drawing's distances to the sides: the true 40 mm, each off within the tolerance.
        assert np.all(np.abs(task.drawing_sides - 0.04) <= 0.0001) and len(set(task.drawing_sides)) == 4
        tops.append(true[2])
    assert len(set(tops)) == 6
    # No tolerance, nothing drawn: the block on its drawing.
    loop = build_loop(config("seed=0"))
    loop.reset(np.random.default_rng(0))
    np.testing.assert_array_equal(loop.data.body("block").xpos, loop.task.scene.block_pos)  # type: ignore[attr-defined]
    np.testing.assert_array_equal(loop.task.drawing_sides, [0.04] * 4)  # type: ignore[attr-defined]


# -- end states --------------------------------------------------------------------------------
def _measure(depth: float, tilt: float) -> InsertionMeasure:
    return InsertionMeasure(depth, 0.0, 0.0, 0.0, tilt, 0.0)


def test_end_states_follow_the_bore_geometry() -> None:
    geometry = {"clearance": 1e-4, "chamfer": 1e-3, "radius": 0.01}
    assert classify_end_state(_measure(0.0012, 0.0), **geometry) == "missed"  # on the chamfer
    # 10 mm into the bore a 0.1 mm clearance allows 1.15 deg of tilt.
    assert classify_end_state(_measure(0.011, math.radians(1.1)), **geometry) == "wedged"
    assert classify_end_state(_measure(0.011, math.radians(0.5)), **geometry) == "jammed"


# -- strategies in the physics -----------------------------------------------------------------
def test_straight_push_with_a_stiff_hand_fails_beyond_the_chamfer(tmp_path: Path) -> None:
    # The first 4 s (of 9, until the grasp gives): the push has passed 30 N by then.
    sets = ["task.strategy=straight", "task.lateral_error=0.0015", "controller=pd", "max_steps=8000"]
    r = run(tmp_path, *sets)
    assert r.status == "failure"
    assert r.end_state == "missed"
    assert r.insertion_depth_m < 0.001
    assert r.peak_contact_force_n > 30.0  # the position push drives into the top face


def test_spiral_search_finds_the_hole_beyond_the_chamfer(tmp_path: Path) -> None:
    r = run(tmp_path, "task.strategy=spiral", "task.lateral_error=0.0015", controller=RCC)
    assert r.status == "success", r.detail
    assert r.end_state == "seated"
    assert r.insertion_depth_m >= 0.04
    assert r.search_distance_m > 0.001  # it travelled to find the hole
    assert r.first_contact_s is not None and r.contact_to_seat_s is not None
    assert r.contact_to_seat_s == pytest.approx(r.time_to_insert_s - r.first_contact_s)
    assert r.contact_impulse_ns > 0.0
    phases = [p["phase"] for p in r.phases]
    assert phases[:5] == ["start", "settle", "approach", "descend", "search"]
    assert "insert" in phases


def test_force_strategy_regulates_the_push_with_the_admittance(tmp_path: Path) -> None:
    """On the flat top (1.5 mm off, beyond the chamfer), closed-loop force regulation settles
    at the commanded 3 N."""
    r = run(
        tmp_path,
        "task.strategy=force",
        "task.lateral_error=0.0015",
        "task.strategy.insert_time=1.5",
        controller={"name": "admittance"},
    )
    assert r.status == "failure" and r.reason == "missed"
    with np.load(r.trace_path) as npz:
        columns = [str(c) for c in npz["columns"]]
        data = npz["data"]
    t = data[:, columns.index("t")]
    force = data[:, columns.index("block-peg")]
    late = force[t > t[-1] - 0.5]
    assert float(np.median(late)) == pytest.approx(3.0, abs=0.3)


def test_the_mpc_force_limit_bounds_a_position_push(tmp_path: Path) -> None:
    """A stiff position push onto the top face: the MPC's effort bound holds the quasi-static
    contact force at its limit; without it the push is far harder. The first 3 s (the push
    begins at 1 s and the bounded force is steady from 1.5 s)."""
    medians = []
    for limit in (8.0, 1000.0):
        r = run(
            tmp_path / str(limit),
            "task.strategy=straight",
            "task.lateral_error=0.0015",
            "max_steps=6000",  # 3 s of 0.5 ms steps
            controller={"name": "mpc", "force_limit": limit},
        )
        with np.load(r.trace_path) as npz:
            columns = [str(c) for c in npz["columns"]]
            data = npz["data"]
        t = data[:, columns.index("t")]
        force = data[:, columns.index("block-peg")]
        medians.append(float(np.median(force[t > t[-1] - 0.5])))
    assert medians[0] == pytest.approx(8.0, abs=1.0)
    assert medians[1] > 3 * medians[0]


# -- the align strategy ----------------------------------------------------------------------------
HARD = {"scene.friction=0.9", "scene.assets.clearance=0.00005"}
CONTACT_MPC = {
    "name": "mpc",
    "formulation": "contact",
    "compliance_center": TIP,
    "force_limit": 10.0,
    "tare_time": 0.25,
    "control_dt": 0.001,
}


@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (
            ["task.strategy.datum_offset=0.05"],
            "task.strategy.datum_offset: the datum touch reaches 45.4 mm from the hole",
        ),
        (["task.strategy.datum_offset=0.02", "task.lateral_error=0.003"], "within 1 mm of the hole's mouth"),
        (
            ["task.strategy.search_pitch=0.002"],
            "task.strategy.search_pitch: 0.002 m leaves gaps in the chamfer's capture range",
        ),
    ],
)
def test_align_settings_are_checked_against_the_scene(sets: list[str], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        config("task.strategy=align", *sets)


def _align_tilted(*, until_phase: str | None) -> tuple[Any, Any, float, Any]:
    """mu = 0.9, 0.05 mm clearance, 3 mm off and 2 deg tilted in the hand, unknown to the task,
    with the contact-aware MPC: (the loop, its initial belief, the peak peg-block force, the
    outcome), run to the end or until the task enters ``until_phase``."""
    cfg = config(
        "task.strategy=align",
        "task.lateral_error=0.003",
        "task.tilt_error=0.0349066",
        *HARD,
        controller=CONTACT_MPC,
    )
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    belief = loop.task.belief
    peak, outcome = 0.0, None
    while loop.steps < 40000 and loop.task.phase != until_phase:
        evaluation = loop.step()
        peak = max(peak, loop.peg.force_block)
        if evaluation.done:
            outcome = evaluation
            break
    return loop, belief, peak, outcome


def test_align_finds_the_hidden_tilt_and_the_hole_within_the_budget() -> None:
    """The align strategy up to its final descent (8 s of 13): the contact-aware MPC flattens
    the peg on the datum (finding the hidden tilt) and finds the hole by hops, the peg-block force
    never above its 10 N budget."""
    loop, belief, peak, outcome = _align_tilted(until_phase="insert")
    assert outcome is None and loop.task.phase == "insert"
    assert loop.task.aligned_tilt == pytest.approx(0.0349066, abs=math.radians(0.1))
    assert loop.task.belief is not belief  # the calibration revised the belief
    assert peak <= 10.0
    phases = [r.phase for r in loop.task.records]
    assert phases == ["start", "settle", "approach", "touch", "align", "transfer", "search", "insert"]


@pytest.mark.slow  # ~15 s; the test above stops at the final descent, in 9 s
def test_align_seats_a_tilted_peg_at_high_friction_within_the_budget() -> None:
    """The same, to the end: it also seats the peg."""
    loop, belief, peak, outcome = _align_tilted(until_phase=None)
    assert outcome is not None and outcome.success, outcome
    assert loop.task.aligned_tilt == pytest.approx(0.0349066, abs=math.radians(0.1))
    assert loop.task.belief is not belief  # the calibration revised the belief
    assert peak <= 10.0
    phases = [r.phase for r in loop.task.records]
    assert phases[:8] == ["start", "settle", "approach", "touch", "align", "transfer", "search", "insert"]


def test_the_speed_sensing_noise_is_measured_through_the_velocity_filter() -> None:
    """1 mm/s of white noise on the sensed velocity, read at 1 kHz: the task's stop and seated
    detections see it through a 5 Hz low-pass, which passes sqrt(alpha / (2 - alpha)) of it."""
    cfg = config("seed=3", "domain.velocity_noise=0.001", "task.lateral_error=0.0", "controller.name=pd")
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(3))
    task: Any = loop.task
    while task.phase == "settle":
        loop.step()
    alpha = 1.0 - math.exp(-2.0 * math.pi * 5.0 * task.control_dt)
    assert task.speed_noise == pytest.approx(0.001 * math.sqrt(alpha / (2.0 - alpha)), rel=0.5)
    assert task.speed_noise < 0.25 * 0.001
