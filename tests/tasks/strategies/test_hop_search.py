"""The align strategy's hop search: its lattice covers the plane, it visits every point once, and
a press that drops onto the chamfer sends the peg towards the hole."""

from __future__ import annotations

import math

import numpy as np
import pytest

from peg_ctrl.planners import make_planner
from peg_ctrl.planners.base import MotionLimits
from peg_ctrl.tasks.strategies.hop_search import HexLattice, HopSearch, HopSettings

CENTRE = np.array([0.2, 0.0])
Z_FACE = 0.05
SETTINGS = HopSettings(
    press_force=0.6,
    hover=8e-5,
    lift=2e-4,
    hop_speed=0.01,
    lower_speed=0.002,
    drop_min=3e-5,
    capture=0.00105,
    settle_time=0.05,
    guide_time=1.0,
)
DT = 0.001


def test_the_lattice_leaves_no_gap_and_grows_ring_by_ring() -> None:
    lattice = HexLattice(pitch=0.0016, radius=0.004)
    points = np.array(lattice.points())
    assert points.shape == (1 + 6 + 12, 2)  # rings 1 and 2 reach 2.77 mm; ring 3 (4.16 mm) is out
    np.testing.assert_array_equal(points[0], [0.0, 0.0])
    distances = np.linalg.norm(points, axis=1)
    assert np.all(np.diff(distances[:7]) >= 0) and distances[7:].min() > distances[:7].max()
    # Every point of the disc the lattice spans is within pitch / sqrt(3) of a lattice point.
    rng = np.random.default_rng(0)
    probe = rng.uniform(-1.0, 1.0, (4000, 2)) * 0.0024
    probe = probe[np.linalg.norm(probe, axis=1) <= 0.0024]
    nearest = np.min(np.linalg.norm(probe[:, None] - points[None], axis=2), axis=1)
    assert nearest.max() <= 0.0016 / math.sqrt(3.0) + 1e-12


def _search(radius: float) -> HopSearch:
    return HopSearch(
        centre=CENTRE,
        z_face=Z_FACE,
        quat=np.array([1.0, 0.0, 0.0, 0.0]),
        lattice=HexLattice(pitch=0.0016, radius=radius),
        settings=SETTINGS,
        planner=make_planner("ruckig"),
        limits=MotionLimits(),
        tip_to_pinch=lambda tip, q: tip + np.array([0.0, 0.0, 0.1]),
        t0=0.0,
    )


def _run(search: HopSearch, drop: float, moment: tuple[float, float], until: float) -> float:
    """Step the search with the peg's end pressed ``drop`` below the face wherever it is sent."""
    t = 0.0
    while t < until and not search.exhausted:
        target = search.sample(t)
        tip = target.p_world - np.array([0.0, 0.0, 0.1])
        pressing = target.force_controlled
        tip[2] = Z_FACE - drop if pressing else tip[2]
        force = np.array([0.0, 0.0, SETTINGS.press_force if pressing else 0.0])
        search.step(t, tip, force, np.array([*moment, 0.0]) * force[2], pressing)
        t += DT
    return t


def test_a_search_on_the_face_presses_every_point_once_then_is_exhausted() -> None:
    search = _search(radius=0.0014)  # the centre and one ring: 7 points
    t = _run(search, drop=0.0, moment=(0.0, 0.0), until=10.0)
    assert search.exhausted and t < 10.0
    assert (search.index, search.hops, search.chamfer_hits) == (6, 6, 0)
    last = search.sample(t).p_world[:2]
    np.testing.assert_allclose(last, CENTRE + search.points[6], atol=1e-9)  # no wrap to the centre


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_drop_onto_the_chamfer_sends_the_peg_towards_the_hole(side: float) -> None:
    """Pressed 0.5 mm below the face with the contact on the +x (or -x) side of the tip (a
    moment about y of -x_cop * F): the hole is the other way, capture - drop away."""
    search = _search(radius=0.0014)
    _run(search, drop=0.0005, moment=(0.0, -side * 0.001), until=0.2)
    assert search.chamfer_hits == 1
    goal = search._trajectory.sample(1e3).p_world[:2]  # noqa: SLF001 - where the hop ends
    np.testing.assert_allclose(goal - CENTRE, [-side * (SETTINGS.capture - 0.0005), 0.0], atol=1e-6)
