"""Small scenes of planes for the transport tests (no Blender)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.scene import mesh


def quad(corners, cuts: int) -> mesh.MeshArrays:
    """A planar grid over the quad ``corners`` (a, b, c, d counter-clockwise seen from its
    front; normal ``(b - a) x (d - a)``) with ``cuts`` x ``cuts`` cells."""
    a, b, _, d = (np.asarray(x, float) for x in corners)
    n = cuts + 1
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="xy")
    pos = (a + (b - a) * u[..., None] + (d - a) * v[..., None]).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    A, B, C, D = (idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(),
                  idx[1:, :-1].ravel())
    tris = np.concatenate([np.column_stack([A, B, C]), np.column_stack([A, C, D])])
    normal = np.cross(b - a, d - a)
    normal /= np.linalg.norm(normal)
    corners_v = tris.reshape(-1)
    return mesh.MeshArrays(pos, corners_v, np.tile(normal, (len(corners_v), 1)),
                           np.arange(len(corners_v)).reshape(-1, 3))


def floor_and_wall(cuts: int):
    """A 2 x 2 floor (normal +z) and a 2 x 2 wall standing just past its far edge, facing
    it (a 1 cm gap: no floor point lies in the wall's plane, where a ray would start on it)."""
    floor = quad([(-1, -1, 0), (1, -1, 0), (1, 0.99, 0), (-1, 0.99, 0)], cuts)
    wall = quad([(-1, 1, 0), (1, 1, 0), (1, 1, 2), (-1, 1, 2)], cuts)
    return [floor, wall]
