"""Glossy lobes too narrow for the cubemap, drawn per pixel for every method.

A lobe narrower than a few cubemap texels (:func:`core.shading.brdf.is_sharp`: a mirror, or
roughness below ~0.19 at 6×32²) cannot be integrated texel by texel: sampled at texel
centres it renders black with a few bright blobs, and interpolated per vertex it smears.
FrameState marks such materials (:attr:`core.shading.brdf.Material.per_pixel_lobe`), so every
method shades their Lambert base only, and this pass adds the lobes per pixel
(``shaders/passes/sharp_lobe_frag.glsl``): NDF samples, the environment filtered to each
sample's share of the lobe from a mip pyramid of the equirect (level 0 is the
background's texture; where the lobe is narrower than the pixel's footprint, of the World's
residual: its compact sources are then the lights pass's, addon/gpu/lights.py), the shading points' stored visibility at each sample direction
(mixed over the triangle's corners whose normal's hemisphere holds it: only those traced it).
The viewport and F12 draw it alike, after the method's own pass, adding with depth
test equal.  A slot's textured Roughness and normal or bump map are read per pixel (as
the compact sources' pass does, addon/lights.py), with Cycles' multiscatter factor at the
pixel's roughness: every method leaves such a slot's lobes to this pass.
"""

from __future__ import annotations

import numpy as np

from ...core.shading import brdf as core_brdf, microfacet
from ...core.sphere import envmap
from ...core.scene import textures
from . import drawing, shaders, visibility
from ..blender import texture_export
from ..frame import keys

#: NDF samples per pixel for a lobe of non-zero roughness (one for a mirror)
SAMPLES = 32
#: the World's compact sources the pass tells apart (a bit each; the Compact Sources
#: setting allows 8)
MAX_WORLD_SOURCES = 32

#: roughness nodes of a textured Roughness' multiscatter rows (values i / (n - 1))
ROUGHNESS_NODES = 17
#: cos_o nodes of a multiscatter row (values i / (TABLE - 1), sharp_lobe_frag.glsl)
TABLE = 32
# per object: (geometry fingerprint, sharp slots) -> batch
_BATCHES = drawing.gpu_cache({})
# the vertex format every feature set of the pass draws
_FORMAT = drawing.gpu_cache({}, limit=1)
# per image: (level 0, mips, levels); the whole World, or its residual and its sources
_MIPS = drawing.gpu_cache({}, limit=3)


def _shader(features=()):
    """The pass compiled with ``features`` (ROUGH_TEX, NORMAL_MAP: left out of the draws
    without them, as the lights pass does)."""
    return shaders.shader("sharp_lobe", features)


_ATTRIBUTES = (("VEC3", "pos"), ("VEC3", "nrm"), ("VEC3", "triPoints"), ("VEC3", "bary"),
               ("VEC3", "triN0"), ("VEC3", "triN1"), ("VEC3", "triN2"), ("VEC2", "uv"),
               ("VEC4", "tng"))


def _batch(attrs):
    """A batch of the pass's vertex layout, which any feature set's shader draws
    (``batch_for_shader`` refuses the UVs a shader without textures compiles out)."""
    import gpu
    fmt = _FORMAT.get("format")
    if fmt is None:
        fmt = _FORMAT["format"] = gpu.types.GPUVertFormat()
        for kind, ident in _ATTRIBUTES:
            fmt.attr_add(id=ident, comp_type="F32", len=int(kind[-1]), fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, len(attrs["pos"]))
    for _, ident in _ATTRIBUTES:
        vbo.attr_fill(ident, np.ascontiguousarray(attrs[ident], dtype=np.float32))
    return gpu.types.GPUBatch(type="TRIS", buf=vbo)


def sharp_slots(st) -> list:
    """Material slots of an object whose glossy lobes this pass draws (``st.materials``
    also holds a textured slot's per-point variants: ``st.slot_of`` maps them back)."""
    return sorted({int(st.slot_of[i]) for i, m in enumerate(st.materials) if m.per_pixel_lobe})


