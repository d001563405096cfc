"""Occluders the shadow-field tests share, and the exact cast they are checked against:
axis-aligned boxes (an L of two), quads, random rotations and Embree's occlusion query
(Blender-free)."""

from __future__ import annotations

import numpy as np


#: An L-shaped occluder (a slab and a post on one end): non-convex, off-centre.
L_BOXES = (((-1.0, -0.5, -0.3), (1.0, 0.5, 0.3)), ((0.5, -0.5, 0.3), (1.0, 0.5, 1.2)))


def aabb(lo, hi):
    """(12, 3, 3) triangles of the axis-aligned box ``[lo, hi]``."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[c[q[0]], c[q[i]], c[q[i + 1]]] for q in quads for i in (1, 2)])


def aabbs(pairs):
    """The triangles of several boxes ``((lo, hi), ...)``."""
    return np.concatenate([aabb(lo, hi) for lo, hi in pairs])


def quad(a, b, c, d):
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def outside(points, boxes, pad=0.02):
    """Mask of the points outside every box (with a little padding)."""
    inside = np.zeros(len(points), bool)
    for lo, hi in boxes:
        inside |= ((points > np.asarray(lo) - pad) & (points < np.asarray(hi) + pad)).all(1)
    return ~inside


def rotation(seed):
    """A random rotation matrix (uniform unit quaternion)."""
    q = np.random.default_rng(seed).normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def cast(scene, origins, dirs):
    """(P, D) bool, True where the ray from each origin along each direction is blocked."""
    P, D = len(origins), len(dirs)
    org = np.repeat(np.asarray(origins, np.float32), D, axis=0)
    d = np.ascontiguousarray(np.tile(np.asarray(dirs, np.float32), (P, 1)))
    return (np.asarray(scene.run(org, d, query="OCCLUDED")) != -1).reshape(P, D)
