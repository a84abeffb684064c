"""Generated peg and block meshes: reproducible, convex, tiling the block, clearing the hole."""

from __future__ import annotations

import filecmp
import multiprocessing
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay

from peg_ctrl.errors import OutputError
from peg_ctrl.sim.assets import (
    AssetParams,
    block_parts,
    block_visual,
    cache_dir,
    ensure_assets,
    peg_mesh,
    reference_assets_dir,
    write_assets,
)
from peg_ctrl.sim.scene import SceneConfig, build_model

PARAMS = [
    AssetParams(),
    AssetParams(clearance=0.0002, chamfer=0.002),
    AssetParams(n_parts=6, clearance=0.004),
    AssetParams(n_parts=33, clearance=5e-5, chamfer=0.001, contact_margin=0.0, hole_ring=0.0141),
]


def _block_minus_hole_volume(p: AssetParams) -> float:
    sx, sy, sz = p.block_size
    hole_area = p.n_parts * p.hole_inradius**2 * np.tan(np.pi / p.n_parts)
    return sx * sy * sz - hole_area * sz


def test_same_parameters_give_identical_bytes(tmp_path: Path) -> None:
    a = write_assets(AssetParams(), tmp_path / "a")
    b = write_assets(AssetParams(), tmp_path / "b")
    assert a.keys() == b.keys()
    for name in a:
        assert filecmp.cmp(a[name], b[name], shallow=False), name


def test_committed_default_assets_match_the_generator(tmp_path: Path) -> None:
    fresh = write_assets(AssetParams(), tmp_path)
    for _name, path in fresh.items():
        committed = reference_assets_dir() / path.name
        assert filecmp.cmp(path, committed, shallow=False), f"{committed} is stale; regenerate"


