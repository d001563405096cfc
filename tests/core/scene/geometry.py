"""Shapes, traces and worlds the scene and REFERENCE tests share: boxes, a wall, a flat-shaded
cube as mesh arrays, a cubemap trace of triangles and a white world (Blender-free)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap


#: the cubemap resolution and the ray offset of the traces
N = 32
OFFSET = 1e-4


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def trace(tris, points, normals, n=N, offset=OFFSET, **kw):
    cube = directions.cubemap(n)
    scene = visibility.build_occluder_scene(np.asarray(tris, dtype=np.float64))
    bits = visibility.trace_visibility(scene, points, normals, cube, offset, **kw)
    assert bits.shape == (len(points), (cube.size + 7) // 8) and bits.dtype == np.uint8
    return bits, visibility.unpack_visibility(bits, cube.size)


def wall_triangles(x=0.01, size=1e3):
    a, b, c, d = ([x, -size, -size], [x, size, -size], [x, size, size], [x, -size, size])
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def box_triangles(lo=-1.0, hi=1.0):
    v = np.array([[x, y, z] for x in (lo, hi) for y in (lo, hi) for z in (lo, hi)], float)
    # index = 4*ix + 2*iy + iz
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [[v[a], v[b], v[c]], [v[a], v[c], v[d]]]
    return np.array(tris)


def white_world(n=N):
    return envmap.WorldLighting(None, color=(1.0, 1.0, 1.0)).to_cubemap(n)


#: a coloured Lambert material
LAMBERT = materials.Material(diffuse_albedo=(0.8, 0.5, 0.2))


def shade(bits, pts, nrm, lighting, material, n=N, eye=(0.0, 0.0, 10.0)):
    cube = directions.cubemap(n)
    return reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [material],
                                  np.asarray(eye, float), cube, lighting)


def flat_cube():
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    # outward-wound quads; index = 4*ix + 2*iy + iz
    quads = [((0, 1, 3, 2), [-1, 0, 0]), ((4, 6, 7, 5), [1, 0, 0]), ((0, 4, 5, 1), [0, -1, 0]),
             ((2, 3, 7, 6), [0, 1, 0]), ((0, 2, 6, 4), [0, 0, -1]), ((1, 5, 7, 3), [0, 0, 1])]
    corner_verts, corner_normals, tris = [], [], []
    for q, nrm in quads:
        base = len(corner_verts)
        corner_verts += list(q)
        corner_normals += [nrm] * 4
        tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return mesh.MeshArrays(v, corner_verts, corner_normals, tris)
