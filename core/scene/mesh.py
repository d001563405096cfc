"""Triangle meshes as numpy arrays, and the shading points PRT is computed at.

A mesh arrives as world-space arrays exported from Blender's evaluated
depsgraph (or built by tests):

* ``positions``  (V, 3) vertex positions,
* ``corner_verts`` (C,) vertex index of each face corner,
* ``corner_normals`` (C, 3) shading normal of each corner (split normals),
* ``triangles`` (T, 3) corner indices of each triangle,
* ``corner_materials`` (C,) material slot of each corner's face.

A two-sided mesh (:func:`with_back_sides`) carries its back side as triangles of its own:
the first ``front_triangles`` triangles and ``front_corners`` corners are the mesh's, the
rest copy them reversed with flipped normals, so every method shades the back side as a
surface of its own (Cycles shades a back face with the flipped normal).

Transfer is computed per *shading point*: a distinct (vertex, normal,
material) triple.  A smooth mesh has one point per vertex; a flat-shaded
cube has three per corner vertex.  Points are derived deterministically from
the arrays, so stored per-point results can be re-attached to an unchanged
mesh without storing the mapping, and a changed mesh is detected by its
fingerprint.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np


@dataclass
class MeshArrays:
    positions: np.ndarray
    corner_verts: np.ndarray
    corner_normals: np.ndarray
    triangles: np.ndarray
    corner_materials: np.ndarray | None = None
    #: triangles / corners that are the mesh's own (the rest are back sides); None: all
    front_triangles: int | None = None
    front_corners: int | None = None

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float64).reshape(-1, 3)
        self.corner_verts = np.ascontiguousarray(self.corner_verts, dtype=np.int64).reshape(-1)
        self.corner_normals = np.ascontiguousarray(self.corner_normals, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int64).reshape(-1, 3)
        if self.corner_materials is None:
            self.corner_materials = np.zeros(len(self.corner_verts), dtype=np.int64)
        self.corner_materials = np.ascontiguousarray(self.corner_materials, dtype=np.int64).reshape(-1)
        if self.front_triangles is None:
            self.front_triangles = len(self.triangles)
        if self.front_corners is None:
            self.front_corners = len(self.corner_verts)

    @property
    def two_sided(self) -> bool:
        """Whether the mesh carries its back side (:func:`with_back_sides`)."""
        return self.front_triangles < len(self.triangles)

    @property
    def triangle_positions(self) -> np.ndarray:
        """(T, 3, 3) world positions of every triangle's corners."""
        return self.positions[self.corner_verts[self.triangles]]


def triangle_areas(tri_positions: np.ndarray) -> np.ndarray:
    a, b, c = tri_positions[:, 0], tri_positions[:, 1], tri_positions[:, 2]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def degenerate_triangles(mesh: MeshArrays, scale: float | None = None) -> np.ndarray:
    """Mask of zero-area (or non-finite) triangles, relative to the mesh scale."""
    tp = mesh.triangle_positions
    if scale is None:
        scale = bounding_diagonal(mesh.positions)
    area = triangle_areas(tp)
    return ~np.isfinite(area) | (area <= (1e-12 * max(scale, 1e-30) ** 2))


def occluder_index(mesh: MeshArrays) -> np.ndarray:
    """Indices of the triangles that cast shadows: the mesh's own (not its back sides)
    but the zero-area ones of :func:`degenerate_triangles`."""
    own = degenerate_triangles(mesh)[:mesh.front_triangles]
    return np.nonzero(~own)[0]


def occluder_triangles(mesh: MeshArrays) -> tuple[np.ndarray, int]:
    """``(triangle positions (T', 3, 3), ignored)``: the triangles that cast shadows
    (:func:`occluder_index`) and how many zero-area ones were left out (the count the
    precompute's warning reports: the faces it calls ignored are exactly the faces the
    occluder scene does not hold)."""
    keep = occluder_index(mesh)
    return mesh.triangle_positions[keep], int(mesh.front_triangles - len(keep))


