"""The probe strategy's estimators: the belief over the hole narrows as landings, misses and
bearings say, and the rock calibration's fit recovers the peg's tilt in the hand from landing
heights."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from peg_ctrl.sim.belief import HoleBelief
from peg_ctrl.tasks.strategies.probe import ProbeConfig
from peg_ctrl.tasks.strategies.skills import RockCalibration

CFG = ProbeConfig()
CENTRE = (0.2, 0.0)  # the observed hole [m]
REACH = 0.0015  # clearance + chamfer [m]
CAPTURE = REACH - CFG.drop_min


def _belief(radius: float = CFG.search_radius) -> HoleBelief:
    return HoleBelief(CENTRE, radius=radius, sigma=CFG.search_sigma, capture=CAPTURE)


def _mass(belief: HoleBelief, keep: NDArray[np.bool_]) -> float:
    return float(belief.weights[keep].sum())


# -- the prior ---------------------------------------------------------------------------------------


def test_the_prior_is_a_truncated_gaussian_about_the_observed_hole() -> None:
    b = _belief()
    r = CFG.search_radius / 1e-4  # in grid steps
    assert b.points.shape[1] == 2 and b.weights.shape == (len(b.points),)
    assert np.pi * (r - 1) ** 2 < len(b.points) < np.pi * (r + 1) ** 2  # the grid points in the disc
    assert np.linalg.norm(b.points - CENTRE, axis=1).max() <= CFG.search_radius
    assert b.weights.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(b.mean, CENTRE, atol=1e-15)
    np.testing.assert_array_equal(b.most_likely, CENTRE)
    np.testing.assert_array_equal(b.best_probe(), CENTRE)
    # The spread of a 2-d Gaussian of sigma cut at R: E r^2 = 2 s^2 (1 - (1 + u) e^-u) / (1 - e^-u).
    s, u = CFG.search_sigma, CFG.search_radius**2 / (2.0 * CFG.search_sigma**2)
    expected = math.sqrt(2.0 * s * s * (1.0 - (1.0 + u) * math.exp(-u)) / (1.0 - math.exp(-u)))
    assert b.spread == pytest.approx(expected, rel=0.01)  # 2.70 mm


@pytest.mark.parametrize(
    ("radius", "sigma", "capture", "spacing"),
    [(0.0, 0.002, 0.001, 1e-4), (0.005, 0.0, 0.001, 1e-4), (0.005, 0.002, 1e-4, 1e-4)],
)
def test_the_belief_checks_its_parameters(
    radius: float, sigma: float, capture: float, spacing: float
) -> None:
    with pytest.raises(ValueError, match="need radius > 0, sigma > 0 and capture > spacing > 0"):
        HoleBelief(CENTRE, radius=radius, sigma=sigma, capture=capture, spacing=spacing)


# -- landings ----------------------------------------------------------------------------------------


def test_a_landing_on_the_chamfer_puts_the_hole_on_a_ring_and_three_fix_it() -> None:
    """The hole 1.12 mm off the observation. A landing 1 mm from it sank 0.5 mm: the axis is 1 mm
    from that landing (a ring, 4 % of the prior's mass within 0.1 mm of it before, all of it
    after). Two more landings from other sides leave one point: the hole."""
    b = _belief()
    hole = np.array(CENTRE) + np.array([0.001, 0.0005])
    sides = [np.array([-1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.6, -0.8])]
    gaps = [0.001, 0.0008, 0.0011]  # how far each landing is from the axis [m]
    p = hole + gaps[0] * sides[0]
    ring = np.abs(np.linalg.norm(b.points - p, axis=1) - gaps[0]) < 1e-4
    assert 0.02 < _mass(b, ring) < 0.08
    b.landing(p, REACH - gaps[0], reach=REACH, sigma=CFG.drop_sigma)
    assert _mass(b, ring) > 0.999
    for side, gap in zip(sides[1:], gaps[1:], strict=True):
        b.landing(hole + gap * side, REACH - gap, reach=REACH, sigma=CFG.drop_sigma)
    np.testing.assert_allclose(b.most_likely, hole, atol=1e-9)
    assert _mass(b, np.linalg.norm(b.points - hole, axis=1) < 1.5e-4) > 0.95
    assert np.linalg.norm(b.mean - hole) < 5e-5 and b.spread < 1e-4


def test_a_landing_on_the_face_rules_out_the_disc_it_would_have_dropped_in() -> None:
    """No depth: the axis is at least ``reach`` away. Within 1.4 mm (6.7 sigma of the depth
    inside the 1.5 mm reach) the belief is gone; beyond the reach the prior is scaled up, its
    shape kept."""
    b = _belief()
    prior = b.weights.copy()
    p = np.array(CENTRE) + np.array([0.0005, 0.0])
    d = np.linalg.norm(b.points - p, axis=1)
    b.landing(p, 0.0, reach=REACH, sigma=CFG.drop_sigma)
    assert _mass(b, d < 0.0014) < 1e-9
    outside = d >= REACH
    ratio = b.weights[outside] / prior[outside]
    assert np.ptp(ratio) < 1e-12 * ratio.max()
    assert 1.0 < ratio[0] < 1.0 / prior[outside].sum()  # the rim inside the reach keeps a little


def test_evidence_against_every_particle_starts_the_belief_over_flat() -> None:
    b = _belief()
    b.landing(np.array(CENTRE), 0.01, reach=REACH, sigma=CFG.drop_sigma)  # 10 mm deep: no particle fits
    np.testing.assert_array_equal(b.weights, np.full(len(b.points), 1.0 / len(b.points)))


# -- no drop ------------------------------------------------------------------------------------------


def test_no_drop_scales_the_capture_disc_by_the_miss_chance() -> None:
    """A press at the centre met the face: the disc of mass m keeps miss m / (miss m + 1 - m)."""
    b = _belief()
    p = np.array(CENTRE)
    m = b.capture_mass(p)
    assert m == pytest.approx(1.0 - math.exp(-(CAPTURE**2) / (2.0 * CFG.search_sigma**2)), rel=0.03)  # 0.23
    b.no_drop(p, miss=0.02)
    assert b.capture_mass(p) == pytest.approx(0.02 * m / (0.02 * m + 1.0 - m), rel=1e-9)
    b.no_drop(p, miss=0.0)
    assert b.capture_mass(p) == 0.0
    # The belief is now a ring: its mean stays, its most likely point moves out of the disc.
    np.testing.assert_allclose(b.mean, CENTRE, atol=1e-15)
    assert CAPTURE <= np.linalg.norm(b.most_likely - p) < CAPTURE + 1.5e-4


# -- bearings -----------------------------------------------------------------------------------------


def _bearing_mean(towards: NDArray[np.float64], kappa: float) -> NDArray[np.float64]:
    """The mean of the prior times the bearing's likelihood from the centre (1 within the capture
    disc, a von Mises on the direction outside it), by quadrature in polar coordinates [m]."""
    s, big = CFG.search_sigma, CFG.search_radius
    r = (np.arange(4000) + 0.5) * big / 4000
    phi = (np.arange(720) + 0.5) * 2.0 * math.pi / 720
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    cos = np.cos(pp) * towards[0] + np.sin(pp) * towards[1]
    w = np.exp(-0.5 * (rr / s) ** 2) * np.where(rr < CAPTURE, 1.0, np.exp(kappa * (cos - 1.0))) * rr
    return np.array([(w * rr * np.cos(pp)).sum(), (w * rr * np.sin(pp)).sum()]) / w.sum()


@pytest.mark.parametrize("angle", [0.0, math.radians(30.0)])
def test_a_bearing_moves_the_mean_along_its_direction(angle: float) -> None:
    """Bearings of 0.3 rad (kappa 11) and 1 rad (kappa 1) towards ``angle``: the mean moves that
    way, by what the continuous posterior's mean says (0.76 mm both: the capture disc, where the
    bearing says nothing, keeps its mass and holds the mean back), and the sharper bearing leaves
    less behind the landing."""
    towards = np.array([math.cos(angle), math.sin(angle)])
    behind = []
    for kappa in (1.0 / 0.3**2, 1.0):
        b = _belief()
        rel = b.points - CENTRE
        b.bearing(np.array(CENTRE), towards, kappa=kappa)
        shift = b.mean - CENTRE
        np.testing.assert_allclose(shift, _bearing_mean(towards, kappa), rtol=0.03, atol=2e-6)
        assert abs(math.atan2(shift[1], shift[0]) - angle) < math.radians(1.0)
        assert float(np.linalg.norm(shift)) > 7e-4
        behind.append(_mass(b, (rel @ towards < 0.0) & (np.linalg.norm(rel, axis=1) >= CAPTURE)))
    assert behind[0] < 1e-3 < 0.05 < behind[1]


# -- best probe, most likely, peak -------------------------------------------------------------------------


def test_the_best_probe_holds_the_most_belief_within_the_search_radius() -> None:
    """After a miss at the centre and a bearing towards +y, the best probe is the grid point whose
    capture disc holds the most belief (by brute force over every particle), inside the disc."""
    b = _belief(radius=0.003)
    b.no_drop(np.array(CENTRE), miss=0.0)
    b.bearing(np.array(CENTRE), np.array([0.0, 1.0]), kappa=4.0)
    best = b.best_probe()
    assert np.linalg.norm(best - CENTRE) <= 0.003
    assert best[1] - CENTRE[1] > CAPTURE / 2.0  # towards the bearing
    masses = [b.capture_mass(p) for p in b.points]
    assert b.capture_mass(best) == pytest.approx(max(masses), rel=1e-9)


def test_most_likely_and_peak_on_a_hand_made_belief() -> None:
    """Weight 0.5 at the centre, 0.3 at 0.1 mm along x, 0.2 at 0.3 mm along x: the most likely
    point is the centre; the peak within 0.2 mm is (0.3 x 0.1) / 0.8 = 0.0375 mm along x, within
    0.35 mm the mean of all three, 0.09 mm."""
    b = _belief(radius=0.001)
    offsets = np.array([[0.0, 0.0], [1e-4, 0.0], [3e-4, 0.0]])
    b.weights = np.zeros(len(b.points))
    for offset, w in zip(offsets, (0.5, 0.3, 0.2), strict=True):
        b.weights[np.argmin(np.linalg.norm(b.points - CENTRE - offset, axis=1))] = w
    np.testing.assert_allclose(b.most_likely, CENTRE, atol=1e-15)
    np.testing.assert_allclose(b.peak(2e-4) - CENTRE, [3.75e-5, 0.0], atol=1e-12)
    np.testing.assert_allclose(b.peak(3.5e-4) - CENTRE, [9e-5, 0.0], atol=1e-12)
    np.testing.assert_allclose(b.mean - CENTRE, [9e-5, 0.0], atol=1e-12)


# -- the rock calibration's fit ----------------------------------------------------------------------------

_Q0 = Rotation.from_euler("xz", [math.pi, 0.4])  # the hand pointing down, turned 0.4 rad about z
UP_BODY = _Q0.inv().apply([0.0, 0.0, 1.0])  # the believed peg axis, upright at the touch
GRASP_BODY = np.array([0.0, 0.002, 0.001])  # where the pads hold the axis, from the pinch point [m]
GRIP_LENGTH = 0.06  # pads to the lower end [m]
RADIUS = 0.01  # the peg's [m]


def _wxyz(r: Rotation) -> NDArray[np.float64]:
    x, y, z, w = r.as_quat()
    return np.array([w, x, y, z])


def _calibration(
    tilt: float,
    z_face: float,
    noise: NDArray[np.float64],
    *,
    offset: float = 0.0,
    end_known: bool = False,
    turns: tuple[float, ...] = (1.0, -1.0),
    free_end: bool = False,
) -> RockCalibration:
    """The calibration after its three landings, the touch and at +/- ``rock_angle`` about the
    pads' normal (gripper x), for a peg tilted by ``tilt`` [rad] about it in the hand and held
    ``offset`` [m] along the pads' plane, across its axis, from where the task believes: each hand
    pose put the lowest point of the peg's end on the face at ``z_face`` [m] (plus ``noise`` (3,)).
    ``end_known``: the task's belief of the end is the true end (located by touch); ``turns``: the
    turned landings, in ``rock_angle``; ``free_end``: the fit looks for the end's offset across
    the pads too (up to 6 mm either way)."""
    up_true = Rotation.from_rotvec(tilt * np.array([1.0, 0.0, 0.0])).apply(UP_BODY)
    across = np.cross(UP_BODY, [1.0, 0.0, 0.0])
    grasp_true = GRASP_BODY + offset * across
    x_world = _Q0.apply([1.0, 0.0, 0.0])
    landings = []
    for k, angle in enumerate((0.0, *(t * CFG.rock_angle for t in turns))):
        r = Rotation.from_rotvec(angle * x_world) * _Q0
        tip = r.apply(grasp_true - GRIP_LENGTH * up_true)  # the true lower end's centre, from the pinch
        axis = r.apply(up_true)
        lowest = RADIUS * math.sqrt(1.0 - axis[2] ** 2)  # the end's rim below its centre
        p = np.array([0.17 + 0.001 * k, -0.02, z_face + noise[k] - tip[2] + lowest])
        landings.append(SimpleNamespace(p_world=p, quat_world=_wxyz(r)))
    cal = RockCalibration.__new__(RockCalibration)  # the fit alone: no strategy, no motion
    # Located by touch, the believed end is the true one (on the believed, upright axis).
    grasp = grasp_true - GRIP_LENGTH * up_true + GRIP_LENGTH * UP_BODY if end_known else GRASP_BODY
    cal.task = SimpleNamespace(up_body=UP_BODY, grasp_body=grasp, grip_length=GRIP_LENGTH, radius=RADIUS)
    cal.end_known = end_known
    cal.landings = landings
    cal._thetas = np.linspace(-CFG.max_tilt, CFG.max_tilt, 321)  # as __init__ makes it
    cal._ends = np.linspace(-0.006, 0.006, 61) if free_end else np.zeros(1)
    cal._end_body = across / np.linalg.norm(across) if free_end else np.zeros(3)
    cal.end = 0.0
    return cal


@pytest.mark.parametrize("tilt_deg", [2.0, -2.0, 0.0])
@pytest.mark.parametrize("offset", [0.003, -0.001])
@pytest.mark.parametrize("swing_in_end", [False, True])
def test_the_rock_with_a_free_end_finds_the_tilt_and_where_the_end_is(
    tilt_deg: float, offset: float, swing_in_end: bool
) -> None:
    """Five landings (the touch, +/- rock_angle, +/- 1.6 rock_angle): the offset that the
    three-landing fit reads as a tilt is fitted with it, the tilt to 0.05 degrees and the offset
    to the grid's 0.2 mm step. Where the tilt's model turns the end about the pads (``end_known``
    false) the offset is the grasp's; where it does not (``plan``: the belief's offset of the end
    holds the tilt's swing too) it is the grasp's and the swing, ``grip_length`` per radian, and
    the swing's rise, ``grip_length (1 - cos tilt)``, goes into the face's height."""
    tilt = math.radians(tilt_deg)
    cal = _calibration(tilt, 0.05, np.zeros(5), offset=offset, turns=(1.0, -1.0, 1.6, -1.6), free_end=True)
    cal.end_known = swing_in_end
    cal._fit()
    up_true = Rotation.from_rotvec(tilt * np.array([1.0, 0.0, 0.0])).apply(UP_BODY)
    across = np.cross(UP_BODY, [1.0, 0.0, 0.0])
    swing = GRIP_LENGTH * (UP_BODY - up_true) if swing_in_end else np.zeros(3)
    end = float((offset * across + swing) @ across)
    rise = GRIP_LENGTH * (1.0 - math.cos(tilt)) if swing_in_end else 0.0
    assert cal.tilt is not None and math.degrees(cal.tilt) == pytest.approx(tilt_deg, abs=0.05)
    assert cal.end == pytest.approx(end, abs=1e-4)
    assert cal.z_face == pytest.approx(0.05 - rise, abs=5e-6)


@pytest.mark.parametrize("tilt_deg", [2.0, -1.3, 3.71, 0.0])
def test_the_rock_fit_recovers_the_tilt_and_the_face(tilt_deg: float) -> None:
    """Exact heights: the tilt to 0.05 degrees, and to a tenth of the grid's 0.029-degree step
    (the parabola through the best three refines it); the face's height to 5 um (it is read at
    the best grid point, not at the refined tilt); the axis in the hand to the tilt's accuracy."""
    z_face = 0.05
    cal = _calibration(math.radians(tilt_deg), z_face, np.zeros(3))
    cal._fit()
    assert cal.tilt is not None
    assert math.degrees(cal.tilt) == pytest.approx(tilt_deg, abs=0.05)
    step = float(cal._thetas[1] - cal._thetas[0])
    assert abs(cal.tilt - math.radians(tilt_deg)) < 0.1 * step
    assert cal.z_face == pytest.approx(z_face, abs=5e-6)
    up_true = Rotation.from_rotvec(math.radians(tilt_deg) * np.array([1.0, 0.0, 0.0])).apply(UP_BODY)
    assert np.linalg.norm(cal.axis_body) == pytest.approx(1.0, abs=1e-12)
    assert math.degrees(math.acos(min(1.0, float(cal.axis_body @ up_true)))) < 0.05


