"""Physics profiles: what ``seed`` and ``precision`` put into the compiled model, the hole's
roundness measured on the generated collision meshes, and the checks on conflicting settings."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.errors import ConfigError
from peg_ctrl.run.episode import EpisodeConfig
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.physics import MIN_HOLE_SIDES, PRECISION, PhysicsConfig, parts_for_play
from peg_ctrl.sim.scene import SceneConfig, build_model, check_scene

PEG_RADIUS = 0.010  # [m], AssetParams default
PEG_HALF_LENGTH = 0.05  # [m], half the default 0.1 m peg
CLEARANCE = 0.0001  # [m], the precision model's clearance in this file
PLAY_TOLERANCE = 5e-6  # [m], the precision profile's tolerance on a round peg's play
F32 = 1e-7  # [m], slack for float32 mesh vertices
SOLIMP = [0.9, 0.95, 0.001, 0.5, 2.0]


@pytest.fixture(scope="module")
def precision_cfg() -> SceneConfig:
    return SceneConfig(assets=AssetParams(clearance=CLEARANCE))


@pytest.fixture(scope="module")
def precision_model(precision_cfg: SceneConfig) -> mujoco.MjModel:
    return build_model(precision_cfg, "precision")


def _part_ids(model: mujoco.MjModel) -> list[int]:
    return [g for g in range(model.ngeom) if model.geom(g).name.startswith("object_")]


def _hole_sides(model: mujoco.MjModel) -> int:
    """The precision block's parts around the hole: all its parts but the ring's four slabs."""
    return len(_part_ids(model)) - 4


def _hole_corners(model: mujoco.MjModel, cfg: SceneConfig, r_max: float) -> list[np.ndarray]:
    """Per block part, the xy [m] (relative to the hole axis) of its mesh vertices closer than
    ``r_max`` to the axis. MuJoCo recentres meshes, so vertices go through the geom's pose."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    block = data.body("block").xpos.copy()
    np.testing.assert_allclose(block[:2], cfg.hole_xy, atol=1e-12)
    corners = []
    for g in _part_ids(model):
        mesh = model.geom_dataid[g]
        start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        local = model.mesh_vert[start : start + count].astype(float)
        world = data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T
        xy = world[:, :2] - np.asarray(cfg.hole_xy)
        corners.append(xy[np.hypot(xy[:, 0], xy[:, 1]) < r_max])
    return corners


