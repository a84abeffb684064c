"""The pure key mapping: axes, rate limits, deadzone, speed keys, jaw range."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.teleop import KEYMAP, TeleopConfig, TeleopMapper

CFG = TeleopConfig()
DT = 0.001
HOME = np.array([-0.2, 0.0, 0.2])


def _mapper() -> TeleopMapper:
    return TeleopMapper(CFG, p_world=HOME, quat_world=[1.0, 0.0, 0.0, 0.0], jaw_sep_m=0.04)


def _hold(m: TeleopMapper, key: str, seconds: float, *, shift: bool = False) -> None:
    m.press(key, shift=shift)
    for _ in range(int(round(seconds / DT))):
        m.step(DT)
    m.release(key)


def _rates(m: TeleopMapper) -> np.ndarray:
    """Body angular displacement of the command since home [rad]."""
    rotvec = np.zeros(3)
    mujoco.mju_subQuat(rotvec, m.quat_world, np.array([1.0, 0.0, 0.0, 0.0]))
    return rotvec


@pytest.mark.parametrize("key, index, sign", [(k, i, s) for k, (i, s) in KEYMAP.items()])
def test_each_key_moves_its_axis_in_its_direction(key: str, index: int, sign: float) -> None:
    m = _mapper()
    _hold(m, key, 0.5)
    moved = np.concatenate([m.p_world - HOME, _rates(m), [m.jaw_sep_m - 0.04]])
    assert np.sign(moved[index]) == sign
    others = np.delete(moved, index)
    assert np.abs(others).max() < 1e-12, f"{key} moved other axes: {moved}"


def test_release_stops_the_motion() -> None:
    m = _mapper()
    _hold(m, "Q", 0.5)  # a rotation, the case that used to stick
    for _ in range(1000):
        m.step(DT)
    assert np.all(m.velocity == 0.0)
    frozen = m.quat_world.copy()
    for _ in range(500):
        m.step(DT)
    np.testing.assert_array_equal(m.quat_world, frozen)


def test_rate_limit_and_full_speed() -> None:
    m = _mapper()
    m.press("6")
    previous = 0.0
    for _ in range(300):
        m.step(DT)
        assert m.velocity[0] - previous <= CFG.lin_accel * DT + 1e-15
        previous = m.velocity[0]
    assert m.velocity[0] == pytest.approx(CFG.lin_speed)  # reached after lin_speed / lin_accel = 0.1 s


def test_deadzone_zeroes_small_velocities() -> None:
    m = _mapper()
    m.press("8")
    m.step(DT)  # one step of ramp: 0.6 mm/s, inside the 2 % deadzone of 60 mm/s
    m.release("8")
    m.step(DT)
    assert m.velocity[2] == 0.0


def test_fine_motion_and_speed_keys() -> None:
    m = _mapper()
    _hold(m, "6", 1.0, shift=True)
    assert m.velocity.max() <= CFG.lin_speed * CFG.fine_scale + 1e-12
    for key, speed in (("J", 0.5), ("K", 1.0), ("L", 2.0)):
        m.press(key)
        assert m.speed == speed
    for _ in range(20):
        m.press("=")
    assert m.speed == 5.0
    for _ in range(40):
        m.press("-")
    assert m.speed == 0.1
    with pytest.raises(ValueError, match="speed multiplier"):
        m.set_speed(7.0)


def test_jaw_command_stays_in_range() -> None:
    m = _mapper()
    _hold(m, "]", 3.0)
    assert m.jaw_sep_m == 0.0
    _hold(m, "[", 5.0)
    assert m.jaw_sep_m == 0.085
