"""Monitors on synthetic observations, and divergence on real MuJoCo data."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.monitors import (
    ContactMonitor,
    DivergenceMonitor,
    InsertionMonitor,
    SeatedCriterion,
    SettledCriterion,
)
from peg_ctrl.scene import SceneConfig
from peg_ctrl.state import BLOCK_PEG, PAIRS, PegObservation

SCENE = SceneConfig()
TOP = SCENE.assets.block_size[2]
HX, HY = SCENE.hole_xy


def peg(centre, axis, *, speed: float = 0.0) -> PegObservation:  # type: ignore[no-untyped-def]
    c, a = np.asarray(centre, float), np.asarray(axis, float) / np.linalg.norm(axis)
    bottom = c - 0.5 * SCENE.assets.peg_length * (a if a[2] >= 0 else -a)
    return PegObservation(c, np.array([1.0, 0, 0, 0]), a, bottom, speed, 0.0)


def test_upright_peg_on_the_axis() -> None:
    half = 0.5 * SCENE.assets.peg_length
    m = InsertionMonitor(SCENE, SeatedCriterion(0.04, 0.0025, 0.1)).measure(
        peg((HX, HY, TOP - 0.03 + half), (0, 0, 1))
    )
    assert m.depth_m == pytest.approx(0.03)
    assert m.lateral_error_m == pytest.approx(0.0, abs=1e-12)
    assert m.radial_m == pytest.approx(0.0, abs=1e-12)
    assert m.tilt_rad == pytest.approx(0.0, abs=1e-7)


def test_lateral_error_is_measured_at_the_mouth() -> None:
    tilt = 0.05
    axis = (math.sin(tilt), 0.0, math.cos(tilt))
    # The axis passes 1 mm beside the hole axis at the mouth, the centre is higher and further off.
    at_mouth = np.array([HX + 0.001, HY, TOP])
    centre = at_mouth + 0.05 * np.asarray(axis)
    m = InsertionMonitor(SCENE, SeatedCriterion(0.04, 0.0025, 0.1)).measure(peg(centre, axis))
    assert m.lateral_error_m == pytest.approx(0.001)
    assert m.radial_m == pytest.approx(0.001 + 0.05 * math.sin(tilt))
    assert m.tilt_rad == pytest.approx(tilt)


def test_a_horizontal_peg_has_no_lateral_error_at_the_mouth() -> None:
    m = InsertionMonitor(SCENE, SeatedCriterion(0.04, 0.0025, 0.1)).measure(peg((HX, HY, 0.2), (0, 1, 0)))
    assert m.lateral_error_m == math.inf and m.tilt_rad == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    ("depth", "lateral", "tilt", "seated"),
    [(0.05, 0.0, 0.0, True), (0.03, 0.0, 0.0, False), (0.05, 0.003, 0.0, False), (0.05, 0.0, 0.2, False)],
)
def test_seated_criterion(depth: float, lateral: float, tilt: float, seated: bool) -> None:
    from peg_ctrl.monitors import InsertionMeasure

    assert SeatedCriterion(0.04, 0.0025, 0.1)(InsertionMeasure(depth, lateral, 0.0, 0.0, tilt, 0.0)) is seated


def test_settled_criterion_is_spec_5() -> None:
    from peg_ctrl.monitors import InsertionMeasure

    c = SettledCriterion(max_radial=0.03, max_bottom_z=0.07, max_speed=0.05)
    assert c(InsertionMeasure(0.0, 0.0, 0.029, 0.069, 0.0, 0.049))
    assert not c(InsertionMeasure(0.0, 0.0, 0.031, 0.069, 0.0, 0.0))
    assert not c(InsertionMeasure(0.0, 0.0, 0.0, 0.07, 0.0, 0.0))
    assert not c(InsertionMeasure(0.0, 0.0, 0.0, 0.0, 0.0, 0.051))


def test_contact_monitor_keeps_peaks_and_fails_on_a_spike() -> None:
    m = ContactMonitor(force_spike=150.0)
    forces = [0.0] * len(PAIRS)
    forces[BLOCK_PEG] = 12.0
    m.check(forces, [1e-4, 2e-4, 3e-4])
    assert (m.peak_block, m.peak_any, m.max_penetration, m.grip_penetration) == (12.0, 12.0, 3e-4, 2e-4)
    forces[BLOCK_PEG] = 151.0
    with pytest.raises(EpisodeFailure) as info:
        m.check(forces, [0.0, 0.0, 0.0])
    assert info.value.reason == "force_spike" and "block-peg" in info.value.detail
    ContactMonitor(force_spike=None).check(forces, [0.0, 0.0, 0.0])  # no limit: no failure


def test_divergence_monitor_catches_a_nan_and_a_warning(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    m = DivergenceMonitor(state_every=1)
    m.reset(data)
    m.check(data)  # a clean state passes
    data.qvel[0] = np.nan
    with pytest.raises(EpisodeFailure, match="diverged"):
        m.check(data)
    data.qvel[0] = 0.0
    data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number += 1  # as MuJoCo counts a blow-up
    with pytest.raises(EpisodeFailure, match="diverged"):
        m.check(data)