class PlacedArrays(MeshArrays):
    """An instance's arrays: its source's index arrays, and its world positions and corner
    normals placed by ``place_positions()`` and ``place_normals()`` (the normals repaired:
    :func:`repair_normals`) each time they are read, not held (a thousand instances of a
    5k-vertex mesh would hold 0.3 GB of them through a frame).  Read them once where they
    are used more than once."""

    def __init__(self, local: MeshArrays, place_positions, place_normals):
        self.corner_verts, self.triangles = local.corner_verts, local.triangles
        self.corner_materials = local.corner_materials
        self.front_triangles, self.front_corners = local.front_triangles, local.front_corners
        self._place_positions, self._place_normals = place_positions, place_normals
        self._vertices = len(local.positions)

    @property
    def positions(self) -> np.ndarray:
        return np.ascontiguousarray(self._place_positions(), dtype=np.float64).reshape(-1, 3)

    def _placed(self) -> tuple[np.ndarray, int]:
        """(the corner normals placed and repaired, how many were repaired)."""
        normals = self._place_normals()
        # the repair reads the vertex count, not the positions: none placed for it
        count = repair_normals(MeshArrays(np.zeros((self._vertices, 3)), self.corner_verts,
                                          normals, self.triangles, self.corner_materials))
        return normals, count

    @property
    def corner_normals(self) -> np.ndarray:
        return self._placed()[0]


