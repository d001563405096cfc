"""Compact light sources drawn per pixel for every method.

The world's few compact, bright sources (a sun, softboxes, windows: :func:`core.sphere.sources.
extract_sources`) are split off the environment; every method shades the smooth residual
from its precomputed transfer, and this pass adds the sources per pixel
(``shaders/passes/lights_*.glsl``), each with its own shadow map filtered to its angular size.
Blender's sun lamps go through the same path.  The sources are found in the image's
texture space, so turning the world (a Mapping rotation) moves them with no new
extraction; the shadow maps follow.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ...core.shading import brdf as core_brdf, microfacet
from ...core.shading.materials import Material
from ...core.scene import mesh as core_mesh
from ...core.scene import textures
from . import drawing, light_tiles, shaders, shadow_maps
from ..blender import texture_export
from ..frame import keys
from ..frame.sources import lamp_sources, shadow_plan

#: view-cosine nodes of the per-material tables (lights_frag.glsl table)
TABLE_NODES = 32

BATCHES = drawing.gpu_cache({})
#: texels per source in srcTex (lights_frag.glsl's layout)
SOURCE_TEXELS = 36
#: srcTex row 0's texel of the light groups' counts (distant, point and spot, area)
COUNT_TEXEL = 35


# --------------------------------------------------------------------------- shaders

#: every optional feature of lights_frag.glsl (a #define each; shaders.SPECS["lights"])
FEATURES = shaders.SPECS["lights"].switches


def _shader(features=FEATURES):
    """The pass compiled with ``features`` (lights_frag.glsl: what a draw lacks is left
    out of its shader, not branched around)."""
    return shaders.shader("lights", features)


def slot_features(params: np.ndarray, albedo_source) -> tuple:
    """The per-slot features of a slot's paramTex rows (:func:`slot_texels`) and textured
    colour source."""
    out = []
    if params[0, 1, 2] > 0 and params[0, 1, 3] > 0.5:
        out.append("GLOSSY")
    if params[0, 11, 0] >= 2:
        out.append("ROUGH_TEX")
    if params[0, 16, 0] > 0.5:
        out.append("NORMAL_MAP")
    if albedo_source is not None:
        out.append("ALBEDO_TEX")
    # the lobes of each roughness node the pass mixes (rows 4k + 4), else of row 0
    rows = params[4::4] if "ROUGH_TEX" in out else params[:1]
    out += microfacet.lobe_signature((*p[1, 1:3], p[2, 0], p[5, 0]) for p in rows)
    return tuple(out)


#: shadow-map taps per source and sample with one sample per pixel: the blocker search's and
#: the filter's (lights_frag.glsl's PCF_TAPS unless a frame defines fewer)
BLOCKER_TAPS, FILTER_TAPS = 16, 24
#: glossy samples per source on the disc and of the NDF with one sample per pixel
#: (lights_frag.glsl's NL and NB; fewer per sample with several, as the filter's taps)
LOBE_SAMPLES = 8


def frame_features(sources, supersampling: int = 1) -> tuple:
    """The per-frame features: local lamps (point, spot) and area lamps, and with
    ``supersampling`` s > 1 fewer filter taps and glossy samples per sample: a pixel's s²
    samples turn their patterns differently, so n / s per sample still give each pixel s
    times those of one sample per pixel.  The blocker search keeps its taps: fewer miss blockers, a bias
    the pixel's average does not remove."""
    s = max(1, int(supersampling))
    out = [] if s == 1 else [f"PCF_TAPS {max(4, -(-FILTER_TAPS // s))}",
                             f"LOBE_TAPS {max(2, -(-LOBE_SAMPLES // s))}"]
    if any(s.local and s.area is None for s in sources):
        out.append("LOCAL_LAMPS")
    if any(s.area is not None for s in sources):
        out.append("AREA_LAMPS")
    if len(sources) >= light_tiles.TILED_FROM:
        out.append("LIGHT_TILES")
    return tuple(out)


