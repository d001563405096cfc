"""How much of a camera's image each mesh corner stands for (pure numpy + Embree).

An image's rel-L2 error is a sum over pixels; a per-vertex method's pixels interpolate
its corners' radiance across each triangle, so the image's squared error norm is close
to ``Σ_c w_c ‖e_c‖²`` with ``w_c`` a third of the *visible pixel area* of every triangle
the corner is in.  :func:`corner_pixel_weights` computes those weights for a camera:
each triangle's projected area in pixels (perspective or orthographic ``clip``
matrix, the GL ``projection @ view``), counted when its centroid is inside the frame,
in front of the camera and not hidden by any other triangle (one Embree occlusion ray
from the camera to the centroid; a back face of a closed mesh is hidden by its front).
"""

from __future__ import annotations

import numpy as np

from ...scene import visibility


def _clip_to_pixels(points: np.ndarray, clip: np.ndarray, width: int, height: int):
    """(pixel xy (N, 2), clip w (N,)) of world ``points`` under the 4×4 ``clip``."""
    h = np.concatenate([points, np.ones((len(points), 1))], axis=1) @ np.asarray(clip).T
    w = h[:, 3]
    safe = np.where(np.abs(w) > 1e-12, w, 1e-12)
    ndc = h[:, :2] / safe[:, None]
    return (ndc + 1.0) * 0.5 * np.array([width, height], dtype=np.float64), w


def corner_pixel_weights(meshes, clip: np.ndarray, width: int, height: int,
                         eye=None, view_dir=None, occluders=None, only=None) -> list:
    """Per mesh, the pixel area (float64 per corner) each corner stands for in the image.

    ``meshes``: :class:`~.mesh.MeshArrays` in world space (the whole scene's, so they
    hide each other); ``clip``: the 4×4 world-to-clip matrix; ``eye``: camera position
    (perspective) or ``view_dir``: unit direction toward an orthographic camera.
    ``occluders``: an Embree scene of every triangle (:func:`visibility.build_occluder_scene`
    of them when None and Embree is installed; without Embree nothing is hidden).
    ``only``: per mesh, a mask of the triangles to count (None: all); the others count
    nothing here but still hide (AUTO weighs a sample of points: the triangles around
    them are all it needs).
    """
    if occluders is None and visibility.have_embree() and meshes:
        occluders = visibility.build_occluder_scene(
            np.concatenate([m.positions[m.corner_verts[m.triangles]] for m in meshes]))
    out = []
    for i, m in enumerate(meshes):
        weights = np.zeros(len(m.corner_verts), dtype=np.float64)
        triangles = m.triangles if only is None or only[i] is None else m.triangles[only[i]]
        tp = m.positions[m.corner_verts[triangles]]
        if len(tp) == 0:
            out.append(weights)
            continue
        flat = tp.reshape(-1, 3)
        xy, w = _clip_to_pixels(flat, clip, width, height)
        xy, w = xy.reshape(-1, 3, 2), w.reshape(-1, 3)
        e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        centre = tp.mean(axis=1)
        cxy, cw = _clip_to_pixels(centre, clip, width, height)
        seen = ((w > 1e-9).all(axis=1) & (cw > 1e-9) & np.isfinite(area)
                & (cxy[:, 0] >= 0) & (cxy[:, 0] <= width)
                & (cxy[:, 1] >= 0) & (cxy[:, 1] <= height))
        if occluders is not None and seen.any():
            idx = np.nonzero(seen)[0]
            target = centre[idx]
            if eye is not None:
                origin = np.broadcast_to(np.asarray(eye, np.float64), target.shape)
            else:
                reach = float(np.ptp(flat, axis=0).max()) * 4.0 + 1.0
                origin = target + reach * np.asarray(view_dir, np.float64)
            ray = target - origin
            dist = np.linalg.norm(ray, axis=1)
            ok = dist > 0
            ray = ray / np.where(ok, dist, 1.0)[:, None]
            # stop short of the centroid by a relative step (its own triangle and the
            # neighbours sharing its plane are not occluders)
            tfar = dist * (1.0 - 1e-4) - 1e-6 * (1.0 + dist)
            hit = occluders.run(np.ascontiguousarray(origin, np.float32),
                                np.ascontiguousarray(ray, np.float32),
                                dists=np.ascontiguousarray(np.maximum(tfar, 0.0), np.float32),
                                query="OCCLUDED")
            seen[idx] = ok & (np.asarray(hit) == -1)
        per = np.where(seen, area / 3.0, 0.0)
        for k in range(3):
            weights += np.bincount(triangles[:, k], weights=per, minlength=len(weights))
        out.append(weights)
    return out


def look_at_clip(eye, target, fov: float, near: float = 1e-3, far: float = 1e4) -> np.ndarray:
    """GL world-to-clip matrix of a square perspective camera at ``eye`` looking at
    ``target`` (``fov``: full angle in radians; +Z up unless looking along it)."""
    eye = np.asarray(eye, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - eye
    fwd /= max(float(np.linalg.norm(fwd)), 1e-300)
    up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    view = np.eye(4)
    view[:3, :3] = np.stack([right, np.cross(right, fwd), -fwd])
    view[:3, 3] = -view[:3, :3] @ eye
    f = 1.0 / np.tan(fov / 2)
    proj = np.array([[f, 0, 0, 0], [0, f, 0, 0],
                     [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                     [0, 0, -1.0, 0]])
    return proj @ view