@pytest.fixture()
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("PEG_CTRL_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "assets"


def _tree(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def test_ensure_assets_writes_only_into_the_cache(cache: Path) -> None:
    package = Path(__file__).resolve().parents[2] / "peg_ctrl"
    before = _tree(package.parent / "assets"), _tree(package)
    files = ensure_assets(AssetParams())
    assert cache_dir() == cache
    for path in files.values():
        assert path.is_file() and cache in path.parents
        assert filecmp.cmp(path, reference_assets_dir() / path.name, shallow=False)
    assert (_tree(package.parent / "assets"), _tree(package)) == before
    assert ensure_assets(AssetParams()) == files  # the second call reuses the set
    assert [p.name for p in cache.iterdir()] == [files["peg"].parent.name]  # no staging left


def test_cache_location_follows_the_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("PEG_CTRL_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "peg_ctrl" / "assets"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "peg_ctrl" / "assets"


def test_an_incomplete_cached_set_is_replaced(cache: Path) -> None:
    files = ensure_assets(AssetParams(n_parts=6))
    files["object_03"].unlink()
    files["peg"].write_bytes(b"torn")
    again = ensure_assets(AssetParams(n_parts=6))
    assert again == files
    fresh = write_assets(AssetParams(n_parts=6), cache.parent / "check")
    for name, path in again.items():
        assert filecmp.cmp(path, fresh[name], shallow=False), name


def _generate(params: AssetParams) -> dict[str, bytes]:
    return {name: path.read_bytes() for name, path in ensure_assets(params).items()}


def test_concurrent_processes_generate_the_same_set_safely(cache: Path) -> None:
    params = AssetParams(clearance=0.0005)
    ctx = multiprocessing.get_context("spawn")  # the environment (PEG_CTRL_CACHE) is inherited
    with ctx.Pool(4) as pool:
        results = pool.map(_generate, [params] * 8)
    assert all(r == results[0] for r in results)
    fresh = write_assets(params, cache.parent / "check")
    assert results[0] == {name: path.read_bytes() for name, path in fresh.items()}
    assert len(list(cache.iterdir())) == 1, "staging directories were left behind"


def test_an_unwritable_cache_is_one_clear_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("PEG_CTRL_CACHE", str(blocker))
    with pytest.raises(OutputError, match="PEG_CTRL_CACHE"):
        ensure_assets(AssetParams(n_parts=5))
    assert os.listdir(tmp_path) == ["a_file"]


def test_default_has_ten_parts() -> None:
    assert len(block_parts(AssetParams())) == 10


@pytest.mark.parametrize("params", PARAMS, ids=["default", "tight-chamfer", "six-parts", "ring"])
def test_parts_are_convex_and_tile_the_block_without_the_hole(params: AssetParams) -> None:
    parts = block_parts(params)
    assert len(parts) == params.part_count
    for part in parts:
        hull = ConvexHull(part.vertices)
        assert part.volume() == pytest.approx(hull.volume, rel=1e-9)  # convex
    total = sum(part.volume() for part in parts)
    if params.chamfer == 0.0:
        assert total == pytest.approx(_block_minus_hole_volume(params), rel=1e-9)

    # Random points: each lies in at most one part; none in the hole lies in any part.
    rng = np.random.default_rng(0)
    half = 0.5 * np.asarray(params.block_size)
    pts = rng.uniform(-half, half, size=(20000, 3))
    inside = np.stack([Delaunay(part.vertices).find_simplex(pts) >= 0 for part in parts])
    assert inside.sum(axis=0).max() <= 1, "parts overlap"
    radius = np.linalg.norm(pts[:, :2], axis=1)
    in_hole = radius < params.hole_inradius - 1e-9
    assert not inside[:, in_hole].any(), "a part intrudes into the hole"
    solid = radius > params.hole_circumradius + params.chamfer * 2 + 1e-9
    assert inside[:, solid].sum(axis=0).min() == 1, "a gap between parts"


def test_visual_mesh_is_closed_with_the_block_volume() -> None:
    p = AssetParams()
    mesh = block_visual(p)
    assert mesh.volume() == pytest.approx(_block_minus_hole_volume(p), rel=1e-9)
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2), "visual mesh is not watertight"


def test_peg_hull_never_exceeds_the_nominal_radius() -> None:
    p = AssetParams()
    v = peg_mesh(p).vertices
    assert np.linalg.norm(v[:, :2], axis=1).max() == pytest.approx(p.peg_radius, abs=1e-15)
    assert np.ptp(v[:, 2]) == pytest.approx(p.peg_length)


@pytest.mark.parametrize("clearance", [0.001, 0.0002])
def test_measured_clearance_between_peg_and_hole(clearance: float) -> None:
    """Upright peg centred in the hole: the closest block part is `clearance` away (MuJoCo distance)."""
    cfg = SceneConfig(assets=AssetParams(clearance=clearance))
    model = build_model(cfg)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    adr = model.joint("peg_free").qposadr[0]
    hx, hy = cfg.hole_xy
    data.qpos[adr : adr + 7] = [hx, hy, 0.5 * cfg.assets.peg_length + 0.002, 1, 0, 0, 0]
    mujoco.mj_forward(model, data)
    peg = model.geom("peg").id
    parts = [model.geom(f"object_{i + 1:02d}").id for i in range(cfg.assets.n_parts)]
    fromto = np.zeros(6)
    dists = [mujoco.mj_geomDistance(model, data, peg, g, 0.05, fromto) for g in parts]
    margin = cfg.assets.contact_margin
    # Geometric gap = clearance + contact margin; contact forces start at `margin`.
    assert min(dists) - margin == pytest.approx(clearance, abs=2e-6)

    # The peg spans the whole hole depth. Centred, no peg-block contact is active; shifted
    # sideways by more than the clearance, one is.
    def active_block_contacts() -> int:
        return sum(
            1
            for c in data.contact[: data.ncon]
            if c.efc_address >= 0 and {c.geom1, c.geom2} & {peg} and {c.geom1, c.geom2} & set(parts)
        )

    assert active_block_contacts() == 0
    data.qpos[adr] += clearance + 0.0003
    mujoco.mj_forward(model, data)
    assert active_block_contacts() > 0


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"clearance": -0.001}, "clearance"),
        ({"peg_radius": 0.0}, "peg_radius"),
        ({"n_parts": 3}, "n_parts"),
        ({"block_size": (0.025, 0.08, 0.05)}, "hole"),
        ({"chamfer": float("nan")}, "chamfer"),
        ({"hole_ring": 0.011}, "hole_ring"),
        ({"hole_ring": 0.05}, "hole_ring"),
    ],
)
def test_bad_parameters_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        AssetParams(**kwargs)