def _surface_batch(pos, nrm, uv, attr, tng, triangles):
    """A batch of the pass's vertex layout (any feature set's shader draws it): per face
    corner its values, ``triangles`` (T, 3) indexing them."""
    import gpu
    vbo = drawing.vertex_buffer((("pos", pos), ("nrm", nrm), ("uv", uv), ("attr", attr), ("tng", tng)))
    return gpu.types.GPUBatch(type="TRIS", buf=vbo, elem=_index_buffer(triangles))


def _depth_shader():
    return shaders.shader("shadow_depth")


def _index_buffer(triangles):
    """The pass's own index buffers (the surface pass's shared ones: drawing.index_buffer)."""
    import gpu
    return gpu.types.GPUIndexBuf(type="TRIS", seq=np.ascontiguousarray(triangles, np.int32))


# --------------------------------------------------------------------------- geometry

def _object_batches(st):
    """(depth batch, [(slot, surface batch)], model matrix) of one object, cached per
    geometry.  An instance placed from its source's arrays as they are, with no per-corner
    texture data (:func:`draws_shared`), draws its source's shared batches: the depth batch in
    object space with its world matrix as the model matrix, the surface batches with only
    their positions its own (its world positions, as every other pass draws them, so the
    pass's depth test EQUAL holds) and its source's normals turned by its normal matrix.
    The others' batches are in world space (model: the identity)."""
    if not draws_shared(st):
        key = (st.name, st.fingerprint, tuple(sorted((slot, id(values)) for slot, (_, values)
                                                     in st.textures.items())),
               tuple(sorted((slot, id(got[2])) for slot, got in st.normals.items())),
               tuple(sorted((slot, id(v)) for slot, got in st.inputs[0].items()
                            for _, v in got.values())))
        return (*keys.held(BATCHES, key, (), lambda: build_batches(st, st.arrays)), _IDENTITY)
    depth, shared = keys.held(BATCHES, ("source", st.source[0]), (),
                              lambda: _source_batches(st))

    def own():
        import gpu
        positions = st.arrays.positions
        out = []
        for slot, vertex, vbo, ibo in shared:
            batch = gpu.types.GPUBatch(type="TRIS", buf=drawing.vertex_buffer((("pos",
                                                                         positions[vertex]),)),
                                       elem=ibo)
            batch.vertbuf_add(vbo)
            out.append((slot, batch))
        return out
    return depth, keys.held(BATCHES, (st.name, st.fingerprint, "placed"), (), own), \
        np.asarray(st.matrix, np.float64)


_IDENTITY = np.eye(4)


def draws_shared(st) -> bool:
    """Whether ``st`` draws its source's shared batches: an instance placed from its
    source's arrays as they are, with no per-corner texture data (UVs, colours, tangents),
    by a matrix that keeps its volume (a flattened one's normals are repaired per instance,
    as sync repairs them: its own batches carry them)."""
    if st.source is None or st.textures or st.normals or st.inputs[0]:
        return False
    A = np.asarray(st.matrix, np.float64)[:3, :3]
    return abs(np.linalg.det(A)) > 1e-6 * max(float(np.abs(A).max()), 1e-30) ** 3


def _corner_layout(arrays):
    """What both kinds of batches are made of: the face corners' positions (C, 3) float32, the
    depth batch, and per slot (slot, the face corners of its triangles, each once, and the
    triangles indexing them)."""
    from gpu_extras.batch import batch_for_shader
    tri = arrays.triangles
    corner_pos = arrays.positions[arrays.corner_verts].astype(np.float32)
    depth = batch_for_shader(_depth_shader(), "TRIS", {"pos": np.ascontiguousarray(corner_pos)},
                             indices=np.ascontiguousarray(tri, dtype=np.int32))
    tri_slot = arrays.corner_materials[tri[:, 0]]
    slots = []
    for slot in np.unique(tri_slot):
        corner, index = np.unique(tri[tri_slot == slot], return_inverse=True)
        slots.append((int(slot), corner, index.reshape(-1, 3)))
    return corner_pos, depth, slots


