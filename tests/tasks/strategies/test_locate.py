"""The locate strategy: the end's offset from two touches per side with the hand turned (or
three touches, the offset across the pads), its settings checked, and a held insertion at
FORGE's difficulty run in the physics."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from peg_ctrl.config import apply_overrides
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.run.episode import EpisodeConfig, build_loop, episode_config_from_mapping
from peg_ctrl.run.loop import StepInfo
from peg_ctrl.tasks.strategies.locate import LocateConfig
from peg_ctrl.tasks.strategies.skills.side_touch import locate_across, locate_end, pair_offset, turn


@pytest.mark.parametrize("delta", [(0.003, -0.002), (-0.0054, 0.0), (0.0, 0.0)])
@pytest.mark.parametrize("yaw", [0.25, 0.6])
def test_four_touches_give_the_end_against_the_believed_one(delta: tuple[float, float], yaw: float) -> None:
    """The true end is ``delta`` from the believed one; a turn by ``yaw`` about the believed end
    swings it to R(yaw) delta. A side is met where the true end reaches it, so the believed end
    stops short of the side by the true end's offset along the approach."""
    d = np.array(delta)
    c, s = math.cos(yaw), math.sin(yaw)
    turned = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])
    side_x, side_y = 0.15, -0.05  # where the true end meets the -x and the -y side [m]
    touches = [
        np.array([side_x - d[0], -0.02]),
        np.array([side_x - turned[0], -0.021]),
        np.array([0.17, side_y - d[1]]),
        np.array([0.171, side_y - turned[1]]),
    ]
    np.testing.assert_allclose(locate_end(touches, yaw), d, atol=1e-12)


@pytest.mark.parametrize("legs", [[(0, False), (0, True), (1, True)], [(0, False), (1, False), (1, True)]])
@pytest.mark.parametrize("angle", [0.3, 1.2, 2.5, -2.0])
@pytest.mark.parametrize("offset", [0.0042, -0.0011])
def test_three_touches_give_the_offset_across_the_pads(
    legs: list[tuple[int, bool]], angle: float, offset: float
) -> None:
    """The true end is ``offset`` along the across-the-pads direction from the believed one; the
    hand turned by ``yaw`` turns that direction with it. Each touch stops the believed end short
    of its side by the true end's offset along the approach; the pair's two touches of one side
    give the offset, and each side's first touch where the true end met it."""
    yaw = 0.25
    across = np.array([math.cos(angle), math.sin(angle)])
    walls = np.array([0.15, -0.05])  # where the true end meets the -x and the -y side [m]
    touches = []
    for k, (side, turned) in enumerate(legs):
        u = turn(across, yaw if turned else 0.0)
        believed = np.array([0.17 + 0.001 * k, -0.02 - 0.001 * k])
        believed[side] = walls[side] - offset * u[side]
        touches.append(believed)
    pair_side = legs[1][0]
    swing = abs(across[pair_side] - turn(across, yaw)[pair_side])
    if swing < 0.05:
        pytest.skip("this pair sees little of the offset: the strategy touches the other side twice")
    assert pair_offset(touches, legs, across, yaw) == pytest.approx(offset, abs=1e-12)
    s, met = locate_across(touches, legs, across, yaw)
    assert s == pytest.approx(offset, abs=1e-12)
    np.testing.assert_allclose(met, walls, atol=1e-12)