def _batches(st, slots):
    """Per sharp slot a batch of its triangles' corners: position, normal, the three
    shading points, barycentric weights and the three points' normals (the hemispheres
    their visibility was traced over), the UVs and tangents of its textured inputs."""
    key = (st.name, st.fingerprint, tuple(slots),
           tuple((slot, id(got[1])) for slot in slots
                 for got in [texture_export.slot_uvs(st, slot)] if got is not None),
           tuple((slot, id(got[2])) for slot, got in sorted(st.normals.items())))
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
    corner = tri.reshape(-1)
    out = []
    for slot in slots:
        sel = np.repeat(tri_slot == slot, 3)
        if sel.any():
            uv = np.zeros((int(sel.sum()), 2), np.float32)
            tng = np.zeros((int(sel.sum()), 4), np.float32)
            uvs = texture_export.slot_uvs(st, slot)
            if uvs is not None:
                uv[:] = uvs[1][corner[sel]]
            mapped = texture_export.shader_normal(st, slot)
            if mapped is not None:
                tng[:] = mapped[1][corner[sel]]
            out.append((slot, _batch({
                "pos": pos[sel], "nrm": nrm[sel], "triPoints": tri_points[sel],
                "bary": bary[sel], "uv": uv, "tng": tng,
                **{"triN%d" % k: tri_normals[sel, k] for k in range(3)}})))
    if len(_BATCHES) >= 32:
        _BATCHES.pop(next(iter(_BATCHES)))
    _BATCHES[key] = out
    return out


def _texture(rgba: np.ndarray):
    return drawing.float_texture(np.ascontiguousarray(rgba, dtype=np.float32))


def _mip_texture(key, image, shown_tex=None):
    """(level 0, mip atlas, levels) textures of an equirect ``image`` (None: black; a
    callable: made on a miss) as this pass reads it, cached under ``key``; ``shown_tex``
    (the background's texture) stands for level 0 where given."""
    got = _MIPS.get(key)
    if got is None:
        level0 = None
        image = image() if callable(image) else image
        if image is None:
            atlas, levels = np.zeros((1, 1, 4), np.float32), 0
            level0 = _texture(atlas) if shown_tex is None else None
        else:
            shown = envmap.display_equirect(image)        # level 0 as the background's
            atlas = envmap.equirect_mip_atlas(shown)
            levels = len(envmap.equirect_mip_sizes(*shown.shape[:2]))
            if shown_tex is None:
                rgba = np.ones(shown.shape[:2] + (4,), np.float32)
                rgba[:, :, :3] = shown
                level0 = _texture(rgba)
        got = (level0, _texture(atlas), levels)
        _MIPS[key] = got
    return (got[0] if shown_tex is None else shown_tex), got[1], got[2]


def _environment(state, shown_tex):
    """(residual level 0, its mips, sources level 0, their mips, levels, worldSrcTex, source
    count): the World's residual and its compact sources' own image (the whole World and
    black where none is split off), and the sources' directions and radii."""
    world = state.full_world if state.full_world is not None else state.world
    img = world.image
    if img is None or state.world.image is None or state.world.image is img:
        key = ("color",) if img is None else keys.image_key(img)
        env_tex, mip_tex, levels = _mip_texture(("whole", key), img, shown_tex)
        black = _mip_texture(("black",), None)
        return env_tex, mip_tex, black[0], black[1], levels, _texture(np.zeros((1, 1, 4))), 0
    key = keys.image_key(state.world.image)
    res_tex, res_mip, levels = _mip_texture(("residual", key), state.world.image)
    src_tex, src_mip, _ = _mip_texture(
        ("sources", key), lambda: np.maximum(np.asarray(img, np.float32) - state.world.image, 0.0))
    rows = np.array([(*s.direction, s.radius) for s in state.sources[:MAX_WORLD_SOURCES]],
                    np.float32).reshape(1, -1, 4)
    return res_tex, res_mip, src_tex, src_mip, levels, _texture(rows), rows.shape[1]