def _source_batches(st):
    """An instance's source's shared batches: (depth batch in object space, per slot (slot,
    the vertex of each of its shading points, their vertex buffer of normals and constant
    texture data, index buffer)).  One vertex per shading point (the corners of one vertex
    with one normal are one point): an instance's own buffer of positions is a quarter of
    one per corner on a smooth mesh."""
    # the source's normals repaired as sync repairs each instance's (a copy: the arrays are
    # the instances')
    arrays = replace(st.source[1], corner_normals=st.source[1].corner_normals.copy())
    core_mesh.repair_normals(arrays)
    depth = _corner_layout(arrays)[1]
    points = core_mesh.shading_points(arrays)
    vertex_of_point = arrays.corner_verts[core_mesh.point_corners(points)]
    tri = points.point_of_corner[arrays.triangles]
    tri_slot = points.materials[tri[:, 0]]
    out = []
    for slot in np.unique(tri_slot):
        point, index = np.unique(tri[tri_slot == slot], return_inverse=True)
        n = len(point)
        vbo = drawing.vertex_buffer((("nrm", points.normals[point]),
                              ("uv", np.zeros((n, 2))), ("attr", np.ones((n, 4))),
                              ("tng", np.zeros((n, 4)))))
        out.append((int(slot), vertex_of_point[point], vbo, _index_buffer(index.reshape(-1, 3))))
    return depth, out


def build_batches(st, arrays):
    """(depth batch, [(slot, surface batch)]) of ``arrays`` (``st``'s), with ``st``'s
    per-corner texture data."""
    corner_pos, depth, slots = _corner_layout(arrays)
    surfaces = []
    for slot, corner, index in slots:
        n = len(corner)
        uv = np.zeros((n, 2), np.float32)
        attr = np.ones((n, 4), np.float32)
        source, values = st.textures.get(slot, (None, None))
        uvs = texture_export.slot_uvs(st, slot)
        if uvs is not None:
            uv[:] = uvs[1][corner]
        if source is not None and source.texture is None:
            attr[:] = values[corner]
        tng = np.zeros((n, 4), np.float32)
        mapped = texture_export.shader_normal(st, slot)
        if mapped is not None:
            tng[:] = mapped[1][corner]
        surfaces.append((slot, _surface_batch(corner_pos[corner], arrays.corner_normals[corner],
                                              uv, attr, tng, index)))
    return depth, surfaces


def normal_texels(model) -> np.ndarray:
    """(3, 4) float32: the rows of ``model``'s normal matrix (core.scene.mesh.normal_matrix),
    as the PLACED vertex stage reads them (paramTex row 0, texels 21-23)."""
    out = np.zeros((3, 4), np.float32)
    out[:, :3] = core_mesh.normal_matrix(model)
    return out


# --------------------------------------------------------------------------- parameters

#: roughness nodes of a slot whose Roughness is textured (values i / (n - 1))
ROUGHNESS_NODES = 17


def slot_texels(st, slot, eye4) -> np.ndarray:
    """The paramTex rows of one material slot: :func:`material_texels` of its material,
    and with a textured Roughness (on the batch's UV map) the same rows at each of
    :data:`ROUGHNESS_NODES` below them, with the roughness source in row 0 (texels 11-15,
    lights_frag.glsl)."""
    material = st.materials[slot] if 0 <= slot < len(st.materials) else Material()
    p = material_texels(material, eye4, st.closed_side)
    mapped = texture_export.shader_normal(st, slot)
    if mapped is not None:                  # texels 16-20: the normal or bump map
        src = mapped[0]
        u = drawing.source_uniforms(src.source)
        p[0, 16] = (1.0 if src.kind == "NORMAL_MAP" else 2.0, src.strength, src.distance, 0.0)
        p[0, 17], p[0, 20] = u["texInfo"], u["mixColor"]
        p[0, 18, :3], p[0, 19, :3] = u["texMap0"], u["texMap1"]
    got = texture_export.shader_inputs(st, slot).get("Roughness")
    if got is None:
        return p
    n = ROUGHNESS_NODES
    nodes = [material_texels(textures.material_at(material, {"Roughness": i / (n - 1)}),
                             eye4, st.closed_side) for i in range(n)]
    u = drawing.source_uniforms(got[0].source)
    p[0, 11] = (n, core_brdf.MICROFACET_ALPHA_MIN, 0.0, 0.0)
    p[0, 12], p[0, 15] = u["texInfo"], u["mixColor"]
    p[0, 13, :3], p[0, 14, :3] = u["texMap0"], u["texMap1"]
    return np.concatenate([p] + nodes, axis=0)