def test_turn_turns_about_the_vertical() -> None:
    np.testing.assert_allclose(turn(np.array([1.0, 0.0]), 0.5 * math.pi), [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(turn(np.array([0.3, -0.4]), 0.0), [0.3, -0.4])


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("yaw", 0.0, "task.strategy.yaw must be > 0, got 0.0"),
        ("touch_speed", -0.01, "task.strategy.touch_speed must be > 0, got -0.01"),
        ("stall_fraction", 1.0, "task.strategy.stall_fraction must be in (0, 1), got 1.0"),
        ("side_touches", 2, "task.strategy.side_touches must be 3 or 4, got 2"),
        (
            "side_depth",
            0.03,
            "task.strategy.side_depth must be below half the block's height (0.025 m), got 0.03",
        ),
    ],
)
def test_bad_settings_are_named(field: str, value: float, message: str) -> None:
    data = apply_overrides(
        {"task": {"name": "held_insertion", "strategy": {"name": "locate", field: value}}}, []
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        episode_config_from_mapping(data)
    assert LocateConfig().insert_speed == 0.03  # slower than probe's


def _forge_difficulty(
    strategy: dict[str, object], observer: float, *, seed: int = 7, friction: float = 0.9, **assets: float
) -> EpisodeConfig:
    """A locate episode at FORGE's difficulty: 3 mm in the hand, 2 degrees of tilt, the hole
    observed 1 mm off (sigma), FORGE's 1 N of force noise, the hand's pose and velocity noisy."""
    mpc = {
        "name": "mpc", "formulation": "contact", "compliance_center": [0.0, -0.07, -0.01],
        "force_limit": 10.0, "force_damping": [2000.0, 2000.0, 100.0], "tare_time": 0.25,
        "control_dt": 0.001, "contact_dt": 0.002, "mpc_dt": 0.005, "q_vel": 100.0,
        "max_contact_speed": 0.002, "accel_filter_hz": 30.0, "moment_filter_hz": 3.5,
        "reversal_backoff": 2.0, "sensor_latency": 0.015, "velocity_filter_hz": 30.0,
        "position_filter_hz": observer,
    }  # fmt: skip
    return episode_config_from_mapping(
        {
            "seed": seed,
            "controller": mpc,
            "task": {
                "name": "held_insertion",
                "strategy": {"name": "locate", **strategy},
                "lateral_error": 0.003,
                "tilt_error": 0.0349066,
                "position_noise": 0.001,
                "drawing_tolerance": 0.00015,
            },
            "domain": {"ft_sensor": "forge", "position_noise": 3e-5, "velocity_noise": 0.001},
            "scene": {"assets": {"chamfer": 0.001, **assets}, "friction": friction},
            "physics": {"profile": "precision"},
        }
    )


@pytest.mark.slow  # one held insertion each, ~10 s of simulation
@pytest.mark.parametrize(
    ("touches", "observer", "within"),
    [
        ({}, 0.0, 0.0003),
        # one reading fewer: a reading's error reaches the end by up to 1 / (2 sin(yaw / 2) cos 45°)
        # against the four touches' 1 / (2 sin(yaw / 2)): 1.41 x 0.3 mm
        ({"side_touches": 3, "quick_datum": True, "side_backoff": 0.0025, "touch_speed": 0.01}, 3.0, 0.00042),
    ],
    ids=["four", "three"],
)
def test_locate_finds_the_end_and_seats_at_forges_difficulty(
    touches: dict[str, object], observer: float, within: float
) -> None:
    """3 mm in the hand, 2 degrees of tilt, the hole observed 1 mm off (sigma), FORGE's 1 N of
    force noise, friction 0.9, the hand's pose and velocity noisy: the end is located to 0.3 mm
    in the hand (0.42 mm with three touches), the tilt to 0.2 degrees, and the peg seats; with
    four touches, or with three (and the controller's position observer)."""
    cfg = _forge_difficulty(touches, observer)
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    task = loop.task

    def end_error() -> np.ndarray:  # the true end from the believed one [m]
        s = loop.state()
        return loop.peg.bottom_world - task.believed_bottom_of(Waypoint.of(s.p_world, s.quat_world, 0.0))  # type: ignore[attr-defined]

    assert float(np.linalg.norm(end_error())) > 0.003
    located = tilt = None
    while True:
        ev = loop.step()
        if located is None and task.phase == "datum":  # type: ignore[attr-defined]
            located = float(np.linalg.norm(end_error()))
        if tilt is None and task.phase == "reference":  # type: ignore[attr-defined]
            tilt = task.strategy.rock.tilt  # type: ignore[attr-defined]
            in_hand = task.disturbance.tilt_sign * cfg.task.tilt_error  # type: ignore[attr-defined]
        if ev.done:
            break
    assert ev.success, ev.detail
    assert located is not None and located < within
    assert tilt is not None and abs(math.degrees(tilt - in_hand)) < 0.2


def test_an_approach_that_never_gets_going_is_a_stall() -> None:
    """The end already on the side as the approach begins (a turn swung it there): the hand
    never follows the command; 0.1 s after the command got going that is a stall, not a push on
    for the whole approach. A hand that follows is no stall until it slows; a hand that sways
    at speed before the command moves has not followed it."""
    from types import SimpleNamespace

    from peg_ctrl.tasks.strategies.skills import SideTouches

    def touches(hand_speed: float) -> SideTouches:
        st = object.__new__(SideTouches)
        st.cfg = LocateConfig(touch_speed=0.01, stall_fraction=0.3)
        st._legs, st.touched = [(0, False), (0, True), (1, True)], [np.zeros(2)]
        st.quat = st._turned = np.array([1.0, 0.0, 0.0, 0.0])
        st.task = SimpleNamespace(hand_velocity=np.array([hand_speed, 0.0, 0.0]))
        st._target = SimpleNamespace(v_world=np.array([0.01, 0.0, 0.0]))
        st._at_speed, st._moving_since = False, None
        return st

    blocked = touches(0.001)
    assert [blocked._stalled(SimpleNamespace(t=t)) for t in (1.0, 1.05, 1.099)] == [False] * 3
    assert blocked._stalled(SimpleNamespace(t=1.101))
    free = touches(0.009)
    assert not any(free._stalled(SimpleNamespace(t=t)) for t in (1.0, 1.05, 1.2))
    free.task.hand_velocity = np.array([0.002, 0.0, 0.0])
    assert free._stalled(SimpleNamespace(t=1.21))
    # The hand still swaying from the move before, at speed along the approach while the command
    # has not got going: not yet following it. A dip of the sway as the command starts is no stall.
    swaying = touches(0.008)
    swaying._target = SimpleNamespace(v_world=np.array([0.001, 0.0, 0.0]))
    assert not swaying._stalled(SimpleNamespace(t=1.0)) and not swaying._at_speed
    swaying._target = SimpleNamespace(v_world=np.array([0.008, 0.0, 0.0]))
    swaying.task.hand_velocity = np.array([0.002, 0.0, 0.0])
    assert not swaying._stalled(SimpleNamespace(t=1.01))


@pytest.mark.parametrize(
    ("angle", "legs"),
    [
        (0.0, [(0, False), (1, False), (1, True)]),  # across along x: a turn moves the end along y
        (0.5 * math.pi, [(0, False), (0, True), (1, True)]),  # along y: it moves along x
        (0.25 * math.pi, [(0, False), (0, True), (1, True)]),
    ],
)
def test_three_touches_pair_the_side_a_turn_moves_the_end_along(
    angle: float, legs: list[tuple[int, bool]]
) -> None:
    """The side touched twice is the one along whose approach a turn by ``yaw`` moves an end
    that sits off across the pads the most; four touches keep both sides' pairs."""
    from peg_ctrl.tasks.strategies.skills import SideTouches

    st = object.__new__(SideTouches)
    st.cfg = LocateConfig(side_touches=3)
    st._across = np.array([math.cos(angle), math.sin(angle)])
    assert st._plan_legs() == legs
    st.cfg = LocateConfig()
    assert st._plan_legs() == [(0, False), (0, True), (1, False), (1, True)]


def test_turn_speed_zero_is_the_tasks_limit_and_negative_is_refused() -> None:
    assert LocateConfig().turn_speed == 0.0
    data = apply_overrides(
        {"task": {"name": "held_insertion", "strategy": {"name": "locate", "turn_speed": -1.0}}}, []
    )
    with pytest.raises(ConfigError, match=r"^task\.strategy\.turn_speed must be >= 0, got -1\.0$"):
        episode_config_from_mapping(data)


@pytest.mark.slow  # the search and the centring of one held insertion each, ~8 s of simulation
@pytest.mark.parametrize("reanchor", [False, True])
def test_every_push_of_the_centring_reaches_its_wall(reanchor: bool) -> None:
    """The centring pushes the end in the bore's mouth along +x, -x, +y, -y. Reversing a push
    keeps that axis force-controlled, and the contact loop goes on from its command, pressed
    into the wall just found: without ``centre_reanchor`` (the default, which the committed
    studies ran) the hand can stand still there and a wall is read where there is none, the true
    end well inside the bore. With it, every reading has the true end at a wall: the bore's radial
    clearance from its axis, to 10 micrometres (the contact gives a few). The
    descent then starts within 20 micrometres of the axis: the midpoint of readings that each
    average 20 ms of a 0.03 mm pose noise (7 micrometres), and the hand's wander."""
    strategy = {"side_touches": 3, "quick_datum": True, "side_backoff": 0.0025, "touch_speed": 0.005}
    cfg = _forge_difficulty(
        {**strategy, "centre_reanchor": reanchor}, 3.0, seed=13, friction=0.3, clearance=5e-5
    )
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    task = loop.task
    clearance = cfg.scene.assets.clearance

    def off_axis() -> float:  # the true end from the bore's true axis [m]
        bottom = loop.peg.bottom_world
        return math.hypot(bottom[0] - task.insertion.hole_x, bottom[1] - task.insertion.hole_y)  # type: ignore[attr-defined]

    at_walls: list[float] = []
    while task.phase != "insert":  # type: ignore[attr-defined]
        assert not loop.step().done
        centring = task.strategy.centring  # type: ignore[attr-defined]
        if centring is not None and len(centring.walls) > len(at_walls):
            at_walls.append(off_axis())
    assert len(at_walls) == 4
    t0 = loop.data.time
    while loop.data.time < t0 + 0.15:  # the relax dwell and the move onto the axis
        loop.step()
    if reanchor:
        assert clearance - 1e-5 < min(at_walls) <= max(at_walls) < clearance + 1e-5, at_walls
        assert off_axis() < 2e-5
    else:
        assert min(at_walls) < clearance - 1e-5, at_walls


@pytest.mark.slow  # one held insertion each way, ~9 s of simulation each
def test_a_slower_friction_lets_the_descent_slide_past_the_bores_edge() -> None:
    """The descent's taps are friction at the touch (docs/physics.md, "Known limits"): a contact
    that appears under the peg sliding down at 30 mm/s starts out sticking, and MuJoCo's convex
    model starts the slip by pushing the peg off. contact_real's featured arm, development seed
    115, friction 0.9, 1 mm in the hand, the wrist sensor: with the precision profile's friction
    (the normal's 1 ms) the descent passes 20 N; with ``physics.friction_time`` 5 ms it stays
    within 10 N, and both seat."""
    from pathlib import Path

    from peg_ctrl.config import read_mapping
    from peg_ctrl.experiments.config import expand, experiment_from_mapping
    from peg_ctrl.sim.physics import PhysicsConfig
    from peg_ctrl.sim.state import PAIRS

    data = read_mapping(Path(__file__).parents[3] / "experiments" / "configs" / "contact_real.yaml")
    mpc = next(c for c in data["controllers"] if c["name"] == "mpc")
    arm = {"side_touches": 3, "quick_datum": True, "side_backoff": 0.0025, "touch_speed": 0.005}
    data.update(
        controllers=[{**mpc, "position_filter_hz": 3.0}],
        strategies=[{"name": "locate", **arm, "centre_reanchor": True}],
        arms={"mpc": ["locate"]},
        seeds=[115],
        grid={
            "scene.friction": [0.9],
            "task.lateral_error": [0.001],
            "task.tilt_error": [0.0],
            "sensor": {"domain.ft_sensor": ["wrist"], "task.position_noise": [0.0005]},
        },
    )
    (job,) = expand(experiment_from_mapping(data))
    block_peg = PAIRS.index(("block", "peg"))

    class Descent:  # the largest peg-block force of the descent [N]
        peak = 0.0

        def record(self, loop: object, info: StepInfo) -> None:
            if info.phase == "insert":
                self.peak = max(self.peak, info.forces[block_peg])

    peaks = {}
    for friction_time in (None, 0.005):
        cfg = dataclasses.replace(job.config, physics=PhysicsConfig("precision", friction_time=friction_time))
        descent = Descent()
        loop = build_loop(cfg, recorders=[descent])
        loop.reset(np.random.default_rng(cfg.seed))
        while not (ev := loop.step()).done:
            pass
        assert ev.success, ev.detail
        peaks[friction_time] = descent.peak
    assert peaks[None] > 20.0 and peaks[0.005] < 10.0, peaks
