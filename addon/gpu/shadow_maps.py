"""The shadow maps of the per-pixel sources (addon/gpu/lights.py), drawn into two atlases as
:func:`addon.frame.sources.shadow_plan` lays them out: one orthographic depth tile per
distant source (the World's compact sources, sun lamps), and per local lamp (point, spot,
area) the faces of its shadow cube it lights through, each holding the distance to the
lamp of what it sees.  Both atlases grow with the number of sources, their tiles shrinking
when the plan's budget says so; each is cached per geometry and source placement."""

from __future__ import annotations

import numpy as np

from ...core.scene import mesh as core_mesh
from ..frame.sources import CUBE_AXES, atlas_grid
from . import drawing, shaders

_SHADOWS = drawing.gpu_cache({})
# the distant atlas's depth texture, drawn into again after a turn (same size)
_SHADOW_TARGET = drawing.gpu_cache({}, limit=1)
_CUBES = drawing.gpu_cache({})


def light_matrix(direction, centre, radius) -> np.ndarray:
    """World -> clip of an orthographic view from ``direction`` (toward the light) that
    holds the sphere (``centre``, ``radius``): depth 0 at the light's side."""
    c = np.asarray(direction, np.float64)
    u = np.cross(c, [0.0, 0.0, 1.0] if abs(c[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(c, u)
    M = np.eye(4)
    for row, axis in enumerate((u, v, -c)):
        M[row, :3] = axis / radius
        M[row, 3] = -axis @ np.asarray(centre, np.float64) / radius
    return M


def face_matrix(position, axis, near, far) -> np.ndarray:
    """World -> clip of a square 90-degree perspective view from ``position`` along
    ``axis`` (one face of a local lamp's shadow cube)."""
    f = np.asarray(axis, np.float64)
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, up, -f
    view[:3, 3] = -view[:3, :3] @ np.asarray(position, np.float64)
    proj = np.zeros((4, 4))
    proj[0, 0] = proj[1, 1] = 1.0
    proj[2, 2] = -(far + near) / (far - near)
    proj[2, 3] = -2.0 * far * near / (far - near)
    proj[3, 2] = -1.0
    return proj @ view


def _begin():
    """Depth-tested, unculled drawing of the casters into a bound atlas."""
    import gpu
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    gpu.state.face_culling_set("NONE")


def distant_atlas(sources, casters, depth_batches, size: int):
    """Every distant source's shadow map, a ``size``² tile each, in one depth atlas:
    (texture, per source (matrix, tile (x, y, size), depth range, texel size)).
    ``depth_batches``: the casters' depth batches, each with its model matrix (4x4; None for
    a batch in world space).  Cached per geometry and directions."""
    import gpu
    import mathutils
    key = (tuple(st.fingerprint for st in casters), size,
           tuple(np.round(s.direction, 7).tobytes() for s in sources))
    got = _SHADOWS.get(key)
    if got is not None:
        return got
    box = core_mesh.bounds([st.arrays for st in casters])
    lo, hi = box if len(box) else (np.zeros(3), np.zeros(3))
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6) * 1.01
    cols, rows = atlas_grid(len(sources), size)
    width, height = size * cols, size * rows
    tex = _SHADOW_TARGET.get((width, height))
    if tex is None:
        _SHADOW_TARGET.clear()
        tex = _SHADOW_TARGET[(width, height)] = gpu.types.GPUTexture((width, height),
                                                                     format="DEPTH_COMPONENT32F")
    # a framebuffer belongs to the GPU context that made it (F12's and the viewport's
    # differ; textures are shared): made here, in the context that draws the atlas
    fb = gpu.types.GPUFrameBuffer(depth_slot=tex)
    tiles = []
    saved = gpu.state.viewport_get()
    sh = shaders.shader("shadow_depth")
    with fb.bind():
        fb.clear(depth=1.0)
        _begin()
        for k, s in enumerate(sources):
            x, y = (k % cols) * size, (k // cols) * size
            gpu.state.viewport_set(x, y, size, size)
            M = light_matrix(s.direction, centre, radius)
            sh.bind()
            light = mathutils.Matrix(M.tolist())
            for batch, model in depth_batches:      # a placed caster's: light @ its matrix
                sh.uniform_float("viewProjection", light if model is None
                                 else mathutils.Matrix((M @ model).tolist()))
                batch.draw(sh)
            tiles.append((M, (x, y, size), 2.0 * radius, 2.0 * radius / size))
    gpu.state.viewport_set(*saved)
    gpu.state.depth_test_set("NONE")
    got = (tex, tiles)
    _SHADOWS.clear()
    _SHADOWS[key] = got
    return got


def cube_atlas(sources, faces, casters, depth_batches, size: int):
    """The faces of each local lamp's shadow cube (``faces``: per lamp a bool per face of
    CUBE_AXES) at ``size``² texels in one R32F atlas of the distance to the lamp: (texture,
    per lamp (the six faces' tile origins (x, y), (-1, -1) where not drawn, and matrices)).
    Cached per geometry, lamp positions and faces."""
    import gpu
    import mathutils
    key = (tuple(st.fingerprint for st in casters), size, tuple(faces),
           tuple(np.round(s.position, 7).tobytes() for s in sources))
    got = _CUBES.get(key)
    if got is not None:
        return got
    allp = np.concatenate([st.arrays.positions for st in casters]) if casters else \
        np.zeros((1, 3))
    cols, rows = atlas_grid(sum(sum(f) for f in faces), size)
    width, height = size * cols, size * rows
    colour = gpu.types.GPUTexture((width, height), format="R32F")
    depth = gpu.types.GPUTexture((width, height), format="DEPTH_COMPONENT32F")
    fb = gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=colour)
    saved = gpu.state.viewport_get()
    # the placed casters' world matrices, a row of three texels per caster (PLACED)
    models = None
    if any(model is not None for _batch, model in depth_batches):
        rows = np.zeros((len(depth_batches), 3, 4), np.float32)
        for i, (_batch, model) in enumerate(depth_batches):
            if model is not None:
                rows[i] = np.asarray(model, np.float64)[:3]
        models = drawing.float_texture(rows)
    variants = {False: shaders.shader("shadow_distance"),
                True: shaders.shader("shadow_distance", ("PLACED",))}
    out, k = [], 0
    with fb.bind():
        fb.clear(color=(1e30, 1e30, 1e30, 1e30), depth=1.0)
        _begin()
        gpu.state.blend_set("NONE")
        for s, drawn in zip(sources, faces):
            reach = float(np.max(np.linalg.norm(allp - s.position, axis=1))) * 1.01 + 1e-3
            near = max(min(0.5 * s.radius, 0.05 * reach), 1e-4 * reach)
            origins, mats = [], []
            for axis, on in zip(CUBE_AXES, drawn):
                M = face_matrix(s.position, axis, near, reach)
                mats.append(M)
                if not on:
                    origins.append((-1.0, -1.0))
                    continue
                x, y = (k % cols) * size, (k // cols) * size
                k += 1
                origins.append((float(x), float(y)))
                gpu.state.viewport_set(x, y, size, size)
                view = mathutils.Matrix(M.tolist())
                bound = None
                for k_caster, (batch, model) in enumerate(depth_batches):
                    sh = variants[model is not None]
                    if sh is not bound:                  # bound again only when it changes
                        bound = sh
                        sh.bind()
                        sh.uniform_float("viewProjection", view)
                        sh.uniform_float("lamp", tuple(map(float, s.position)))
                        if model is not None:
                            sh.uniform_sampler("modelTex", models)
                    if model is not None:
                        sh.uniform_int("caster", k_caster)
                    batch.draw(sh)
            out.append((origins, mats))
    gpu.state.viewport_set(*saved)
    gpu.state.depth_test_set("NONE")
    got = (colour, out)
    _CUBES.clear()
    _CUBES[key] = got
    return got