@dataclass(eq=False)
class Occluders:
    """Triangles that cast shadows, indexed: ``vertices`` (V, 3) float32 and ``triangles``
    (T, 3) int32 into them.  Embree holds an indexed mesh in about 40 bytes a triangle less
    than the same triangles one by one, and this copy in half (a thousand instances' worth
    of occluders is the precompute's largest array after Embree's)."""

    vertices: np.ndarray
    triangles: np.ndarray

    def __len__(self) -> int:
        return len(self.triangles)

    @property
    def positions(self) -> np.ndarray:
        """(T, 3, 3) float32 corners of every triangle."""
        return self.vertices[self.triangles]

    @classmethod
    def join(cls, parts) -> "Occluders":
        """One set of the ``parts`` (Occluders), in order."""
        parts = list(parts)
        if not parts:
            return cls(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
        starts = np.cumsum([0] + [len(p.vertices) for p in parts])
        return cls(np.concatenate([p.vertices for p in parts]),
                   np.concatenate([p.triangles + np.int32(s) for p, s in zip(parts, starts)]))


def triangle_soup(occluders) -> np.ndarray:
    """(T, 3, 3) corners of ``occluders`` (:class:`Occluders`, or such corners already)."""
    return occluders.positions if isinstance(occluders, Occluders) else occluders


def occluder_mesh(mesh: MeshArrays) -> tuple[Occluders, int]:
    """:func:`occluder_triangles` as :class:`Occluders`: the vertices those triangles use
    (float32, in vertex order) and the triangles indexing them."""
    keep = occluder_index(mesh)
    corners = mesh.corner_verts[mesh.triangles[keep]]
    used, index = np.unique(corners, return_inverse=True)
    return (Occluders(mesh.positions[used].astype(np.float32),
                      index.reshape(-1, 3).astype(np.int32)),
            int(mesh.front_triangles - len(keep)))


def with_back_sides(mesh: MeshArrays) -> MeshArrays:
    """``mesh`` with the back side of every triangle as a triangle of its own: corners
    ``C..2C-1`` copy corners ``0..C-1`` with flipped normals and triangles ``T..2T-1``
    are the originals reversed (so a back side seen from behind winds counter-clockwise,
    as a front face does).  The mesh itself when it is two-sided already."""
    if mesh.two_sided:
        return mesh
    c = len(mesh.corner_verts)
    back = mesh.triangles[:, ::-1] + c
    return MeshArrays(mesh.positions, np.concatenate([mesh.corner_verts, mesh.corner_verts]),
                      np.concatenate([mesh.corner_normals, -mesh.corner_normals]),
                      np.concatenate([mesh.triangles, back]),
                      np.concatenate([mesh.corner_materials, mesh.corner_materials]),
                      front_triangles=len(mesh.triangles), front_corners=c)


def corner_source(mesh: MeshArrays) -> np.ndarray:
    """(C,) the corner of the mesh's own each corner copies (itself for its own corners):
    what per-corner values exported for the mesh (UVs, colours, tangents) are read at."""
    c = np.arange(len(mesh.corner_verts))
    return c if not mesh.two_sided else c % mesh.front_corners


def corner_areas(mesh: MeshArrays) -> np.ndarray:
    """Surface area each corner stands for (a third of each triangle it is in), (C,):
    ``sum_c w_c |x_c|^2`` is the surface L2 norm that an image's error approximates
    (pixels cover surface area, not corners)."""
    p = mesh.positions[mesh.corner_verts]
    tri = mesh.triangles
    area = triangle_areas(p[tri])
    w = np.zeros(len(p), dtype=np.float64)
    for k in range(3):
        np.add.at(w, tri[:, k], area / 3.0)
    return w


def point_areas(mesh: MeshArrays, points: "ShadingPoints") -> np.ndarray:
    """Surface area each shading point stands for (P,): its corners' :func:`corner_areas`."""
    return np.bincount(points.point_of_corner, weights=corner_areas(mesh),
                       minlength=points.count)


def point_interiors(mesh: MeshArrays, points: "ShadingPoints") -> np.ndarray:
    """(P, 3) a point inside each shading point's own surface: the mean of the centroids of
    the triangles it is a corner of (off the point's creases, on its side of them)."""
    return face_interiors(mesh.triangle_positions, points.point_of_corner[mesh.triangles],
                          points.positions)


def face_interiors(tri_positions: np.ndarray, tri_points: np.ndarray,
                   points: np.ndarray) -> np.ndarray:
    """(P, 3) the mean of the centroids of the triangles (T, 3, 3) each point is a corner
    of (``tri_points`` (T, 3): the point of each corner); the point itself where it is a
    corner of none."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    tri_points = np.asarray(tri_points, np.int64).reshape(-1, 3)
    cen = np.asarray(tri_positions, np.float64).reshape(-1, 3, 3).mean(axis=1)
    acc = np.zeros((len(points), 3))
    for k in range(3):
        np.add.at(acc, tri_points[:, k], cen)
    count = np.bincount(tri_points.reshape(-1), minlength=len(points))
    return np.where(count[:, None] > 0, acc / np.maximum(count, 1)[:, None], points)


def closed_side(mesh: MeshArrays) -> int:
    """How back faces are seen: 0 for an open mesh; for a closed one (every edge shared
    by exactly two triangles that traverse it in opposite directions) +1 when its
    triangles wind outward (signed volume > 0), -1 when inward (e.g. a negative scale).
    Seen from inside a closed mesh every direction is blocked by it, so the renderer
    draws its inner side black, as Cycles' direct light is there.  2 for a two-sided mesh
    (:func:`with_back_sides`): each side is a triangle of its own, drawn from its front."""
    if len(mesh.triangles) == 0:
        return 0
    if mesh.two_sided:
        return 2
    # vertices welded by position, so meshes split at seams (imports) count as closed
    scale = max(bounding_diagonal(mesh.positions), 1e-30)
    q = np.round(np.nan_to_num(mesh.positions) / (scale * 1e-7)).astype(np.int64)
    _, weld = np.unique(q, axis=0, return_inverse=True)
    v = weld.reshape(-1)[mesh.corner_verts[mesh.triangles]]      # (T, 3) welded ids
    v = v[(v[:, 0] != v[:, 1]) & (v[:, 1] != v[:, 2]) & (v[:, 2] != v[:, 0])]
    a = np.concatenate([v[:, 0], v[:, 1], v[:, 2]])
    b = np.concatenate([v[:, 1], v[:, 2], v[:, 0]])
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    directed = a * n + b
    if len(np.unique(directed)) != len(directed):
        return 0                        # an edge traversed twice the same way
    if not np.isin(b * n + a, directed).all():
        return 0                        # an edge without its opposite: a boundary
    p = mesh.positions[mesh.corner_verts[mesh.triangles]]
    volume = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum())
    return 1 if volume > 0.0 else -1 if volume < 0.0 else 0


def seen_points(mesh: MeshArrays, points: "ShadingPoints", clip: np.ndarray, side: int,
                eye=None, view_dir=None, margin: float = 0.05) -> np.ndarray:
    """(P,) bool: the shading points a camera may see -- corners of a triangle that is not
    wholly outside one plane of the frustum (``clip``: 4×4 world-to-clip, the GL
    ``projection @ view``, its sides widened by ``margin`` of the frame) and, on a closed
    mesh (``side`` ±1, :func:`closed_side`), that faces the camera (``eye`` a position, or
    ``view_dir`` a unit direction toward an orthographic camera): a closed mesh's back
    faces are hidden by its front, and seen from inside it is drawn black.  Open and
    two-sided meshes keep both windings.  Conservative: hidden points of front faces are
    kept (no occlusion test)."""
    tri_points = points.point_of_corner[mesh.triangles]
    keep = np.zeros(points.count, dtype=bool)
    if len(tri_points) == 0:
        return keep
    tp = mesh.triangle_positions                                   # (T, 3, 3)
    h = np.concatenate([tp, np.ones(tp.shape[:2] + (1,))], axis=2) @ np.asarray(clip).T
    x, y, z, w = h[..., 0], h[..., 1], h[..., 2], h[..., 3]
    wide = (1.0 + margin) * w
    outside = ((x < -wide).all(1) | (x > wide).all(1) | (y < -wide).all(1)
               | (y > wide).all(1) | (z < -w).all(1) | (z > w).all(1))
    inside = ~outside
    if side in (1, -1):
        ng = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
        toward = (np.asarray(eye, np.float64) - tp.mean(axis=1) if view_dir is None
                  else np.broadcast_to(np.asarray(view_dir, np.float64), ng.shape))
        inside &= side * np.einsum("ij,ij->i", ng, toward) > 0.0          # edge-on: no area
    keep[tri_points[inside].reshape(-1)] = True
    return keep


def normal_matrix(matrix) -> np.ndarray:
    """(3, 3) what turns normals when ``matrix`` (4x4 or 3x3) places positions: the inverse
    transpose of its 3x3 (the 3x3 itself when singular)."""
    A = np.asarray(matrix, np.float64)[:3, :3]
    return np.linalg.inv(A).T if abs(np.linalg.det(A)) > 1e-30 else A


def bounding_box(positions: np.ndarray) -> np.ndarray:
    """(2, 3) the least and greatest coordinates of the finite ``positions`` ((0, 3) when
    none is finite): a box the precompute gathers per object, whose corners bound the scene."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        return np.zeros((0, 3))
    return np.array([p.min(axis=0), p.max(axis=0)])


def bounds(meshes) -> np.ndarray:
    """:func:`bounding_box` of every mesh's positions together, each mesh's read once and
    not concatenated (an instance's are placed when read: a thousand would be a copy of
    the scene per frame)."""
    boxes = [bounding_box(m.positions) for m in meshes]
    return bounding_box(np.concatenate(boxes)) if boxes else np.zeros((0, 3))


def bounding_diagonal(positions: np.ndarray) -> float:
    box = bounding_box(positions)
    return float(np.linalg.norm(box[1] - box[0])) if len(box) else 0.0


def repair_normals(mesh: MeshArrays) -> int:
    """Replace zero/NaN corner normals (zero-area faces) in place; return how many.

    A bad corner takes the mean of the valid normals of its vertex, or +Z when
    the vertex has none.  :class:`PlacedArrays` repair theirs as they are read: how many.
    """
    if isinstance(mesh, PlacedArrays):
        return mesh._placed()[1]
    n = mesh.corner_normals
    length = np.linalg.norm(n, axis=1)
    bad = ~np.isfinite(length) | (length < 1e-8)
    count = int(bad.sum())
    if count:
        good = ~bad
        acc = np.zeros_like(mesh.positions)
        np.add.at(acc, mesh.corner_verts[good], n[good] / length[good, None])
        fill = acc[mesh.corner_verts[bad]]
        fl = np.linalg.norm(fill, axis=1)
        fill = np.where(fl[:, None] > 1e-8, fill / np.maximum(fl, 1e-30)[:, None], [0.0, 0.0, 1.0])
        n[bad] = fill
    good = ~bad
    n[good] /= length[good, None]
    return count


@dataclass
class ShadingPoints:
    """Distinct (vertex, normal, material) triples of a mesh."""

    point_of_corner: np.ndarray   # (C,) int
    positions: np.ndarray         # (P, 3)
    normals: np.ndarray           # (P, 3) unit
    materials: np.ndarray         # (P,) material slot

    @property
    def count(self) -> int:
        return len(self.positions)


def point_keys(normals: np.ndarray, materials: np.ndarray) -> np.ndarray:
    """One int64 per (normal, material slot): the normal quantised to 1/4096 per component
    (14 bits each) and the slot (20 bits) packed, so that sorting by (vertex, key) orders
    shading points (:func:`shading_points`) and equal keys are the same point."""
    q = np.clip(np.round(np.asarray(normals) * 4096.0).astype(np.int64) + 4096, 0, 8192)
    mat = np.clip(np.asarray(materials, dtype=np.int64), 0, (1 << 20) - 1)
    return (((q[:, 0] << 14) | q[:, 1]) << 14 | q[:, 2]) << 20 | mat


def shading_points(mesh: MeshArrays) -> ShadingPoints:
    """Group corners into shading points, ordered by (vertex, normal, material).

    Normals are compared quantised to 1/4096 per component; the three components
    and the material slot are packed into one integer key (:func:`point_keys`) so a
    two-key stable sort groups the corners (much faster than ``np.unique(axis=0)``).
    """
    count = len(mesh.corner_verts)
    if count == 0:
        empty = np.zeros((0, 3))
        return ShadingPoints(np.zeros(0, np.int64), empty, empty, np.zeros(0, np.int64))
    corner_normals = mesh.corner_normals          # read once (PlacedArrays place them)
    key = point_keys(corner_normals, mesh.corner_materials)
    order = np.lexsort((key, mesh.corner_verts))
    v_sorted, k_sorted = mesh.corner_verts[order], key[order]
    new = np.ones(count, dtype=bool)
    new[1:] = (v_sorted[1:] != v_sorted[:-1]) | (k_sorted[1:] != k_sorted[:-1])
    point_sorted = np.cumsum(new) - 1
    inverse = np.empty(count, dtype=np.int64)
    inverse[order] = point_sorted
    first = order[new]
    normals = np.zeros((int(point_sorted[-1]) + 1, 3))
    np.add.at(normals, inverse, corner_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-30), [0.0, 0.0, 1.0])
    return ShadingPoints(
        point_of_corner=inverse,
        positions=mesh.positions[mesh.corner_verts[first]],
        normals=normals,
        materials=mesh.corner_materials[first].copy(),
    )