# paramTex rows per (material, eye, closed side): a frame's pilot and its samples, and the
# frames after an HDRI turn, draw the same (a textured roughness has 17 materials per slot)
_MATERIAL_TEXELS = keys.cache(256)


def material_texels(material, eye4, closed_side=0) -> np.ndarray:
    """The paramTex rows of one material slot of an object (layout in lights_frag.glsl):
    a new array (the caller writes into it)."""
    key = (material, tuple(float(v) for v in eye4), float(closed_side))
    got = _MATERIAL_TEXELS.get(key)
    if got is None:
        got = _MATERIAL_TEXELS[key] = _material_texels(material, eye4, closed_side)
    return got.copy()


def _material_texels(material, eye4, closed_side) -> np.ndarray:
    p = np.zeros((4, max(TABLE_NODES, 10), 4), np.float32)
    p[0, 9, 0] = closed_side
    if material.has_diffuse:
        p[0, 0, :3] = np.asarray(material.diffuse_albedo) / math.pi
        p[0, 0, 3] = 1.0
    # a slot whose lobes the sharp pass draws: its lamps are drawn here, the World's compact
    # sources where the lobe is narrower than the pixel's footprint (lights_frag.glsl)
    p[0, 9, 1] = 1.0 if material.per_pixel_lobe else 0.0
    material = replace(material, per_pixel_lobe=False)
    lobes = [] if material.is_diffuse_only else core_brdf.sharp_lobes(material)
    r = material.table_roughness
    p[0, 1] = (max(r * r, core_brdf.MICROFACET_ALPHA_MIN),
               0.0 if material.lobe_distribution == "BECKMANN" else 1.0, len(lobes),
               1.0 if lobes else 0.0)
    for j, (kind, weight, f0, B, eta) in enumerate(lobes[:2]):
        p[0, 2 + 3 * j] = (kind, weight, eta, 0.0)
        p[0, 3 + 3 * j, :3] = f0
        p[0, 4 + 3 * j, :3] = B
    p[0, 8] = eye4
    mu = np.linspace(0.0, 1.0, TABLE_NODES)
    views = np.stack([np.sqrt(np.maximum(1.0 - mu * mu, 0.0)), np.zeros(TABLE_NODES), mu],
                     axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (TABLE_NODES, 1))
    p[1, :TABLE_NODES, :3] = core_brdf.diffuse_view_weight(material, normals, views)
    p[1, :TABLE_NODES, 3] = 1.0
    cos_o = np.maximum(mu, core_brdf.COS_VIEW_MIN)
    which = ["metal" if (material.fresnel == "DIELECTRIC" and kind == core_brdf.SHARP_F82)
             else "main" for kind, *_ in lobes[:2]]
    for j, w in enumerate(which):
        p[2 + j, :TABLE_NODES, :3] = core_brdf.multiscatter_factor(material, cos_o, w)
    return p


def _input_texture(st, slot):
    """The GPU texture of a slot's textured Roughness (white without one)."""
    got = texture_export.shader_inputs(st, slot).get("Roughness")
    return drawing.albedo_texture(got[0].source.texture.pixels) if got is not None \
        else drawing.white_texture()


