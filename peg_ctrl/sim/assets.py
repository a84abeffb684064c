"""Parametric peg and block-with-hole meshes, generated reproducibly.

The block is a rectangular prism with a vertical through-hole. The hole is a regular
``n_parts``-gon whose *inradius* is ``peg_radius + clearance + contact_margin``. The block's
collision geoms carry a contact margin (SPEC: 1 mm), and MuJoCo makes a contact active once the
surfaces are closer than the margin, so the margin is added to the geometry: the *effective*
radial clearance at the flats, where contact forces start, is exactly ``clearance`` (more at the
corners). The solid around it is split into
``n_parts`` convex prisms, one per polygon edge: part ``i`` is bounded by edge ``i`` of the
hole polygon, the two rays from the hole axis through that edge's end points, and the outer
walls of the block. These parts tile the block exactly and never overlap the hole.

With ``hole_ring`` set, the parts stop at a square of that half-width around the hole and the
rest of the block is four slabs (the seed's parts run to the block's walls). A part's
collision cost grows with its size near the peg, and a peg resting on the face away from the
hole then touches one slab instead of a fan of parts.

An optional chamfer widens the hole mouth: the top ``chamfer`` metres of each inner face are
cut by a plane at 45 degrees, which keeps every part convex (a convex prism intersected with a
half-space).

The peg is a cylinder approximated by an ``n_segments``-gon prism whose vertices lie on the
nominal radius, so its convex hull never exceeds ``peg_radius``.

Meshes are written as binary STL in metres with a fixed header, so the same parameters give
byte-identical files.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import OutputError
from peg_ctrl.io import to_json

__all__ = [
    "AssetParams",
    "Mesh",
    "block_parts",
    "block_visual",
    "peg_mesh",
    "write_stl",
    "write_assets",
    "reference_assets_dir",
    "cache_dir",
    "ensure_assets",
]

_STL_HEADER = b"peg_ctrl generated mesh".ljust(80, b"\0")
# Bump when the generator's output changes for the same parameters, so old cached sets are not reused.
_CACHE_FORMAT = 1


@dataclasses.dataclass(frozen=True)
class AssetParams:
    """Geometry of the peg and the block. All lengths in [m]."""

    peg_radius: float = 0.010
    peg_length: float = 0.100
    clearance: float = 0.001  # radial clearance at the hole flats [m]; negative: interference
    block_size: tuple[float, float, float] = (0.080, 0.080, 0.050)  # full extents x, y, z [m]
    n_parts: int = 10  # convex collision parts around the hole (and hole polygon sides)
    chamfer: float = 0.0  # depth and width of the 45-degree chamfer at the hole mouth [m]
    contact_margin: float = 0.001  # contact margin of the block geoms, added to the hole [m]
    peg_segments: int = 32  # sides of the polygonal peg cross-section
    # Half-width of the square around the hole axis at which the hole's parts end; beyond it
    # the block is four slabs. None: the parts reach the block's walls (SPEC).
    hole_ring: float | None = None

    def __post_init__(self) -> None:
        _check_positive("peg_radius", self.peg_radius)
        _check_positive("peg_length", self.peg_length)
        # A negative clearance is an interference fit (validity studies); beyond a tenth of the
        # radius it is no longer a fit at all.
        if not (np.isfinite(self.clearance) and self.clearance > -0.1 * self.peg_radius):
            raise ValueError(
                f"clearance must be > -{0.1 * self.peg_radius:g} m (-0.1 x peg_radius; negative is "
                f"an interference fit), got {self.clearance!r}"
            )
        if not (np.isfinite(self.contact_margin) and self.contact_margin >= 0.0):
            raise ValueError(f"contact_margin must be >= 0 m, got {self.contact_margin!r}")
        if len(self.block_size) != 3:
            raise ValueError(f"block_size must have 3 entries (x, y, z), got {self.block_size!r}")
        for axis, value in zip("xyz", self.block_size, strict=True):
            _check_positive(f"block_size.{axis}", value)
        if not (isinstance(self.n_parts, int) and self.n_parts >= 4):
            raise ValueError(f"n_parts must be an integer >= 4, got {self.n_parts!r}")
        if not (isinstance(self.peg_segments, int) and self.peg_segments >= 8):
            raise ValueError(f"peg_segments must be an integer >= 8, got {self.peg_segments!r}")
        if not (np.isfinite(self.chamfer) and 0.0 <= self.chamfer < self.block_size[2]):
            raise ValueError(
                f"chamfer must be in [0, block height {self.block_size[2]}) m, got {self.chamfer!r}"
            )
        hole_outer = self.hole_circumradius + self.chamfer / np.cos(np.pi / self.n_parts)
        half_min = 0.5 * min(self.block_size[0], self.block_size[1])
        if hole_outer >= 0.8 * half_min:
            raise ValueError(
                f"hole (circumradius {hole_outer:.4f} m incl. chamfer) does not fit in the block "
                f"(half width {half_min:.4f} m); enlarge block_size or shrink peg_radius/clearance"
            )
        ring = self.hole_ring
        if ring is not None and not (np.isfinite(ring) and hole_outer < ring < half_min):
            raise ValueError(
                f"hole_ring must be between the hole's mouth ({hole_outer:.4f} m) and the block's "
                f"half width ({half_min:.4f} m), got {ring!r}"
            )

    @property
    def hole_inradius(self) -> float:
        """Distance from the hole axis to the hole's flat faces (geometric, incl. margin) [m]."""
        return self.peg_radius + self.clearance + self.contact_margin

    @property
    def hole_circumradius(self) -> float:
        """Distance from the hole axis to the hole polygon's corners [m]."""
        return self.hole_inradius / float(np.cos(np.pi / self.n_parts))

    @property
    def part_count(self) -> int:
        """Collision parts of the block: one per hole side, and four slabs with a ``hole_ring``."""
        return self.n_parts + (4 if self.hole_ring is not None else 0)

    def fields(self) -> dict[str, object]:
        """The parameters as a mapping; an unset ``hole_ring`` is left out, so the seed's asset
        sets (and their keys) are those from before the ring existed."""
        out = dataclasses.asdict(self)
        if out["hole_ring"] is None:
            del out["hole_ring"]
        return out

    def key(self) -> str:
        """A short stable hash of the parameters, used to name cached asset sets."""
        blob = json.dumps(self.fields(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:12]


def _check_positive(name: str, value: float) -> None:
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite positive length in m, got {value!r}")


@dataclasses.dataclass(frozen=True)
class Mesh:
    """A triangle mesh: ``vertices`` (n, 3) in [m], ``faces`` (k, 3) vertex indices, CCW outward."""

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]

    def volume(self) -> float:
        """Signed volume [m^3]; positive for a closed mesh with outward normals."""
        v = self.vertices[self.faces]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def _prism(polygon: NDArray[np.float64], z0: float, z1: float) -> Mesh:
    """Extrude a CCW convex polygon (m, 2) from ``z0`` to ``z1``."""
    m = len(polygon)
    bottom = np.column_stack([polygon, np.full(m, z0)])
    top = np.column_stack([polygon, np.full(m, z1)])
    vertices = np.vstack([bottom, top])
    faces: list[tuple[int, int, int]] = []
    for k in range(1, m - 1):
        faces.append((0, k + 1, k))  # bottom, facing -z
        faces.append((m, m + k, m + k + 1))  # top, facing +z
    for k in range(m):
        n = (k + 1) % m
        faces.append((k, n, m + n))
        faces.append((k, m + n, m + k))
    return Mesh(vertices, np.asarray(faces, dtype=np.int64))


