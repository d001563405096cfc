"""Rigid motion of a precomputed object (no bpy): whether an object only moved or turned
since its precompute, and how its stored per-point data then maps onto its points.

Per-point data traced in world space (RSL's distance tables live in each vertex's frame)
stays valid when the whole object turns with its vertices: the frames turn with it.  At
precompute the pose is stored -- the rotation part of the object's matrix
(:func:`rotation_part`) and a few vertices in object space (:func:`local_probe`); later
:func:`rigid_turn` says whether the object's vertices are still those (only its matrix
changed) and by which rotation it turned, and :func:`stored_rows` maps each current
shading point to the stored row it was precomputed as.
"""

from __future__ import annotations

import numpy as np

from .mesh import MeshArrays, ShadingPoints, point_keys

#: vertices compared in object space to tell a rigid motion from an edit
PROBE_VERTICES = 64
#: largest change of a probed vertex, relative to the largest coordinate, that is no edit
PROBE_TOLERANCE = 1e-4


def invertible(matrix) -> bool:
    """Whether a 4x4 placement has an inverse: finite, its 3x3 part of full rank (a scale
    of 0 along an axis flattens it: no shadow field follows it, no ray is carried into it)."""
    m = np.asarray(matrix, np.float64)
    return bool(np.isfinite(m).all()) and int(np.linalg.matrix_rank(m[:3, :3])) == 3


def rotation_part(matrix) -> np.ndarray:
    """The rotation nearest to the linear part of a 4x4 (or 3x3) matrix (polar
    decomposition; a matrix with a reflection gives the rotation nearest to it)."""
    U, _, Vt = np.linalg.svd(np.asarray(matrix, dtype=np.float64)[:3, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    return R


def local_probe(world_positions, matrix, count: int = PROBE_VERTICES) -> np.ndarray:
    """Up to ``count`` vertices (evenly spaced in index order) taken back to object space
    by the 4x4 ``matrix`` that placed them (a matrix scaled to 0 on an axis has no
    inverse: its pseudo-inverse gives the vertices with that axis' coordinate 0, the same
    at every pose, so a flattened object is still told moved from edited)."""
    pos = np.asarray(world_positions, dtype=np.float64).reshape(-1, 3)
    M = np.asarray(matrix, dtype=np.float64)
    idx = np.linspace(0, len(pos) - 1, min(count, len(pos))).astype(np.int64)
    return (pos[idx] - M[:3, 3]) @ np.linalg.pinv(M[:3, :3]).T


def rigid_turn(matrix, world_positions, rotation, probe,
               tolerance: float = PROBE_TOLERANCE):
    """``R1 R0^T`` when the object only moved or turned since its precompute: its
    vertices placed by the 4x4 ``matrix`` now are, in object space, the ``probe`` stored
    then by :func:`local_probe` (within ``tolerance`` of the largest coordinate);
    ``rotation`` = ``R0``, the :func:`rotation_part` stored then, ``R1`` the one of
    ``matrix``.  None otherwise (an edited mesh, another vertex count)."""
    now = local_probe(world_positions, matrix)
    then = np.asarray(probe, dtype=np.float64).reshape(-1, 3)
    scale = max(float(np.abs(then).max(initial=0.0)), 1e-9)
    if now.shape != then.shape or np.abs(now - then).max(initial=0.0) > tolerance * scale:
        return None
    return rotation_part(matrix) @ np.asarray(rotation, dtype=np.float64).reshape(3, 3).T


def stored_rows(points: ShadingPoints, arrays: MeshArrays, turn) -> np.ndarray:
    """The stored row of each current shading point after the object turned by ``turn``
    (:func:`rigid_turn`).  Points are ordered by (vertex, quantised world normal,
    material) (:func:`.mesh.shading_points`), so after a turn the split normals of a
    vertex may sort differently; the precompute's order is the order of the turned-back
    normals."""
    vert = np.empty(points.count, dtype=np.int64)
    vert[points.point_of_corner] = arrays.corner_verts
    key = point_keys(np.asarray(points.normals, np.float64) @ np.asarray(turn, np.float64),
                     points.materials)
    order = np.lexsort((key, vert))          # order[i]: current point of stored row i
    rows = np.empty(points.count, dtype=np.int64)
    rows[order] = np.arange(points.count)
    return rows