def _normal_texture(st, slot):
    """The GPU texture of a slot's normal or bump map (white without one)."""
    mapped = texture_export.shader_normal(st, slot)
    return drawing.albedo_texture(mapped[0].source.texture.pixels) if mapped is not None \
        else drawing.white_texture()


def _texture(rgba):
    return drawing.float_texture(np.ascontiguousarray(rgba, dtype=np.float32))


def draws(state, eye, view_dir, supersampling: int, pilot: int) -> tuple[list, list]:
    """``(draws, pilot's draws)``: ``draw(view_projection)`` callables adding every source to
    the objects (empty when there is none), for a frame of ``supersampling``² samples per
    pixel and for adaptive anti-aliasing's pilot frame of ``pilot``², both drawing the same
    batches (a thousand instances' batches are made once per frame).  Renders the sources'
    shadow maps first (cached)."""
    sources = list(state.sources) + lamp_sources(state.drawn_lamps)
    casters = [st for st in state.objects if st.status != "unshadowed"]
    if not sources or not state.objects:
        return [], []
    # every source is drawn, each with its shadow map unless the plan's budget says not
    plan = shadow_plan(sources)
    distant = [s for s in sources if not s.local]
    local = [s for s in sources if s.local]
    depth = [(got[0], None if got[2] is _IDENTITY else got[2])        # (batch, model)
             for got in map(_object_batches, casters)]
    mapped = distant[:plan.distant_shadowed]
    shadow_tex, tiles = shadow_maps.distant_atlas(mapped, casters, depth, plan.distant_tile) \
        if mapped else (drawing.white_texture(), [])
    cube_tex, cubes = shadow_maps.cube_atlas(local, plan.faces, casters, depth,
                                             plan.face_tile) \
        if any(any(f) for f in plan.faces) else (drawing.white_texture(), [])
    src = np.zeros((len(sources), SOURCE_TEXELS, 4), np.float32)
    in_world = len(state.sources)           # the World's sources come first, all distant
    # srcTex's rows by group (lights_frag.glsl loops over each with its own code): the
    # distant sources, then the point and spot lamps, then the area lamps
    lamps = [j for j, s in enumerate(local) if s.area is None]
    areas = [j for j, s in enumerate(local) if s.area is not None]
    rows, groups = lamps + areas, (len(distant), len(lamps), len(areas))
    src[0, COUNT_TEXEL, :3] = groups
    for k, s in enumerate(distant):
        src[k, 0] = (*s.direction, s.radius)
        src[k, 1] = (*s.radiance, 1.0 if s.point_like else 0.0)
        src[k, 8, 0] = 1.0 if k < in_world else 0.0
        if k < len(tiles):                      # else tile size 0: no shadow
            M, tile, depth_range, texel = tiles[k]
            src[k, 2:6] = M.T                   # columns of the matrix (GLSL mat4 order)
            src[k, 6] = (*tile, depth_range)
            src[k, 7] = (texel, *(M[0, :3] / np.linalg.norm(M[0, :3])))   # the map's x axis
    for row, j in enumerate(rows):
        s, k = local[j], len(distant) + row
        src[k, 0] = (*s.position, s.radius)
        src[k, 1] = (*s.radiance, 2.0 if s.spot is None else 3.0)
        if s.area is not None:
            half_x, half_y, ellipse = s.area
            src[k, 1, 3] = 5.0 if ellipse else 4.0
            src[k, 2, :3] = s.direction
            src[k, 4, :3] = half_x
            src[k, 5, :3] = half_y
        elif s.spot is not None:
            axis, cos_half, smooth = s.spot
            src[k, 2] = (*axis, cos_half)
            src[k, 3, 0] = smooth
        if any(plan.faces[j]):                  # else face size 0: no shadow
            origins, mats = cubes[j]
            src[k, 6, 2] = plan.face_tile
            for face, M in enumerate(mats):
                src[k, 8 + 4 * face:12 + 4 * face] = M.T
            src[k, 32:35] = np.asarray(origins, np.float32).reshape(3, 4)
    src_tex = _texture(src)
    eye4 = ((*map(float, view_dir), 0.0) if view_dir is not None else (*map(float, eye), 1.0))
    objects = []                    # per object, per slot: (batch, textures, slot features)
    for st in state.objects:
        slots = []
        _depth, surfaces, model = _object_batches(st)
        for slot, batch in surfaces:
            texels = slot_texels(st, slot, eye4)
            source = st.textures.get(slot, (None, None))[0]
            features = slot_features(texels, source)
            if model is not _IDENTITY:           # row 0, texels 21-23 (lights_vert.glsl)
                texels[0, 21:24] = normal_texels(model)
                features += ("PLACED",)
            slots.append((batch, _texture(texels), source, _input_texture(st, slot),
                          _normal_texture(st, slot), features))
        objects.append(slots)
    textures = (src_tex, shadow_tex, cube_tex)
    ordered = distant + [local[j] for j in rows]          # as srcTex holds them
    return (_frame_draws(state, ordered, groups, objects, textures, supersampling),
            _frame_draws(state, ordered, groups, objects, textures, pilot))