def _flat_distance(corners: np.ndarray) -> float:
    """Distance from the axis to the midpoint of a part's hole edge (its two farthest corners)."""
    d = np.linalg.norm(corners[:, None, :] - corners[None, :, :], axis=-1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return float(np.linalg.norm(0.5 * (corners[i] + corners[j])))


# --- seed --------------------------------------------------------------------------------------


# The seed's solver options are asserted in tests/sim/test_scene.py::test_physics_options.


def test_seed_profile_keeps_the_spec_contact_model(model: mujoco.MjModel) -> None:
    parts = _part_ids(model)
    assert [model.geom(g).name for g in parts] == [f"object_{i:02d}" for i in range(1, 11)]
    for g in parts:
        assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        assert model.geom_margin[g] == pytest.approx(0.001, abs=1e-15)
        np.testing.assert_array_equal(model.geom_solref[g], [0.01, 1.0])
        np.testing.assert_allclose(model.geom_solimp[g], SOLIMP, rtol=0, atol=1e-15)
    assert model.geom_type[model.geom("peg").id] == mujoco.mjtGeom.mjGEOM_MESH
    assert model.npair == 0


def test_seed_hole_is_a_decagon_whose_corners_stand_out(model: mujoco.MjModel) -> None:
    cfg = SceneConfig()
    corners = _hole_corners(model, cfg, r_max=0.015)
    assert [len(c) for c in corners] == [4] * 10  # two corners, top and bottom, per part
    flats = np.array([_flat_distance(c) for c in corners])
    # Flats at peg radius + clearance + the 1 mm margin.
    np.testing.assert_allclose(flats, cfg.assets.hole_inradius, rtol=0, atol=F32)
    radii = np.hypot(*np.vstack(corners).T)
    assert radii.min() - flats.max() > 0.4e-3  # 0.62 mm: the decagon is far from round
    np.testing.assert_allclose(radii, 0.012 / math.cos(math.pi / 10), rtol=0, atol=F32)


# --- precision ---------------------------------------------------------------------------------


def test_precision_solver_options(precision_model: mujoco.MjModel) -> None:
    opt = precision_model.opt
    assert opt.timestep == 0.0005
    assert opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert opt.solver == mujoco.mjtSolver.mjSOL_NEWTON
    assert opt.tolerance == 1e-10


def test_precision_peg_is_a_primitive_cylinder(precision_model: mujoco.MjModel) -> None:
    g = precision_model.geom("peg").id
    assert precision_model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER
    assert precision_model.geom_size[g][0] == pytest.approx(PEG_RADIUS, abs=1e-15)
    assert precision_model.geom_size[g][1] == pytest.approx(PEG_HALF_LENGTH, abs=1e-15)


def test_precision_has_one_stiff_sliding_pair_per_block_part(precision_model: mujoco.MjModel) -> None:
    m = precision_model
    parts = _part_ids(m)
    # 0.1 mm of play and no chamfer: the fewest sides allowed
    assert _hole_sides(m) == parts_for_play(CLEARANCE, PLAY_TOLERANCE) == MIN_HOLE_SIDES
    np.testing.assert_array_equal(m.geom_margin[parts], 0.0)
    assert m.npair == len(parts) + 1  # and the table
    peg = m.geom("peg").id
    pairs = [{int(a), int(b)} for a, b in zip(m.pair_geom1, m.pair_geom2, strict=True)]
    assert all(peg in pair for pair in pairs)  # MuJoCo may store either geom first
    assert sorted(next(iter(pair - {peg})) for pair in pairs) == sorted([*parts, m.geom("table").id])
    np.testing.assert_array_equal(m.pair_dim, 3)
    np.testing.assert_array_equal(m.pair_margin, 0.0)
    np.testing.assert_array_equal(m.pair_solref, np.tile([0.001, 1.0], (m.npair, 1)))
    # MuJoCo clamps a time constant below two steps; the profile's must not rely on that.
    assert np.all(m.pair_solref[:, 0] >= 2 * m.opt.timestep)


def test_precision_hole_lets_a_round_peg_move_as_in_a_round_hole(
    precision_model: mujoco.MjModel, precision_cfg: SceneConfig
) -> None:
    r_nom = PEG_RADIUS + CLEARANCE
    n = _hole_sides(precision_model)
    corners = _hole_corners(precision_model, precision_cfg, r_max=0.0105)
    assert [len(c) for c in corners[:n]] == [4] * n
    assert all(len(c) == 0 for c in corners[n:])  # the slabs stay away from the hole
    flats = np.array([_flat_distance(c) for c in corners[:n]])
    np.testing.assert_allclose(flats, r_nom, rtol=0, atol=F32)  # no margin widens the hole
    # A regular n-gon: every corner at flat / cos(pi / n).
    radii = np.hypot(*np.vstack(corners[:n]).T)
    np.testing.assert_allclose(radii, r_nom / math.cos(math.pi / n), rtol=0, atol=F32)
    # The peg's axis is free in that polygon shrunk by the peg's radius (inradius: the
    # clearance), whose corners stand within the tolerance beyond the clearance's circle.
    play = flats.mean() - PEG_RADIUS
    assert play * (1.0 / math.cos(math.pi / n) - 1.0) <= PLAY_TOLERANCE


@pytest.mark.parametrize("clearance, chamfer", [(5e-5, 1e-3), (2.5e-5, 1e-3), (1e-3, 0.0)])
def test_precision_sides_follow_the_play_with_the_chamfer(clearance: float, chamfer: float) -> None:
    params = PRECISION.assets(AssetParams(clearance=clearance, chamfer=chamfer))
    play = clearance + chamfer
    n = params.n_parts
    assert n == parts_for_play(play, PLAY_TOLERANCE) > MIN_HOLE_SIDES
    assert play * (1.0 / math.cos(math.pi / n) - 1.0) <= PLAY_TOLERANCE
    assert play * (1.0 / math.cos(math.pi / (n - 1)) - 1.0) > PLAY_TOLERANCE
    # the ring ends 3 mm outside the mouth; four slabs make the rest of the block
    mouth = params.hole_circumradius + chamfer / math.cos(math.pi / n)
    assert params.hole_ring == pytest.approx(mouth + 0.003, abs=1e-15)
    assert params.part_count == n + 4


def test_parts_for_play_rejects_bad_values() -> None:
    with pytest.raises(ConfigError, match="tolerance"):
        parts_for_play(1e-3, 0.0)
    with pytest.raises(ConfigError, match="play"):
        parts_for_play(float("nan"), 1e-6)
    assert parts_for_play(0.0, 1e-6) == MIN_HOLE_SIDES


# --- configuration checks ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "assets, field",
    [
        (AssetParams(n_parts=12), "scene.assets.n_parts"),
        (AssetParams(contact_margin=0.002), "scene.assets.contact_margin"),
        (AssetParams(hole_ring=0.02), "scene.assets.hole_ring"),
    ],
)
def test_precision_rejects_asset_fields_it_sets_itself(assets: AssetParams, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        EpisodeConfig(physics=PhysicsConfig("precision"), scene=SceneConfig(assets=assets))
    with pytest.raises(ConfigError, match=field):
        check_scene("precision", SceneConfig(assets=assets))
    # The seed profile takes them.
    cfg = EpisodeConfig(physics=PhysicsConfig("seed"), scene=SceneConfig(assets=assets))
    assert cfg.scene.assets == assets


def test_precision_rejects_the_contact_override() -> None:
    """MuJoCo's override flag would replace the precision pairs' parameters with o_solref/o_solimp."""
    with pytest.raises(ConfigError, match=r"^scene\.contact_override: "):
        EpisodeConfig(physics=PhysicsConfig("precision"), scene=SceneConfig(contact_override=True))
    assert EpisodeConfig(scene=SceneConfig(contact_override=True)).scene.contact_override


def test_episode_and_experiment_configs_round_trip_with_physics() -> None:
    import json

    from peg_ctrl.config import load, to_dict
    from peg_ctrl.experiments.config import expand, experiment_from_mapping

    cfg = EpisodeConfig(physics=PhysicsConfig("precision"), max_steps=None)
    again = load(EpisodeConfig, json.loads(json.dumps(to_dict(cfg))))
    assert again == cfg and again.max_steps is None and again.physics.profile == "precision"
    data = {"controllers": ["pd"], "seeds": 2, "physics": {"profile": "precision"}}
    exp = experiment_from_mapping(data)
    assert experiment_from_mapping(json.loads(json.dumps(to_dict(exp)))) == exp
    jobs = expand(exp)
    assert [j.key for j in jobs] == [j.key for j in expand(experiment_from_mapping(data))]  # stable keys
    assert all(j.config.physics.profile == "precision" for j in jobs)
    seed_keys = {j.key for j in expand(experiment_from_mapping({"controllers": ["pd"], "seeds": 2}))}
    assert seed_keys.isdisjoint(j.key for j in jobs)  # the profile is part of an episode's identity


def test_unknown_profile_lists_the_known() -> None:
    with pytest.raises(ConfigError, match="precision, seed") as exc:
        check_scene("precise", SceneConfig())
    assert "'precise'" in str(exc.value)
    with pytest.raises(ConfigError, match=r"^physics\.profile: .*precision, seed"):
        PhysicsConfig("nope")


def test_negative_clearance_is_an_interference_fit_within_a_bound() -> None:
    fit = AssetParams(clearance=-2e-5)
    assert fit.hole_inradius == pytest.approx(PEG_RADIUS - 2e-5 + 0.001, abs=1e-15)
    # The precision profile drops the margin: the hole is smaller than the peg.
    assert PRECISION.assets(fit).hole_inradius == pytest.approx(PEG_RADIUS - 2e-5, abs=1e-15)
    for bad in (-0.002, -0.001):  # the bound is -0.1 x peg_radius, exclusive
        with pytest.raises(ValueError, match=r"clearance must be > -0\.001 m"):
            AssetParams(clearance=bad)


def test_step_limit_is_20_s_of_simulated_time_unless_given() -> None:
    assert EpisodeConfig().step_limit(0.001) == 20000
    assert EpisodeConfig().step_limit(0.0005) == 40000
    assert EpisodeConfig(max_steps=123).step_limit(0.0005) == 123
    assert EpisodeConfig(max_steps=123).step_limit(0.001) == 123


def test_precision_pair_friction_follows_the_scene() -> None:
    """The pairs take the larger sliding coefficient of the scene's peg and block (MuJoCo's own
    mixing rule), so ``scene.block_friction`` still acts in the precision profile."""
    cfg = SceneConfig(peg_friction=(0.3, 0.1, 1e-4), block_friction=(0.5, 0.1, 1e-4))
    model = build_model(cfg, "precision")
    table = model.pair("peg-table").id
    block = [i for i in range(model.npair) if i != table]
    np.testing.assert_array_equal(
        model.pair_friction[block], np.tile([0.5, 0.5, 0.0, 0.0, 0.0], (len(block), 1))
    )
    np.testing.assert_array_equal(model.pair_friction[table], [1.0, 1.0, 0.0, 0.0, 0.0])  # the table's 1.0


def test_domain_friction_scale_reaches_the_precision_pairs() -> None:
    from peg_ctrl.run.episode import DomainConfig, domain_draw, prepare_model

    cfg = EpisodeConfig(physics=PhysicsConfig("precision"), domain=DomainConfig(friction_scale=(1.5, 1.5)))
    model = prepare_model(cfg, domain_draw(cfg.seed, cfg.domain))
    table = model.pair("peg-table").id
    block = [i for i in range(model.npair) if i != table]
    np.testing.assert_allclose(model.pair_friction[block, :2], 1.35)
    np.testing.assert_array_equal(model.pair_friction[:, 2:], 0.0)
    np.testing.assert_array_equal(model.pair_friction[table, :2], 1.0)  # the table is not the domain's


def test_friction_time_sets_the_peg_pairs_friction_reference(precision_cfg: SceneConfig) -> None:
    """``physics.friction_time`` gives every peg pair (block parts and table) its own friction
    reference, critically damped, and leaves the normal's; unset, the friction rows take the
    normal's (MuJoCo's 0, 0)."""
    slow = build_model(precision_cfg, PhysicsConfig("precision", friction_time=0.005).resolved())
    assert slow.npair == _hole_sides(slow) + 4 + 1  # every block part, and the table
    np.testing.assert_array_equal(slow.pair_solreffriction, np.tile([0.005, 1.0], (slow.npair, 1)))
    np.testing.assert_array_equal(slow.pair_solref, np.tile([0.001, 1.0], (slow.npair, 1)))
    plain = build_model(precision_cfg, PhysicsConfig("precision").resolved())
    np.testing.assert_array_equal(plain.pair_solreffriction, np.zeros((plain.npair, 2)))
    assert PhysicsConfig("precision").resolved() is PRECISION


@pytest.mark.parametrize(
    ("profile_name", "value", "message"),
    [
        ("seed", 0.005, r"^physics\.friction_time: physics\.profile=seed has no explicit peg contact pairs"),
        ("precision", 0.0005, r"^physics\.friction_time must be .* \(>= 0\.001 s\), got 0\.0005$"),
        ("precision", math.inf, r"^physics\.friction_time must be .*, got inf$"),
        ("precision", True, r"^physics\.friction_time must be .*, got True$"),
    ],
)
def test_friction_time_refuses_what_it_cannot_set(profile_name: str, value: float, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        PhysicsConfig(profile_name, friction_time=value)
