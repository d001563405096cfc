"""SSDF_SG per pixel on the GPU (``shaders/methods/ssdf_sg_*.glsl``): the shaders, the textures of
the SSDFs, lighting and materials, the per-slot batches and the pair table of flat
triangles (eq. 39's per-pair SSDF angles, weights and slopes per point, since those are
exactly linear inside a flat triangle: :func:`pair_table`).  The numerics they mirror are
in ``core/methods/ssdf_sg/shading.py`` and ``core/methods/ssdf_sg/scene.py``; the method is ``ssdf_sg.py``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ....core.sg import brdf as sg_brdf
from ....core.sg import albedo
from ....core.sg import ggx_warp
from ....core.shading.materials import slot_material
from ....core.methods.ssdf_sg.scene import cosine_amplitudes, diffuse_slots, flat_triangles, is_glossy, sg_materials
from ...gpu import drawing, shaders
from ...frame import keys
from ...blender.texture_export import shader_inputs, shader_normal, slot_uvs

# the pair pass's "quad", the prefiltered environment's "atlas" (per pyramid) and the
# light-lobe texture per cosine lobe count
_GPU = drawing.gpu_cache({}, limit=8)
# (coefficient texture, eigen-image texture array, texels per point) per field
_FIELD_TEXTURES = drawing.gpu_cache({}, limit=64)
# per-slot batches of an object (ObjectBatches) per (object, geometry, flat or not)
_BATCHES = drawing.gpu_cache({}, limit=64)
# pair tables per (object, geometry, lighting): entries hold the field and the fit
PAIR_TABLES = drawing.gpu_cache({}, limit=8)


#: the main pass's textured input samplers, in :data:`INPUTS` order and the normal map's last
_INPUT_SAMPLERS = tuple(name for _, name in shaders.SPECS["ssdf_sg"].samplers[5:])


def _gpu_shader(flat: bool = False):
    """The per-pixel shader; ``flat``: its variant for flat triangles (FLAT_PAIRS: eq. 39
    from the pair table, see :func:`pair_table`)."""
    return shaders.shader("ssdf_sg_flat" if flat else "ssdf_sg")


def _pairs_shader():
    """The pair pass (``shaders/methods/ssdf_sg_pairs_frag.glsl``) over a full-screen
    triangle."""
    return shaders.shader("ssdf_sg_pairs")


def _texture(rgba, layers=0):
    import gpu
    flat = np.ascontiguousarray(rgba, dtype=np.float32).reshape(-1)
    buf = gpu.types.Buffer("FLOAT", flat.size, flat)
    if layers:
        h, w = rgba.shape[1:3]
        return gpu.types.GPUTexture((w, h), layers=layers, format="RGBA32F", data=buf)
    h, w = rgba.shape[:2]
    return gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)


def field_textures(field):
    """(coefficient texture, eigen-image array, texels per point) of a StoredField."""
    return keys.held(_FIELD_TEXTURES, id(field), (field,), lambda: _field_textures(field))


def _field_textures(field):
    K, D, n = field.terms, field.resolution ** 2, field.resolution
    kt = -(-(K + 1) // 4)
    weights = np.zeros((len(field.coefficients), kt * 4), np.float32)
    weights[:, 0] = 1.0
    weights[:, 1:K + 1] = field.coefficients
    total = len(weights) * kt
    rows = max(1, -(-total // drawing.ROW_TEXELS))
    data = np.zeros((rows * drawing.ROW_TEXELS, 4), np.float32)
    data[:total] = weights.reshape(-1, 4)
    images = np.zeros((kt * 4, D), np.float32)
    images[0] = field.mean
    images[1:K + 1] = field.eigen
    layers = images.reshape(kt, 4, n, n).transpose(0, 2, 3, 1)          # (kt, n, n, 4)
    return (_texture(data.reshape(rows, drawing.ROW_TEXELS, 4)), _texture(layers, layers=kt), kt)


def environment_textures(fit, pre, cosine_lobes: int):
    """(prefiltered atlas texture, light-lobe texture, lobe count): the atlas is made
    once per pyramid, the small lobe texture per fit (a turned world re-solves the
    scene-fitted amplitudes, the pyramid stays).  Lobe texture row j: texel 0 = (axis,
    lam), texel 1 + m = the amplitude seen by cosine lobe m."""
    atlas = keys.held(_GPU, "atlas", (pre,), lambda: _texture(pre.atlas()))

    def lights():
        axes, lam, mu = fit[:3]
        J = max(len(lam), 1)
        light = np.zeros((J, 1 + cosine_lobes, 4), np.float32)
        light[:len(lam), 0, :3] = axes
        light[:len(lam), 0, 3] = lam
        if len(lam):
            light[:len(lam), 1:, :3] = cosine_amplitudes(mu, cosine_lobes).transpose(1, 0, 2)
        return _texture(light)
    return atlas, keys.held(_GPU, ("lights", cosine_lobes), (fit,), lights), len(fit[1])


def material_uniforms(material):
    """Push-constant values of one material slot (the CPU half of specular_lobes)."""
    m = sg_materials([material])[0]
    kd = np.asarray(albedo.diffuse_albedo(m), np.float64).reshape(3) / np.pi
    lam, mu = (np.asarray(x, np.float64).reshape(-1) for x in
               sg_brdf.iso_ndf_lobes(m.model, float(np.asarray(m.roughness).reshape(-1)[0])))
    A, Bd, Bs = (np.asarray(x, np.float64).reshape(3) for x in sg_brdf.fresnel_coefficients(m))
    glossy = is_glossy(m)
    model = {"COOK_TORRANCE": 0, "BLINN_PHONG": 0, "WARD": 1, "GGX": 3}.get(m.model, 2)
    # GGX: E(r, mu) on Cycles' 32 mu nodes and E_avg (the lobes' normalisation and the
    # multiscatter factor), the metal part of A and the two F_ss (linear in the base colour;
    # the shader makes F_ms of them, core.sg.brdf.multiscatter_factors)
    E, e_avg, am, fss = np.ones(GGX_E_NODES), np.ones(1), np.zeros(3), np.zeros((2, 3))
    warp = np.zeros((len(ggx_warp.WARP_MU), 3 * ggx_warp.GGX_WARP_LOBES))
    if m.model == "GGX":
        E, e_avg = albedo.ggx_albedo(m, np.linspace(0.0, 1.0, GGX_E_NODES), GGX_E_NODES)
        r = math.sqrt(min(max(float(np.asarray(m.roughness).reshape(-1)[0]), 0.0), 1.0))
        warp = ggx_warp.ggx_warp_params(r, ggx_warp.WARP_MU)
        if m.multiscatter:
            fss = np.array([f[0] for f in albedo.multiscatter_fss(m, 1)])
        if m.fresnel == "PRINCIPLED":
            am = float(np.asarray(m.metallic).reshape(-1)[0]) * np.clip(
                np.asarray(m.diffuse, np.float64).reshape(3), 0.0, 1.0)
    layer = albedo.diffuse_view_ratio(m, np.linspace(0.0, 1.0, GGX_E_NODES))
    return dict(kd=(*kd, 1.0), glossy=int(glossy), brdfModel=model, layerRatio=layer,
                principled=int(m.fresnel == "PRINCIPLED"),
                roughness=float(np.asarray(m.roughness).reshape(-1)[0]),
                ior=float(np.asarray(m.ior).reshape(-1)[0]), ndfLambda=float(lam[0]),
                ndfMu=float(mu[0]),
                fresA=(*A, 0.0), fresBd=(*Bd, 0.0), fresBs=(*Bs, 0.0), ggxE=E,
                ggxEavg=float(e_avg[0]), multiscatter=int(m.multiscatter),
                fresAm=(*am, 0.0), fssMain=(*fss[0], 0.0), fssMetal=(*fss[1], 0.0),
                ggxWarp=warp)


#: row 0 of the parameter texture: the first of four texels per textured input of
#: :data:`INPUTS` (texture.glsl's info, mapping rows, mix colour), the table's (roughness
#: nodes, level nodes, metallic at corners 0 and 1), the normal map's (kind, strength,
#: distance), the first clamped-cosine lobe
INPUT_TEXEL, TABLE_TEXEL, NORMAL_TEXEL, COSINE_TEXEL = 10, 26, 27, 28
#: table nodes over a textured Roughness / Specular IOR Level (values i / (n - 1))
ROUGHNESS_NODES, LEVEL_NODES = 33, 9
#: Cycles' mu nodes of E(r, mu) (core.shading.brdf_tables)
GGX_E_NODES = 32
#: most GGX view-slice lobes an entry holds (core.sg.ggx_warp.GGX_WARP_LOBES or more)
WARP_LOBES_MAX = 4
#: a table entry's GGX texels: (-, -, E_avg, multiscatter), E at the GGX_E_NODES mu nodes (four
#: a texel), then the metal part of A, F_ss main, F_ss metal at the four corners
GGX_TEXEL = 17
#: first texel of the GGX view slice's lobes in an entry (core.sg.ndf.ggx_warp_params at the
#: entry's roughness and the 21 WARP_MU nodes): per node three texels, the tilts, the
#: log-sharpness factors and the shares of up to WARP_LOBES_MAX lobes (zero past K)
WARP_TEXEL = GGX_TEXEL + 1 + GGX_E_NODES // 4 + 3 * 4
#: first texel of the Lambert base's view ratio (core.sg.brdf.diffuse_view_ratio) at the
#: 32 mu nodes of E (8 texels)
LAYER_TEXEL = WARP_TEXEL + 3 * len(ggx_warp.WARP_MU)
#: texels per table entry: (lambda a^2, mu a^2, eta, -), then kd, A, B_d, B_s at the four
#: (base colour, metallic) corners; GGX: (-, -, E_avg, multiscatter), E at
#: the 32 mu nodes (8 texels), then the metal part of A, F_ss main, F_ss metal at the
#: corners; the view slice's lobes; the view ratio
ENTRY_TEXELS = LAYER_TEXEL + GGX_E_NODES // 4
#: the textured inputs a slot's shader reads, in sampler and texel order
INPUTS = ("colour", "Roughness", "Metallic", "Specular IOR Level")


def parameter_texture(env, mat, res, kt, eye4, cosine, table=None, sources=None, normal=None):
    """The parameter texture read by ``read_parameters`` in ssdf_sg_lib.glsl.  Row 0: 9
    scalar texels, (count, sharpness) of the cosine lobes, four texels per textured input
    of :data:`INPUTS` (``sources``, core.scene.textures.ColorSource or None: lib/texture.glsl's
    info, mapping rows, mix colour) from :data:`INPUT_TEXEL`, the table's (roughness nodes,
    level nodes, metallic at corner 0 and 1) at :data:`TABLE_TEXEL`, (local direction,
    amplitude) per cosine lobe from :data:`COSINE_TEXEL`.  Rows 1..: ``table``
    (:func:`slot_table`), one row per Specular IOR Level node.  ``normal``: a
    core.scene.textures.NormalSource drawn per pixel (:data:`NORMAL_TEXEL`: kind, strength,
    distance; its image's four texels after the cosine lobes)."""
    M = len(cosine.amplitudes)
    table = _slot_table_of(mat) if table is None else table
    nl, nr = table["entries"].shape[:2]
    width = max(COSINE_TEXEL + M + 4, nr * ENTRY_TEXELS)
    p = np.zeros((1 + nl, width, 4), np.float32)
    p[0, 8] = eye4
    p[0, 9] = (M, cosine.sharpness, 0.0, 0.0)
    p[0, COSINE_TEXEL:COSINE_TEXEL + M, :3] = cosine.directions
    p[0, COSINE_TEXEL:COSINE_TEXEL + M, 3] = cosine.amplitudes
    p[0, 0] = (env["envStrength"], env["lightCount"], res, kt)
    p[0, 1] = (env["envRes"], env["envLevels"], env["envLambdaFirst"], env["envRatio"])
    p[0, 2] = (env["envTop"], mat["glossy"], mat["brdfModel"], mat["principled"])
    p[0, 3] = (mat["roughness"], mat["ior"], mat["ndfLambda"], mat["ndfMu"])
    p[0, 4], p[0, 5], p[0, 6], p[0, 7] = mat["kd"], mat["fresA"], mat["fresBd"], mat["fresBs"]
    for k, name in enumerate(INPUTS):
        tex = drawing.source_uniforms((sources or {}).get(name))
        i = INPUT_TEXEL + 4 * k
        p[0, i] = tex["texInfo"]
        p[0, i + 1, :3], p[0, i + 2, :3] = tex["texMap0"], tex["texMap1"]
        p[0, i + 3] = tex["mixColor"]
    p[0, TABLE_TEXEL] = (nr, nl, *table["metallic"])
    if normal is not None:
        tex = drawing.source_uniforms(normal.source)
        p[0, NORMAL_TEXEL] = (1.0 if normal.kind == "NORMAL_MAP" else 2.0, normal.strength,
                              normal.distance, 0.0)
        k = COSINE_TEXEL + M
        p[0, k], p[0, k + 3] = tex["texInfo"], tex["mixColor"]
        p[0, k + 1, :3], p[0, k + 2, :3] = tex["texMap0"], tex["texMap1"]
    p[1:, :nr * ENTRY_TEXELS] = table["entries"].reshape(nl, nr * ENTRY_TEXELS, 4)
    return _texture(p)


def _entry(uniforms, alpha):
    """One table entry's texels from four corners' :func:`material_uniforms`."""
    e = np.zeros((ENTRY_TEXELS, 4), np.float32)
    u = uniforms[0]
    e[0] = (u["ndfLambda"] * alpha * alpha, u["ndfMu"] * alpha * alpha, u["ior"], 0.0)
    for c, v in enumerate(uniforms):
        e[1 + 4 * c:5 + 4 * c] = (v["kd"], v["fresA"], v["fresBd"], v["fresBs"])
    e[GGX_TEXEL] = (0.0, 0.0, u["ggxEavg"], u["multiscatter"])
    e[GGX_TEXEL + 1:GGX_TEXEL + 1 + GGX_E_NODES // 4] = np.asarray(u["ggxE"]).reshape(-1, 4)
    k = GGX_TEXEL + 1 + GGX_E_NODES // 4
    for c, v in enumerate(uniforms):
        e[k + 3 * c:k + 3 * c + 3] = (v["fresAm"], v["fssMain"], v["fssMetal"])
    w = np.asarray(u["ggxWarp"], np.float32)
    K = w.shape[1] // 3
    node = np.zeros((len(w), 3, WARP_LOBES_MAX), np.float32)
    node[:, :, :K] = w.reshape(len(w), 3, K)              # (d_k), (l_k), (f_k)
    e[WARP_TEXEL:WARP_TEXEL + 3 * len(w)] = node.reshape(-1, 4)
    e[LAYER_TEXEL:LAYER_TEXEL + GGX_E_NODES // 4] = np.asarray(u["layerRatio"]).reshape(-1, 4)
    return e


def _slot_table_of(uniforms):
    """The one-entry table of a slot without textured inputs."""
    a = max(uniforms["roughness"], 1e-30)
    return {"entries": _entry([uniforms] * 4, a)[None, None], "metallic": (0.0, 0.0)}


def slot_table(material, colour: bool, inputs, principled):
    """The per-slot table of the shader's textured inputs: entries over the Roughness
    nodes (``inputs`` has it) and Specular IOR Level nodes, each with kd and the Fresnel
    terms at the (base colour, metallic) corners: base colour 1 and 0 when ``colour`` is
    textured (else the slot's own), metallic 0 and 1 when textured (else the slot's own).
    Those terms are bilinear in (base colour, metallic); roughness and level are
    interpolated between nodes (NDF lobe as lambda a^2 and mu a^2, exact in a)."""
    from ....core.scene import textures
    nr = ROUGHNESS_NODES if "Roughness" in inputs else 1
    nl = LEVEL_NODES if "Specular IOR Level" in inputs and principled else 1
    metal = (0.0, 1.0) if "Metallic" in inputs else (material.metallic,) * 2
    entries = np.zeros((nl, nr, ENTRY_TEXELS, 4), np.float32)
    for j in range(nl):
        for i in range(nr):
            vals = {}
            if nr > 1:
                vals["Roughness"] = i / (nr - 1)
            if nl > 1:
                vals["Specular IOR Level"] = j / (nl - 1)
            corners = []
            for m in metal[::-1]:               # corner 2 m_index + c_index: m 1 first
                for c in (1.0, 0.0):
                    base = (c, c, c) if colour else material.diffuse_albedo
                    got = textures.material_at(replace(material, diffuse_albedo=base),
                                               dict(vals, Metallic=m), principled)
                    corners.append(material_uniforms(got))
            entries[j, i] = _entry(corners[::-1], max(corners[0]["roughness"], 1e-30))
    return {"entries": entries, "metallic": metal}


# per slot: (material, inputs) -> its table (a few ms each once the BRDF tables are made)
_TABLES = drawing.gpu_cache({}, limit=64)


def slot_parameters(env, st, table, slot, res, kt, eye4, cosine):
    """:func:`parameter_texture` of one material slot, with its textured inputs
    (``st.textures``, :func:`shader_inputs`) and their table."""
    source = st.textures.get(slot, (None, None))[0]
    constants = st.inputs[1]
    inputs = shader_inputs(st, slot)
    own = slot >= len(st.materials) or slot in st.data.get("sg_own", {})
    mat = material_uniforms(slot_material(table, slot))
    mapped = shader_normal(st, slot)
    normal = mapped[0] if mapped is not None else None
    if own or (source is None and not inputs):
        return parameter_texture(env, mat, res, kt, eye4, cosine, normal=normal)
    material = st.materials[slot]
    key = (repr(material), source is not None, tuple(sorted(inputs)))
    tab = keys.held(_TABLES, key, (), lambda: slot_table(
        material, source is not None, inputs, constants.get(slot)))
    sources = {"colour": source, **{name: s.source for name, (s, _) in inputs.items()}}
    return parameter_texture(env, mat, res, kt, eye4, cosine, tab, sources, normal)


def input_textures(st, slot):
    """The GPU textures of a slot's textured inputs (:data:`INPUTS`, then its normal or bump
    map; white without one)."""
    scalars = shader_inputs(st, slot)
    mapped = shader_normal(st, slot)
    sources = [st.textures.get(slot, (None, None))[0]] + [
        scalars[name][0].source if name in scalars else None for name in INPUTS[1:]] + [
        mapped[0].source if mapped is not None else None]
    return [drawing.albedo_texture(s.texture.pixels) if s is not None and s.texture is not None
            else drawing.white_texture() for s in sources]


#: an object whose pair table would pass this many texels (256 MiB) is drawn without it
MAX_PAIR_TEXELS = 1 << 24


class ObjectBatches:
    """Per material slot the batches of one object: ``draws`` = [(slot, flat, batch)];
    ``flat_points`` the shading points of its flat triangles (pair table rows)."""

    def __init__(self, draws, flat_points):
        self.draws = draws
        self.flat_points = flat_points


def object_batches(st, field, use_flat: bool = True) -> ObjectBatches:
    """Per material slot: per-corner position, normal, triangle points, barycentrics -- the
    flat triangles (:func:`flat_triangles`) in a second batch for the FLAT_PAIRS shader
    with their points' rows in the pair table."""
    inputs = tuple(sorted((slot, id(values)) for slot, (_, values) in st.textures.items())) \
        + tuple(sorted((slot, name, id(v)) for slot, got in st.inputs[0].items()
                       for name, (_, v) in got.items())) \
        + tuple(sorted((slot, id(got[2])) for slot, got in st.normals.items()))
    return keys.held(_BATCHES, (st.name, st.fingerprint, use_flat, inputs), (field,),
                     lambda: _object_batches(st, use_flat))


def _object_batches(st, use_flat: bool) -> ObjectBatches:
    from gpu_extras.batch import batch_for_shader
    arrays, pts = st.arrays, st.points
    tri = arrays.triangles
    corner = tri.reshape(-1)
    pos, nrm, tri_points, bary = drawing.triangle_corners(st)
    slots = arrays.corner_materials[tri[:, 0]]
    flat = flat_triangles(arrays, pts) if use_flat else np.zeros(len(tri), bool)
    # a normal-mapped slot's lobes turn per pixel: never drawn from the pair table
    mapped = [slot for slot in st.normals if shader_normal(st, slot) is not None]
    flat &= ~np.isin(slots, mapped)
    flat_points = np.unique(pts.point_of_corner[tri[flat]])
    row = np.full(len(pts.normals), -1, np.int64)
    row[flat_points] = np.arange(len(flat_points))
    tri_flat = np.repeat(row[pts.point_of_corner[tri]].astype(np.float32), 3, axis=0)
    # a textured slot's UVs and colour attribute per corner (addon.blender.texture_export)
    uv = np.zeros((len(corner), 2), np.float32)
    attr = np.ones((len(corner), 4), np.float32)
    tng = np.zeros((len(corner), 4), np.float32)
    corner_slot = np.repeat(slots, 3)
    for slot in np.unique(slots):
        got = shader_normal(st, int(slot))
        if got is not None:
            tng[corner_slot == slot] = got[1][corner[corner_slot == slot]]
        sel = corner_slot == slot
        uvs = slot_uvs(st, int(slot))
        if uvs is not None:
            uv[sel] = uvs[1][corner[sel]]
        source, values = st.textures.get(int(slot), (None, None))
        if source is not None and source.texture is None:
            attr[sel] = values[corner[sel]]
    draws = []
    for slot in np.unique(slots):
        for is_flat in (False, True):
            sel = np.repeat((slots == slot) & (flat == is_flat), 3)
            if not sel.any():
                continue
            attrs = {"pos": np.ascontiguousarray(pos[sel]), "nrm": np.ascontiguousarray(nrm[sel]),
                     "triPoints": np.ascontiguousarray(tri_points[sel]),
                     "bary": np.ascontiguousarray(bary[sel]),
                     "uv": np.ascontiguousarray(uv[sel]), "attr": np.ascontiguousarray(attr[sel]),
                     "tng": np.ascontiguousarray(tng[sel])}
            if is_flat:
                attrs["triFlat"] = np.ascontiguousarray(tri_flat[sel])
            draws.append((int(slot), is_flat,
                          batch_for_shader(_gpu_shader(is_flat), "TRIS", attrs)))
    return ObjectBatches(draws, flat_points)


def _bind_field_and_lighting(sh, rotation, field_textures, env_tex, light_tex):
    """The uniforms both passes read: the world's rotation, the SSDF's coefficient and
    eigen-image textures, the prefiltered environment and the light lobes."""
    import mathutils
    sh.uniform_float("envRot", mathutils.Matrix(rotation))
    sh.uniform_sampler("coeffTex", field_textures[0])
    sh.uniform_sampler("eigenTex", field_textures[1])
    sh.uniform_sampler("envTex", env_tex)
    sh.uniform_sampler("lightTex", light_tex)


def pair_texels(cosine_lobes: int, light_count: int) -> int:
    """Texels per flat point in the pair table: ceil(P / 4) angles, then P (w, k)."""
    pairs = cosine_lobes * light_count
    return -(-pairs // 4) + pairs


def pair_table(st, field, flat_points, env_tex, light_tex, param_tex, light_count,
               cosine_lobes, rotation):
    """Run the pair pass for the object's flat points: a GPUTexture (rows of ROW_TEXELS texels,
    :func:`pair_texels` per point).  Eq. 39's per-pair work that a flat triangle's pixels
    share, done once per point."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    coeff_tex, eigen_tex, _ = field_textures(field)
    normals = st.points.normals[flat_points]
    count = len(flat_points)
    width = drawing.ROW_TEXELS
    flat = np.zeros((max(1, -(-count // width)) * width, 4), np.float32)
    flat[:count, :3] = normals
    flat[:count, 3] = flat_points
    flat_tex = _texture(flat.reshape(-1, width, 4))
    total = count * pair_texels(cosine_lobes, light_count)
    rows = max(1, -(-total // width))
    sh = _pairs_shader()
    quad = keys.held(_GPU, "quad", (), lambda: batch_for_shader(
        sh, "TRIS", {"ndc": [(-1, -1), (3, -1), (-1, 3)]}))
    offscreen = gpu.types.GPUOffScreen(width, rows, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.depth_test_set("NONE")
            gpu.state.blend_set("NONE")
            sh.bind()
            _bind_field_and_lighting(sh, rotation, (coeff_tex, eigen_tex), env_tex, light_tex)
            sh.uniform_int("flatCount", count)
            sh.uniform_sampler("paramTex", param_tex)
            sh.uniform_sampler("flatTex", flat_tex)
            quad.draw(sh)
            fb = gpu.state.active_framebuffer_get()
            buf = fb.read_color(0, 0, width, rows, 4, 0, "FLOAT")
    finally:
        offscreen.free()
    buf.dimensions = width * rows * 4
    # read back and uploaded again (once per lighting change): a plain texture outlives the
    # offscreen and may be drawn from the viewport's and the F12 render's GPU contexts
    return _texture(np.array(buf, dtype=np.float32).reshape(rows, width, 4))


def gpu_draws(state, fields, sg_tables, fit, pre, cosine, eye, view_dir):
    """draw(view_projection) callables, one per object: ``fields`` its SSDF
    (StoredField), ``sg_tables`` its SG material per slot, ``fit``/``pre`` the lighting
    (``core.methods.ssdf_sg.scene``), ``cosine`` the clamped-cosine mixture."""
    M = len(cosine.amplitudes)
    env_tex, light_tex, light_count = environment_textures(fit, pre, M)
    world = state.world
    rot = [list(map(float, r)) for r in np.asarray(world.rotation, np.float64)]
    eye4 = ((*map(float, view_dir), 0.0) if view_dir is not None
            else (*map(float, eye), 1.0))
    env_common = dict(envStrength=float(world.strength), lightCount=int(light_count),
                      envRes=int(pre.resolution), envLevels=int(pre.n_levels),
                      envLambdaFirst=float(pre.lambda_first), envRatio=float(pre.ratio),
                      envTop=float(pre.lambdas[-2]))
    draws = []
    for st, field, table in zip(state.objects, fields, sg_tables):
        coeff_tex, eigen_tex, kt = field_textures(field)
        batches = object_batches(st, field, use_flat=bool(diffuse_slots(table).any()))
        if len(batches.flat_points) * pair_texels(M, int(light_count)) > MAX_PAIR_TEXELS:
            batches = object_batches(st, field, use_flat=False)
        params = {slot: slot_parameters(env_common, st, table, slot, field.resolution, kt,
                                        eye4, cosine)
                  for slot in sorted({slot for slot, _, _ in batches.draws})}
        inputs = {slot: input_textures(st, slot) for slot in params}
        pair_tex = None
        if len(batches.flat_points):
            key = (st.name, st.fingerprint, np.asarray(world.rotation).round(12).tobytes(),
                   cosine.sharpness, M, int(light_count))
            pair_tex = keys.held(
                PAIR_TABLES, key, (field, fit, batches),
                lambda: pair_table(st, field, batches.flat_points, env_tex, light_tex,
                                   next(iter(params.values())), int(light_count), M, rot))

        def draw(view_projection, batches=batches, params=params, inputs=inputs,
                 coeff_tex=coeff_tex, eigen_tex=eigen_tex, pair_tex=pair_tex,
                 side=float(st.closed_side)):
            for flat in (False, True):
                todo = [(slot, batch) for slot, f, batch in batches.draws if f == flat]
                if not todo:
                    continue
                sh = _gpu_shader(flat)
                sh.bind()
                sh.uniform_float("viewProjection", view_projection)
                sh.uniform_float("closedSide", side)
                _bind_field_and_lighting(sh, rot, (coeff_tex, eigen_tex), env_tex, light_tex)
                if flat:
                    sh.uniform_sampler("pairTex", pair_tex)
                for slot, batch in todo:
                    sh.uniform_sampler("paramTex", params[slot])
                    for name, tex in zip(_INPUT_SAMPLERS, inputs[slot]):
                        sh.uniform_sampler(name, tex)
                    batch.draw(sh)

        draws.append(draw)
    return draws