def parameters(material, eye4, env_size, levels, strength, cube_n, stride, rough=None,
               normal=None, world_sources=0):
    """The paramTex texels of one slot (layout in sharp_lobe_frag.glsl); ``rough``: the
    slot's textured Roughness (core.textures.ScalarSource) read per pixel, ``normal`` its
    core.textures.NormalSource."""
    lobes = core_brdf.sharp_lobes(material)[:2]
    n = ROUGHNESS_NODES if rough is not None else 1
    p = np.zeros((1 + 2 * n, max(TABLE, 20), 4), np.float32)
    p[0, 0] = eye4
    r = material.table_roughness
    p[0, 1] = (r * r, 0.0 if material.lobe_distribution == "BECKMANN" else 1.0, len(lobes),
               SAMPLES)
    p[0, 2] = (env_size[1], env_size[0], levels, strength)
    p[0, 3] = (cube_n, stride, world_sources, 0.0)
    for j, (kind, weight, f0, B, eta) in enumerate(lobes):
        p[0, 4 + 3 * j] = (kind, weight, eta, 0.0)
        p[0, 5 + 3 * j, :3] = f0
        p[0, 6 + 3 * j, :3] = B
    p[0, 10, 0] = n
    if rough is not None:
        u = drawing.source_uniforms(rough.source)
        p[0, 11], p[0, 14] = u["texInfo"], u["mixColor"]
        p[0, 12, :3], p[0, 13, :3] = u["texMap0"], u["texMap1"]
    if normal is not None:
        u = drawing.source_uniforms(normal.source)
        p[0, 15] = (1.0 if normal.kind == "NORMAL_MAP" else 2.0, normal.strength,
                    normal.distance, 0.0)
        p[0, 16], p[0, 19] = u["texInfo"], u["mixColor"]
        p[0, 17, :3], p[0, 18, :3] = u["texMap0"], u["texMap1"]
    # rows 1 + 2k + j: lobe j's multiscatter factor over cos_o at roughness node k
    cos_o = np.maximum(np.linspace(0.0, 1.0, TABLE), core_brdf.COS_VIEW_MIN)
    for k in range(n):
        m = material if n == 1 else textures.material_at(material, {"Roughness": k / (n - 1)})
        for j, (kind, *_) in enumerate(lobes):
            which = "metal" if material.fresnel == "DIELECTRIC" and kind == core_brdf.SHARP_F82 \
                else "main"
            p[1 + 2 * k + j, :TABLE, :3] = core_brdf.multiscatter_factor(m, cos_o, which)
    return _texture(p)


def lobe_signature(material) -> tuple:
    """The slot's lobes compiled into its shader (core.shading.microfacet.lobe_signature):
    the distribution, count and kinds :func:`parameters` writes in row 0."""
    kinds = [kind for kind, *_ in core_brdf.sharp_lobes(material)[:2]]
    dist = 0 if material.lobe_distribution == "BECKMANN" else 1
    return microfacet.lobe_signature([(dist, len(kinds), *(kinds + [0, 0])[:2])])


def draws(state, eye, view_dir, background) -> list:
    """``draw(view_projection)`` callables adding the sharp lobes of every object that has
    them (empty when none has).  ``background``: (texture, rotation, strength) of the
    world as the engine draws it (level 0 of the environment)."""
    todo = [(st, slots) for st in state.objects for slots in [sharp_slots(st)] if slots]
    if not todo:
        return []
    shown_tex, rotation, strength = background
    world = state.full_world if state.full_world is not None else state.world
    env_size = (1, 1) if world.image is None else envmap.display_equirect(world.image).shape[:2]
    env_tex, mip_tex, src_tex, src_mip_tex, levels, world_src, count = \
        _environment(state, shown_tex)
    eye4 = ((*map(float, view_dir), 0.0) if view_dir is not None else (*map(float, eye), 1.0))
    out = []
    for st, slots in todo:
        batches = _batches(st, slots)
        if not batches:
            continue
        vis_tex, stride = visibility.texture(st)
        slot_draws = []
        for slot, batch in batches:
            rough = texture_export.shader_inputs(st, slot).get("Roughness")
            mapped = texture_export.shader_normal(st, slot)
            features = (("ROUGH_TEX",) if rough is not None else ()) + \
                (("NORMAL_MAP",) if mapped is not None else ()) + \
                lobe_signature(st.materials[slot])
            textures_ = [drawing.albedo_texture(got[0].source.texture.pixels)
                         if got is not None else drawing.white_texture()
                         for got in (rough, mapped)]
            params = parameters(st.materials[slot], eye4, env_size, levels, float(strength),
                                state.resolution, stride, rough and rough[0],
                                mapped and mapped[0], count)
            slot_draws.append((batch, params, features, textures_))

        def draw(view_projection, slot_draws=slot_draws, vis_tex=vis_tex,
                 side=float(st.closed_side)):
            for batch, params, features, (rough_tex, normal_tex) in slot_draws:
                sh = _shader(features)
                sh.bind()
                sh.uniform_float("viewProjection", view_projection)
                sh.uniform_float("envRot", rotation)
                sh.uniform_float("closedSide", side)
                sh.uniform_sampler("envTex", env_tex)
                sh.uniform_sampler("mipTex", mip_tex)
                sh.uniform_sampler("sourcesTex", src_tex)
                sh.uniform_sampler("sourcesMipTex", src_mip_tex)
                sh.uniform_sampler("worldSrcTex", world_src)
                sh.uniform_sampler("visTex", vis_tex)
                sh.uniform_sampler("paramTex", params)
                sh.uniform_sampler("roughTex", rough_tex)
                sh.uniform_sampler("normalTex", normal_tex)
                batch.draw(sh)

        out.append(draw)
    return out