def test_the_rock_fit_tolerates_micrometre_noise_on_the_heights() -> None:
    """Landing heights off by 2 um each (the chamfer's depth sigma is 15 um): the tilt of 2 degrees
    still to 0.05 degrees."""
    cal = _calibration(math.radians(2.0), 0.05, np.array([2e-6, -2e-6, 1e-6]))
    cal._fit()
    assert cal.tilt is not None and math.degrees(cal.tilt) == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("tilt_deg", [2.0, -2.0, 0.0])
def test_an_offset_in_the_hand_reads_as_tilt_unless_the_end_is_known(tilt_deg: float) -> None:
    """3 mm along the pads' plane: turning the hand about the pads' normal lifts or lowers the end
    by 3 mm x sin(angle), as a tilt would; the fit is off by more than half a degree (a peg 0.5
    degrees off its bore wedges within 12 mm at 0.05 mm of clearance). With
    the end located first (its believed position the true one), the rim alone fixes the tilt."""
    tilt = math.radians(tilt_deg)
    for offset in (0.003, -0.003):
        blind = _calibration(tilt, 0.05, np.zeros(3), offset=offset)
        blind._fit()
        assert blind.tilt is not None and abs(math.degrees(blind.tilt) - tilt_deg) > 0.5
        known = _calibration(tilt, 0.05, np.zeros(3), offset=offset, end_known=True)
        known._fit()
        assert known.tilt is not None and math.degrees(known.tilt) == pytest.approx(tilt_deg, abs=0.05)
        assert known.z_face == pytest.approx(0.05, abs=5e-6)
