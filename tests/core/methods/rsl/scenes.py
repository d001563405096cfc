"""The lighting and the traced scene the RSL and distance-table tests share: a noisy sky
with a one-pixel sun over a darker ground, and a grid under a box with jittered normals,
traced at 6x32^2 (Blender-free)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.scene import mesh, visibility
from prt_relight.core.sphere import directions


CUBE = directions.cubemap(32)


def sky_with_sun(h=64, w=128, sun=(20, 37), sun_value=5.0e4):
    rng = np.random.default_rng(3)
    img = np.full((h, w, 3), 0.3, dtype=np.float32) + 0.2 * rng.random((h, w, 3)).astype(np.float32)
    img[h // 2:] *= 0.2                                       # darker ground
    img[sun] = sun_value
    return img


def occluded_grid(cuts=10):
    g = mesh.grid(size=2.0, cuts=cuts)
    sp = mesh.shading_points(g)
    box = np.array([[[0.2, -0.5, 0.0], [0.8, -0.5, 0.0], [0.8, -0.5, 0.8]],
                    [[0.2, -0.5, 0.0], [0.8, -0.5, 0.8], [0.2, -0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, -0.5, 0.8], [0.8, 0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, 0.5, 0.8], [0.2, 0.5, 0.8]]])
    rng = np.random.default_rng(0)
    nrm = sp.normals + 0.3 * rng.normal(size=sp.normals.shape)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    scene = visibility.build_occluder_scene(np.concatenate([g.triangle_positions, box]))
    bits = visibility.trace_visibility(scene, sp.positions, nrm, CUBE, 1e-4)
    return sp.positions, nrm, bits