def peg_mesh(params: AssetParams) -> Mesh:
    """The peg: a polygonal cylinder along local +z, centred at the origin."""
    angles = 2.0 * np.pi * np.arange(params.peg_segments) / params.peg_segments
    circle = params.peg_radius * np.column_stack([np.cos(angles), np.sin(angles)])
    half = 0.5 * params.peg_length
    return _prism(circle, -half, half)


def _ray_to_box(direction: NDArray[np.float64], half_x: float, half_y: float) -> float:
    """Distance along a unit 2-D ray from the origin to the rectangle [-hx, hx] x [-hy, hy]."""
    with np.errstate(divide="ignore"):
        tx = half_x / abs(direction[0]) if direction[0] != 0 else np.inf
        ty = half_y / abs(direction[1]) if direction[1] != 0 else np.inf
    return float(min(tx, ty))


def _part_outline(params: AssetParams, i: int) -> tuple[NDArray[np.float64], int]:
    """CCW outline (m, 2) of part ``i`` in the block's xy-plane; the first two points are the hole edge.

    Returns the outline and the number of points (2) that lie on the hole polygon.
    """
    n = params.n_parts
    if params.hole_ring is None:
        hx, hy = 0.5 * params.block_size[0], 0.5 * params.block_size[1]
    else:
        hx = hy = params.hole_ring
    a0 = 2.0 * np.pi * i / n
    a1 = 2.0 * np.pi * (i + 1) / n
    d0 = np.array([np.cos(a0), np.sin(a0)])
    d1 = np.array([np.cos(a1), np.sin(a1)])
    rc = params.hole_circumradius
    outline = [rc * d0, rc * d1, _ray_to_box(d1, hx, hy) * d1]
    # Block corners strictly inside the angular sector, walked clockwise (back from a1 to a0).
    corners = [np.array(c) for c in ((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy))]
    inside = []
    for c in corners:
        ang = np.arctan2(c[1], c[0]) % (2.0 * np.pi)
        if a0 < ang < a1:
            inside.append((ang, c))
    for _, c in sorted(inside, key=lambda t: -t[0]):
        outline.append(c)
    outline.append(_ray_to_box(d0, hx, hy) * d0)
    # Walking inner edge a0 -> a1 then out and back is clockwise seen from +z; reverse to CCW.
    return np.asarray(outline[::-1], dtype=np.float64), 2