def point_corners(points: ShadingPoints) -> np.ndarray:
    """(P,) one face corner of each shading point."""
    poc = points.point_of_corner
    corner = np.zeros(points.count, np.int64)
    corner[poc] = np.arange(len(poc))
    return corner


def per_point(points: ShadingPoints, values: np.ndarray) -> np.ndarray | None:
    """Per-corner ``values`` (C, ...) as one row per shading point when every corner holds
    its point's (per-vertex radiance does), else None."""
    values = np.asarray(values)
    poc = points.point_of_corner
    if len(values) != len(poc):
        return None
    rows = values[point_corners(points)]
    return rows if np.array_equal(rows[poc], values) else None


def fingerprint(mesh: MeshArrays) -> str:
    """Hash of the world-space geometry the precompute depends on."""
    h = hashlib.sha1()
    h.update(np.round(mesh.positions, 5).astype(np.float32).tobytes())
    h.update(mesh.corner_verts.astype(np.int32).tobytes())
    h.update(mesh.triangles.astype(np.int32).tobytes())
    h.update(np.round(mesh.corner_normals, 3).astype(np.float32).tobytes())
    h.update(mesh.corner_materials.astype(np.int32).tobytes())
    return h.hexdigest()


def scene_fingerprint(fingerprints) -> str:
    """One hash of several objects' geometry fingerprints, independent of their order
    and of the objects' names (renaming changes no shadow)."""
    h = hashlib.sha1()
    for fp in sorted(fingerprints):
        h.update(fp.encode("ascii") + b"\0")
    return h.hexdigest()


def grid(size: float = 2.0, cuts: int = 8, z: float = 0.0) -> MeshArrays:
    """A flat square grid of ``cuts`` x ``cuts`` quads (two triangles each), normal +Z."""
    n = cuts + 1
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    pos = np.column_stack([X.ravel(), Y.ravel(), np.full(n * n, z)])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    corner_verts = tris.reshape(-1)
    return MeshArrays(pos, corner_verts, np.tile([0.0, 0.0, 1.0], (len(corner_verts), 1)),
                      np.arange(len(corner_verts)).reshape(-1, 3))
