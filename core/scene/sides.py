"""Which open surfaces need their back side traced and shaded (two-sided surfaces).

Cycles shades the back of a face with the flipped normal, with the light that reaches that
side.  A closed mesh is seen from outside only (its inside is black, ``mesh.closed_side``);
an open one (a room's walls, a plane, a leaf card) can be seen and lit from both sides.
Tracing and storing the back side doubles the object's shading points, so it is done only
where the scene camera sees a back side (a room's walls whose normals face out, seen from
inside; a plane seen from below; a leaf card turned away): a ground seen from above, the
inside of a head with open eyes stay one-sided.  Light exchanged on a back side nobody
sees is not enough: the inside of a nearly closed mesh exchanges
light with itself and is never drawn.  A view from elsewhere (another camera, the
viewport) draws a one-sided surface's back with its front's light, as before.
"""

from __future__ import annotations

import numpy as np

from .mesh import MeshArrays, occluder_index, triangle_areas

#: triangles sampled per mesh (by area) for the test
SAMPLE_TRIANGLES = 256


def _back_samples(mesh: MeshArrays, count: int, rng):
    """``(points (S, 3), back normals (S, 3), triangle index (S,))``: points on the mesh's
    own triangles chosen by area, with each triangle's geometric back normal."""
    tri = occluder_index(mesh)
    if len(tri) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64)
    tp = mesh.triangle_positions[tri]
    area = triangle_areas(tp)
    pick = rng.choice(len(tri), size=min(count, len(tri)), replace=len(tri) < count,
                      p=area / area.sum())
    r1, r2 = rng.random(len(pick)), rng.random(len(pick))
    s = np.sqrt(r1)
    a, b, c = tp[pick, 0], tp[pick, 1], tp[pick, 2]
    pts = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    ng = np.cross(b - a, c - a)
    ng /= np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-300)
    # the geometric normal follows the shading normals' side (a flipped winding keeps its
    # corner normals' orientation: the back is what the shading normal turns away from)
    corner_n = mesh.corner_normals[mesh.triangles[tri[pick]]].sum(axis=1)
    flip = np.einsum("ij,ij->i", ng, corner_n) < 0.0
    ng[flip] *= -1.0
    return pts, -ng, tri[pick]


def camera_sees_back(mesh: MeshArrays, eye, scene=None, offset: float = 0.0,
                     seed: int = 0) -> bool:
    """Whether a camera at ``eye`` sees the back side of some sampled triangle (the
    camera is on the back's side of it and, with a ``scene``, the segment is free)."""
    if eye is None:
        return False
    rng = np.random.default_rng(seed)
    pts, n, _ = _back_samples(mesh, SAMPLE_TRIANGLES, rng)
    to_eye = np.asarray(eye, np.float64)[None, :] - pts
    facing = np.einsum("ij,ij->i", to_eye, n) > 0.0
    if not facing.any():
        return False
    if scene is None:
        return True
    o = pts[facing] + offset * n[facing]
    d = to_eye[facing]
    dist = np.linalg.norm(d, axis=1)
    hit = scene.run(np.ascontiguousarray(o, np.float32),
                    np.ascontiguousarray(d / dist[:, None], np.float32),
                    dists=np.ascontiguousarray(dist, np.float32), query="OCCLUDED")
    return bool(np.any(hit == -1))


def needs_back_side(scene, mesh: MeshArrays, offset: float, eye=None) -> bool:
    """Whether an open mesh's back side is traced and shaded: the camera at ``eye`` sees
    it past the rest of the scene."""
    return camera_sees_back(mesh, eye, scene, offset)