def block_parts(params: AssetParams) -> list[Mesh]:
    """The block's convex collision parts (:attr:`AssetParams.part_count`), in the block frame
    (origin at the block centre): the ``n_parts`` around the hole, then the slabs of a
    ``hole_ring``."""
    hz = 0.5 * params.block_size[2]
    parts = _hole_parts(params, hz)
    if params.hole_ring is not None:
        parts.extend(_prism(outline, -hz, hz) for outline in _slab_outlines(params))
    return parts


def _slab_outlines(params: AssetParams) -> list[NDArray[np.float64]]:
    """CCW outlines of the four slabs between the ring's square and the block's walls: two
    across the whole block in x (the y > a and y < -a sides), two between them."""
    assert params.hole_ring is not None
    a = params.hole_ring
    hx, hy = 0.5 * params.block_size[0], 0.5 * params.block_size[1]
    boxes = ((-hx, a, hx, hy), (-hx, -hy, hx, -a), (a, -a, hx, a), (-hx, -a, -a, a))
    return [np.array([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], dtype=np.float64) for x0, y0, x1, y1 in boxes]


def _hole_parts(params: AssetParams, hz: float) -> list[Mesh]:
    """The ``n_parts`` parts around the hole, each bounded by one side of the hole polygon."""
    parts = []
    for i in range(params.n_parts):
        outline, _ = _part_outline(params, i)
        if params.chamfer <= 0.0:
            parts.append(_prism(outline, -hz, hz))
            continue
        # Chamfer: the two hole-edge vertices (the last two of the CCW outline) are pushed
        # outward along their rays at the top face and an extra ring of vertices sits at depth
        # `chamfer`. The convex hull of these vertices is the chamfered part.
        prism = _prism(outline, -hz, hz)
        m = len(outline)
        verts = [*prism.vertices]
        scale = params.chamfer / np.cos(np.pi / params.n_parts)
        for k in (m - 2, m - 1):
            p = outline[k]
            radial = p / np.linalg.norm(p)
            verts[m + k] = np.array([*(p + scale * radial), hz])
            verts.append(np.array([*p, hz - params.chamfer]))
        parts.append(_convex_hull_mesh(np.asarray(verts)))
    return parts