def _frame_draws(state, sources, groups, objects, textures, supersampling) -> list:
    """The draw callables of :func:`draws`' ``objects`` for a frame of ``supersampling``²
    samples per pixel (``sources`` in srcTex's order, ``groups`` its light groups' counts:
    the light tiles index them)."""
    src_tex, shadow_tex, cube_tex = textures
    tile_tex = _tile_texture(state, sources, groups, supersampling)
    per_frame = frame_features(sources, supersampling)
    out = []
    for object_slots in objects:
        slots = [(batch, params, source, rough, bump, features + per_frame)
                 for batch, params, source, rough, bump, features in object_slots]

        def draw(view_projection, slots=slots):
            for batch, params, source, rough, bump, features in slots:
                sh = _shader(features)
                sh.bind()
                sh.uniform_float("viewProjection", view_projection)
                sh.uniform_sampler("srcTex", src_tex)
                sh.uniform_sampler("shadowTex", shadow_tex)
                sh.uniform_sampler("cubeTex", cube_tex)
                sh.uniform_sampler("paramTex", params)
                if source is not None:         # the push constants only ALBEDO_TEX reads
                    for name, value in drawing.source_uniforms(source).items():
                        sh.uniform_float(name, value)
                    sh.uniform_sampler("albedoTex",
                                       drawing.albedo_texture(source.texture.pixels)
                                       if source.texture is not None
                                       else drawing.white_texture())
                sh.uniform_sampler("roughTex", rough)
                sh.uniform_sampler("normalTex", bump)
                sh.uniform_sampler("tileTex", tile_tex(view_projection))
                batch.draw(sh)

        out.append(draw)
    return out


def _tile_texture(state, sources, groups, supersampling):
    """``tiles(view_projection)``: the LIGHT_TILES texture of the frame's view (made once per
    view and viewport, shared by every object's draw); a white texture with few lights."""
    if "LIGHT_TILES" not in frame_features(sources, supersampling):
        white = drawing.white_texture()
        return lambda view_projection: white
    box = core_mesh.bounds([st.arrays for st in state.objects])
    lo, hi = box if len(box) else (np.zeros(3), np.zeros(3))
    boxes = light_tiles.influence_boxes(sources, lo, hi)
    made = {}

    def tiles(view_projection):
        import gpu
        x, y, w, h = gpu.state.viewport_get()
        M = np.array(view_projection, np.float64)
        key = (M.round(9).tobytes(), x, y, w, h)
        if key not in made:
            made.clear()
            rects = light_tiles.screen_rects(boxes, M, w, h)
            made[key] = _texture(light_tiles.tile_table(rects, w, h, groups, origin=(x, y)))
        return made[key]
    return tiles
