"""Glossy lobes too narrow for the cubemap, drawn per pixel for every method.

A lobe narrower than a few cubemap texels (:func:`core.shading.brdf.is_sharp`: a mirror, or
roughness below ~0.19 at 6×32²) cannot be integrated texel by texel: sampled at texel
centres it renders black with a few bright blobs, and interpolated per vertex it smears.
FrameState marks such materials (:attr:`core.shading.brdf.Material.per_pixel_lobe`), so every
method shades their Lambert base only, and this pass adds the lobes per pixel
(``shaders/passes/sharp_lobe_frag.glsl``): NDF samples, the environment filtered to each
sample's share of the lobe from a mip pyramid of the equirect (level 0 is the
background's texture), the shading points' stored visibility at each sample direction
(mixed over the triangle's corners whose normal's hemisphere holds it: only those traced it).
The viewport and F12 draw it alike, after the method's own pass, adding with depth
test equal.
"""

from __future__ import annotations

import numpy as np

from ...core.shading import brdf as core_brdf
from ...core.sphere import envmap
from ...core.scene import visibility as core_visibility
from . import drawing, shaders
from ..frame import keys

#: NDF samples per pixel for a lobe of non-zero roughness (one for a mirror)
SAMPLES = 32

# per object: (geometry fingerprint, sharp slots) -> batch; visibility textures per bits
_BATCHES = drawing.gpu_cache({})
_VISIBILITY = drawing.gpu_cache({})
_MIPS = drawing.gpu_cache({})


def _shader():
    return shaders.shader("sharp_lobe")


def sharp_slots(st) -> list:
    """Material slots of an object whose glossy lobes this pass draws."""
    return [i for i, m in enumerate(st.materials) if m.per_pixel_lobe]


def _batches(st, slots):
    """Per sharp slot a batch of its triangles' corners: position, normal, the three
    shading points, barycentric weights and the three points' normals (the hemispheres
    their visibility was traced over)."""
    from gpu_extras.batch import batch_for_shader
    key = (st.name, st.fingerprint, tuple(slots))
    got = _BATCHES.get(key)
    if got is not None:
        return got
    arrays = st.arrays
    tri = arrays.triangles
    pos, nrm, tri_points, bary = drawing.triangle_corners(st)
    pts = st.points
    tri_normals = np.repeat(pts.normals[pts.point_of_corner[tri]].astype(np.float32), 3,
                            axis=0)                                  # (3T, 3 points, 3)
    tri_slot = arrays.corner_materials[tri[:, 0]]
    out = []
    for slot in slots:
        sel = np.repeat(tri_slot == slot, 3)
        if sel.any():
            out.append((slot, batch_for_shader(_shader(), "TRIS", {
                "pos": np.ascontiguousarray(pos[sel]), "nrm": np.ascontiguousarray(nrm[sel]),
                "triPoints": np.ascontiguousarray(tri_points[sel]),
                "bary": np.ascontiguousarray(bary[sel]),
                **{"triN%d" % k: np.ascontiguousarray(tri_normals[sel, k]) for k in range(3)}})))
    if len(_BATCHES) >= 32:
        _BATCHES.pop(next(iter(_BATCHES)))
    _BATCHES[key] = out
    return out


def _texture(rgba: np.ndarray):
    return drawing.float_texture(np.ascontiguousarray(rgba, dtype=np.float32))


def visibility_texels(bits: np.ndarray):
    """(rows, drawing.ROW_TEXELS, 4) float32 of bit-packed visibility (P, nbytes): three bytes
    per float (exact below 2^24), point p's floats from texel p * stride; and the stride."""
    floats = core_visibility.bytes_to_float24(bits)              # (P, nbytes / 3)
    P, F = floats.shape
    stride = -(-F // 4)
    flat = np.zeros((P, stride * 4), np.float32)
    flat[:, :F] = floats
    total = max(P * stride, 1)
    rows = -(-total // drawing.ROW_TEXELS)
    out = np.zeros(rows * drawing.ROW_TEXELS * 4, np.float32)
    out[:flat.size] = flat.reshape(-1)
    return out.reshape(rows, drawing.ROW_TEXELS, 4), stride


def _visibility_texture(st):
    def make():
        texels, stride = visibility_texels(st.bits)
        return _texture(texels), stride
    return keys.per_visibility(_VISIBILITY, (st.name, id(st.bits)), st.bits, make, limit=16)


def _mip_texture(world):
    """(texture, levels) of the equirect's mip pyramid below level 0 (newest world image)."""
    img = world.image
    key = ("color",) if img is None else keys.image_key(img)
    got = _MIPS.get(key)
    if got is None:
        if img is None:
            atlas, levels = np.zeros((1, 1, 4), np.float32), 0
        else:
            shown = envmap.display_equirect(img)          # level 0: the background's texture
            atlas = envmap.equirect_mip_atlas(shown)
            levels = len(envmap.equirect_mip_sizes(*shown.shape[:2]))
        got = (_texture(atlas), levels)
        _MIPS.clear()
        _MIPS[key] = got
    return got


def parameters(material, eye4, env_size, levels, strength, cube_n, stride):
    """The paramTex texels of one slot (layout in sharp_lobe_frag.glsl)."""
    lobes = core_brdf.sharp_lobes(material)
    p = np.zeros((1, 4 + 3 * max(len(lobes), 1), 4), np.float32)
    p[0, 0] = eye4
    r = material.table_roughness
    p[0, 1] = (r * r, 0.0 if material.lobe_distribution == "BECKMANN" else 1.0, len(lobes),
               SAMPLES)
    p[0, 2] = (env_size[1], env_size[0], levels, strength)
    p[0, 3] = (cube_n, stride, 0.0, 0.0)
    for j, (kind, weight, f0, B, eta) in enumerate(lobes):
        p[0, 4 + 3 * j] = (kind, weight, eta, 0.0)
        p[0, 5 + 3 * j, :3] = f0
        p[0, 6 + 3 * j, :3] = B
    return _texture(p)


def draws(state, eye, view_dir, background) -> list:
    """``draw(view_projection)`` callables adding the sharp lobes of every object that has
    them (empty when none has).  ``background``: (texture, rotation, strength) of the
    world as the engine draws it (level 0 of the environment)."""
    todo = [(st, slots) for st in state.objects for slots in [sharp_slots(st)] if slots]
    if not todo:
        return []
    env_tex, rotation, strength = background
    world = state.full_world if state.full_world is not None else state.world
    env_size = (1, 1) if world.image is None else envmap.display_equirect(world.image).shape[:2]
    mip_tex, levels = _mip_texture(world)
    eye4 = ((*map(float, view_dir), 0.0) if view_dir is not None else (*map(float, eye), 1.0))
    out = []
    for st, slots in todo:
        batches = _batches(st, slots)
        if not batches:
            continue
        vis_tex, stride = _visibility_texture(st)
        params = {slot: parameters(st.materials[slot], eye4, env_size, levels, float(strength),
                                   state.resolution, stride) for slot, _ in batches}

        def draw(view_projection, batches=batches, params=params, vis_tex=vis_tex,
                 side=float(st.closed_side)):
            sh = _shader()
            sh.bind()
            sh.uniform_float("viewProjection", view_projection)
            sh.uniform_float("envRot", rotation)
            sh.uniform_float("closedSide", side)
            sh.uniform_sampler("envTex", env_tex)
            sh.uniform_sampler("mipTex", mip_tex)
            sh.uniform_sampler("visTex", vis_tex)
            for slot, batch in batches:
                sh.uniform_sampler("paramTex", params[slot])
                batch.draw(sh)

        out.append(draw)
    return out