def _convex_hull_mesh(points: NDArray[np.float64]) -> Mesh:
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    faces = hull.simplices.copy()
    centre = points[hull.vertices].mean(axis=0)
    for f_idx, (a, b, c) in enumerate(faces):
        normal = np.cross(points[b] - points[a], points[c] - points[a])
        if np.dot(normal, points[a] - centre) < 0.0:
            faces[f_idx] = (a, c, b)
    return Mesh(points.astype(np.float64), faces.astype(np.int64))


def block_visual(params: AssetParams) -> Mesh:
    """A single watertight visual mesh of the block with its hole (union of the parts' outer faces).

    Faces shared by two parts (the radial cuts) are dropped, so the result is closed.
    """
    all_vertices: list[NDArray[np.float64]] = []
    all_faces: list[NDArray[np.int64]] = []
    offset = 0
    for part in block_parts(params):
        all_vertices.append(part.vertices)
        all_faces.append(part.faces + offset)
        offset += len(part.vertices)
    vertices = np.vstack(all_vertices)
    faces = np.vstack(all_faces)
    # Merge coincident vertices so shared faces can be recognised.
    keys = np.round(vertices / 1e-9).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    remap = np.empty_like(order)
    remap[order] = np.arange(len(order))
    vertices = vertices[first[order]]
    faces = remap[inverse.reshape(-1)][faces]
    # A radial cut is split into triangles differently by its two parts, so detect internal
    # faces geometrically: a triangle whose centroid lies on a cut plane strictly inside the block.
    keep = np.ones(len(faces), dtype=bool)
    hz = 0.5 * params.block_size[2]
    hx, hy = 0.5 * params.block_size[0], 0.5 * params.block_size[1]
    for f_idx, tri in enumerate(faces):
        pts = vertices[tri]
        centroid = pts.mean(axis=0)
        normal = np.cross(pts[1] - pts[0], pts[2] - pts[0])
        norm = np.linalg.norm(normal)
        if norm == 0.0:
            keep[f_idx] = False
            continue
        normal /= norm
        on_outer = (
            abs(abs(centroid[0]) - hx) < 1e-9
            or abs(abs(centroid[1]) - hy) < 1e-9
            or abs(abs(centroid[2]) - hz) < 1e-9
        )
        # Radial cut planes contain the z-axis: their normal is horizontal and perpendicular
        # to the centroid's horizontal direction. With a ring, the square between the hole's
        # parts and the slabs is a cut too.
        radial_dir = centroid[:2] / max(np.linalg.norm(centroid[:2]), 1e-12)
        is_cut = abs(normal[2]) < 1e-9 and abs(np.dot(normal[:2], radial_dir)) < 1e-9
        if params.hole_ring is not None and abs(normal[2]) < 1e-9:
            a = params.hole_ring
            on_square = (abs(abs(centroid[0]) - a) < 1e-9 and abs(centroid[1]) <= a + 1e-9) or (
                abs(abs(centroid[1]) - a) < 1e-9 and abs(centroid[0]) <= hx + 1e-9
            )
            is_cut = is_cut or on_square
        if is_cut and not on_outer:
            keep[f_idx] = False
    faces = faces[keep]
    used = np.unique(faces)
    remap_used = -np.ones(len(vertices), dtype=np.int64)
    remap_used[used] = np.arange(len(used))
    return Mesh(vertices[used], remap_used[faces])


def write_stl(mesh: Mesh, path: Path) -> None:
    """Write ``mesh`` as binary STL (float32, fixed header) so identical meshes give identical bytes."""
    v = mesh.vertices[mesh.faces].astype(np.float32)
    normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(lengths > 0, normals / np.maximum(lengths, 1e-30), 0.0).astype(np.float32)
    record = np.zeros(
        len(v),
        dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")],
    )
    record["n"] = normals
    record["v"] = v
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(_STL_HEADER)
        fh.write(struct.pack("<I", len(v)))
        fh.write(record.tobytes())


