"""Monitors on synthetic observations, and divergence on real MuJoCo data."""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.state import BLOCK_PEG, PAIRS, PegObservation
from peg_ctrl.tasks.monitors import (
    ContactMonitor,
    DivergenceMonitor,
    InsertionMonitor,
    SeatedCriterion,
    SettledCriterion,
)

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
    from peg_ctrl.tasks.monitors import InsertionMeasure

    assert SeatedCriterion(0.04, 0.0025, 0.1)(InsertionMeasure(depth, lateral, 0.0, 0.0, tilt, 0.0)) is seated


def test_settled_criterion_is_spec_5() -> None:
    from peg_ctrl.tasks.monitors import InsertionMeasure

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


def test_contact_monitor_keeps_the_force_sustained_over_10_ms_apart_from_the_solver_peak() -> None:
    m = ContactMonitor()
    assert m.peak_block_sustained == 0.0
    m.sustain([0.0, 30.0], 0.5e-3)  # a one-step spike: 15 mN s
    m.sustain([0.0] * 25, 0.5e-3)
    assert m.peak_block_sustained == pytest.approx(30.0 * 0.5e-3 / 0.010)  # 1.5 N over 20 steps
    m.sustain([2.0] * 25, 0.5e-3)  # a steady 2 N
    assert m.peak_block_sustained == pytest.approx(2.0) and m.peak_block == 0.0  # check() keeps that one
    m.reset()
    assert m.peak_block_sustained == 0.0


def test_divergence_monitor_catches_a_nan_and_a_warning(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    m = DivergenceMonitor()
    m.reset(data)
    m.check(data, 0.0)  # a clean state passes
    data.qvel[0] = np.nan
    with pytest.raises(EpisodeFailure, match="non-finite state") as info:
        m.check(data, 0.0)
    assert info.value.reason == "diverged"
    data.qvel[0] = 0.0
    data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number += 1  # as MuJoCo counts a blow-up
    data.warning[mujoco.mjtWarning.mjWARN_BADQACC].lastinfo = 3
    with pytest.raises(EpisodeFailure, match=r"QACC at DOF 3.*mjWARN_BADQACC"):
        m.check(data, 0.0)


def test_divergence_monitor_sees_mujocos_reset_through_old_warnings(model: mujoco.MjModel) -> None:
    """A bad state makes MuJoCo reset the data, which clears the warning counters before it
    counts the new one: with one warning already counted at the start, the count is unchanged,
    but time went back."""
    data = mujoco.MjData(model)
    data.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number = 1
    m = DivergenceMonitor()
    m.reset(data)
    data.time = 2.5
    m.check(data, 2.4)
    data.time = 0.001  # after MuJoCo's reset and one step
    with pytest.raises(EpisodeFailure, match=r"time went back from 2.6000 s to 0.0010 s.*BADQVEL"):
        m.check(data, 2.6)


def test_a_bad_velocity_mid_episode_ends_it_diverged_not_force_spike(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A velocity of 1e12 (as a blow-up produces) injected after a control step: MuJoCo flags it
    on the next physics step and resets the state, whose jump would also read as a force spike;
    the episode ends ``diverged``, naming MuJoCo's warning."""
    from peg_ctrl.run.episode import episode_config_from_mapping, run_episode

    def kick(model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if 1.0 <= data.time < 1.0 + 0.006:
            data.qvel[:] = 1e12

    cfg = episode_config_from_mapping({"max_steps": 3000})
    result = run_episode(cfg, tmp_path, plot=False, on_step=kick)
    assert (result.status, result.reason) == ("failure", "diverged")
    assert "mjWARN_BADQVEL" in result.detail
    assert 1.0 <= result.sim_time_s <= 1.02 or "time went back" in result.detail


def test_a_degenerate_peg_diverges_and_a_sweep_goes_on(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A peg of 1e-30 times its mass: MuJoCo's inertia solve fails within a few steps. That
    episode ends ``diverged``; the sweep runs the others to the end."""
    from peg_ctrl.experiments.config import experiment_from_mapping
    from peg_ctrl.experiments.runner import run_sweep

    exp = experiment_from_mapping(
        {
            "name": "diverge",
            "controllers": [{"name": "pd"}],
            "seeds": 1,
            "max_steps": 1500,
            "grid": {"domain.peg_mass_scale": [[1e-30, 1e-30], [1.0, 1.0]]},
        }
    )
    rows = run_sweep(exp, tmp_path / "sweep", workers=1, progress=False, report=False)
    reasons = sorted(row["reason"] for row in rows)
    assert len(rows) == 2 and reasons == ["diverged", "timeout"]
    details = [
        json.loads(p.read_text())["detail"] for p in (tmp_path / "sweep").glob("episodes/*/summary.json")
    ]
    assert any("mjWARN_INERTIA" in d for d in details), details