def part_name(i: int) -> str:
    """Name of collision part ``i`` (0-based): ``object_01`` .. ``object_NN``."""
    return f"object_{i + 1:02d}"


def write_assets(params: AssetParams, directory: Path) -> dict[str, Path]:
    """Write ``peg.stl``, ``block_visual.stl`` and ``object_XX.stl`` plus ``params.json`` to ``directory``.

    Returns a mapping from mesh name to file path.
    """
    directory.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    files["peg"] = directory / "peg.stl"
    write_stl(peg_mesh(params), files["peg"])
    files["block_visual"] = directory / "block_visual.stl"
    write_stl(block_visual(params), files["block_visual"])
    for i, part in enumerate(block_parts(params)):
        name = part_name(i)
        files[name] = directory / f"{name}.stl"
        write_stl(part, files[name])
    meta = directory / "params.json"
    meta.write_text(_params_json(params))  # in a staging directory, published by a rename
    return files


def reference_assets_dir() -> Path:
    """The committed reference copy of the default set (``assets/default`` in a source checkout).

    Only the tests read it, to check the generator byte for byte; an installed package does not
    contain it, and the simulator never reads or writes it (see :func:`ensure_assets`).
    """
    return Path(__file__).resolve().parents[2] / "assets" / "default"


def cache_dir() -> Path:
    """Where generated asset sets live: ``$PEG_CTRL_CACHE/assets``, else
    ``$XDG_CACHE_HOME/peg_ctrl/assets``, else ``~/.cache/peg_ctrl/assets``."""
    base = os.environ.get("PEG_CTRL_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "peg_ctrl"
    )
    return Path(base) / "assets"


def _mesh_names(params: AssetParams) -> list[str]:
    return ["peg", "block_visual", *(part_name(i) for i in range(params.part_count))]


def _params_json(params: AssetParams) -> str:
    return to_json(params.fields(), indent=2, sort_keys=True) + "\n"


def _is_complete(directory: Path, params: AssetParams) -> bool:
    meta = directory / "params.json"
    try:
        if meta.read_text() != _params_json(params):
            return False
    except (OSError, UnicodeDecodeError):
        return False
    return all((directory / f"{name}.stl").is_file() for name in _mesh_names(params))


def ensure_assets(params: AssetParams) -> dict[str, Path]:
    """Mesh files for ``params``, generated once into the user cache (:func:`cache_dir`).

    A set lives in ``cache_dir()/v<format>-<params.key()>``. It is written into a temporary
    directory beside it and renamed into place, so concurrent processes (sweep workers) never
    see a partial set: the first rename wins and the others use the winner's identical files.
    Nothing is ever written inside the installed package.

    Raises:
        OutputError: the cache directory cannot be created or written (set ``PEG_CTRL_CACHE``).
    """
    directory = cache_dir() / f"v{_CACHE_FORMAT}-{params.key()}"
    files = {name: directory / f"{name}.stl" for name in _mesh_names(params)}
    if _is_complete(directory, params):
        return files
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", dir=directory.parent))
        try:
            write_assets(params, staging)
            _publish(staging, directory, params)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    except OSError as exc:
        raise OutputError(
            f"cannot write the generated meshes to the cache {str(directory.parent)!r}: "
            f"{exc.strerror or exc}; set PEG_CTRL_CACHE to a writable directory"
        ) from None
    return files


def _publish(staging: Path, directory: Path, params: AssetParams) -> None:
    """Rename ``staging`` to ``directory`` atomically unless a complete set is already there."""
    for _ in range(3):
        try:
            os.rename(staging, directory)
            return
        except OSError:
            # The target exists: another process won the race, or an old incomplete set is there.
            if _is_complete(directory, params):
                return
        # Move the incomplete set aside (atomic), then retry; delete it afterwards.
        trash = Path(tempfile.mkdtemp(prefix=f".{directory.name}.stale.", dir=directory.parent))
        try:
            os.rename(directory, trash / "set")
        except FileNotFoundError:
            pass
        finally:
            shutil.rmtree(trash, ignore_errors=True)
    raise OSError(f"could not place {directory} (changed concurrently)")
