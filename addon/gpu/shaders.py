"""Every shader of the add-on, built one way: a declarative :class:`Spec` per shader in
:data:`SPECS` (its GLSL files under ``shaders/``, libraries first, and its interface), and
:func:`shader`, which builds a spec with a variant's defines into a
``gpu.types.GPUShaderCreateInfo`` once and keeps it in a GPU cache (emptied on unregister).

``shaders/lib/`` holds function libraries (``constants.glsl`` generated from the Python
constants by ``tools/glsl_constants.py``), ``shaders/passes/`` the passes every method uses,
``shaders/methods/`` a method's own.  No GLSL is written in Python.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations
from pathlib import Path

from ...core.common.cache import Cache

SHADER_DIR = Path(__file__).resolve().parents[2] / "shaders"


@dataclass(frozen=True)
class Spec:
    """One shader as Blender's ``GPUShaderCreateInfo`` takes it.  ``vertex``/``fragment``: the
    files of each stage under ``shaders/`` joined in order (libraries first); ``push_constants``,
    ``samplers`` (slot = position), ``vertex_inputs`` (slot = position), ``outputs``: (type,
    name); ``varyings``: (``"smooth"`` or ``"flat"``, type, name); ``defines``: fixed (name,
    value); ``switches``: the ``#define NAME`` a variant may set, any subset; ``values``: the
    ``#define NAME VALUE`` a variant may set, with the values the tests build it with."""

    vertex: tuple[str, ...]
    fragment: tuple[str, ...]
    push_constants: tuple[tuple[str, str], ...] = ()
    samplers: tuple[tuple[str, str], ...] = ()
    vertex_inputs: tuple[tuple[str, str], ...] = ()
    varyings: tuple[tuple[str, str, str], ...] = ()
    outputs: tuple[tuple[str, str], ...] = (("VEC4", "fragColor"),)
    defines: tuple[tuple[str, str], ...] = ()
    switches: tuple[str, ...] = ()
    values: tuple[tuple[str, tuple[str, ...]], ...] = ()


# --------------------------------------------------------------------------- the specs

_VIEW = (("MAT4", "viewProjection"),)
#: a colour input's push constants (lib/texture.glsl input_colour)
_TEXTURED = (("VEC4", "texInfo"), ("VEC3", "texMap0"), ("VEC3", "texMap1"), ("VEC4", "mixColor"))
_SSDF_SG_SAMPLERS = (("FLOAT_2D", "coeffTex"), ("FLOAT_2D_ARRAY", "eigenTex"),
                     ("FLOAT_2D", "envTex"), ("FLOAT_2D", "lightTex"), ("FLOAT_2D", "paramTex"))
#: the libraries every pass's fragment stage starts with (common.glsl reads the constants)
_COMMON = ("lib/constants.glsl", "lib/common.glsl")
#: lib/sg.glsl with the libraries it calls, in order (tests/gpu/test_sg_common.py's twin builds it too)
SG_LIBRARY = _COMMON + ("lib/microfacet.glsl", "lib/sg.glsl")
_SSDF_SG_LIBS = SG_LIBRARY + ("lib/texture.glsl", "methods/ssdf_sg_lib.glsl")

#: a draw's shared lobe signature compiled in (core.shading.microfacet.lobe_signature)
_LOBE_SIGNATURE = (("LOBE_DIST", ("0", "1")), ("LOBE_COUNT", ("0", "1", "2")),
                   ("LOBE_KIND0", ("0", "1", "2", "3")), ("LOBE_KIND1", ("2", "3")))

_SSDF_SG = Spec(
    vertex=("methods/ssdf_sg_vert.glsl",),
    fragment=_SSDF_SG_LIBS + ("methods/ssdf_sg_frag.glsl",),
    push_constants=_VIEW + (("MAT3", "envRot"), ("FLOAT", "closedSide")),
    # the slot's textured inputs: colour, Roughness, Metallic, Specular IOR Level, normal map
    samplers=_SSDF_SG_SAMPLERS + tuple(("FLOAT_2D", n) for n in (
        "albedoTex", "roughTex", "metalTex", "levelTex", "normalTex")),
    vertex_inputs=(("VEC3", "pos"), ("VEC3", "nrm"), ("VEC3", "triPoints"), ("VEC3", "bary"),
                   ("VEC2", "uv"), ("VEC4", "attr"), ("VEC4", "tng")),
    varyings=(("smooth", "VEC3", "vPos"), ("smooth", "VEC3", "vNrm"),
              ("smooth", "VEC3", "vBary"), ("flat", "VEC3", "vTri"), ("smooth", "VEC2", "vUv"),
              ("smooth", "VEC4", "vAttr"), ("smooth", "VEC4", "vTng")))

SPECS: dict[str, Spec] = {
    # per-vertex radiance (every per-vertex method's frame)
    "surface": Spec(
        vertex=("passes/surface_vert.glsl",), fragment=_COMMON + ("passes/surface_frag.glsl",),
        push_constants=_VIEW, vertex_inputs=(("VEC3", "pos"), ("VEC4", "radiance")),
        varyings=(("smooth", "VEC4", "vRadiance"),),
        # added onto a frame already drawn (a per-pixel method's bounced light): alpha 0;
        # DATA: a data render pass's values, unclamped (addon/frame/passes.py)
        switches=("ADDED", "DATA")),
    # per-vertex radiance times a slot's colour per pixel (drawing.textured_draws)
    "surface_tex": Spec(
        vertex=("passes/surface_tex_vert.glsl",),
        fragment=_COMMON + ("lib/texture.glsl", "passes/surface_tex_frag.glsl"),
        push_constants=_VIEW + _TEXTURED, samplers=(("FLOAT_2D", "albedoTex"),),
        vertex_inputs=(("VEC3", "pos"), ("VEC4", "diffuse"), ("VEC3", "specular"),
                       ("VEC2", "uv"), ("VEC4", "attr")),
        varyings=(("smooth", "VEC4", "vDiffuse"), ("smooth", "VEC3", "vSpecular"),
                  ("smooth", "VEC2", "vUv"), ("smooth", "VEC4", "vAttr")),
        switches=("ADDED",)),
    # the world behind the objects
    "background": Spec(
        vertex=("passes/background_vert.glsl",),
        fragment=("lib/constants.glsl", "passes/background_frag.glsl"),
        push_constants=(("MAT4", "invViewProjection"), ("MAT3", "texRotation"),
                        ("FLOAT", "strength")),
        samplers=(("FLOAT_2D", "envMap"),), vertex_inputs=(("VEC2", "ndc"),),
        varyings=(("smooth", "VEC2", "vNdc"),)),
    # compact sources and lamps per pixel (lights.py); 128 bytes of push constants at most
    # (the closed side rides in paramTex, the source count is srcTex's height)
    "lights": Spec(
        vertex=("passes/lights_vert.glsl",),
        fragment=_COMMON + ("lib/microfacet.glsl", "lib/texture.glsl",
                            "passes/lights_frag.glsl"),
        push_constants=_VIEW + _TEXTURED,
        samplers=tuple(("FLOAT_2D", n) for n in ("paramTex", "srcTex", "shadowTex", "albedoTex",
                                                 "cubeTex", "roughTex", "normalTex",
                                                 "tileTex")),
        vertex_inputs=(("VEC3", "pos"), ("VEC3", "nrm"), ("VEC2", "uv"), ("VEC4", "attr"),
                       ("VEC4", "tng")),
        varyings=tuple(("smooth", kind, n) for kind, n in (
            ("VEC3", "vPos"), ("VEC3", "vNrm"), ("VEC2", "vUv"), ("VEC4", "vAttr"),
            ("VEC4", "vTng"))),
        # what a draw lacks is left out of its shader, not branched around
        switches=("GLOSSY", "ROUGH_TEX", "NORMAL_MAP", "ALBEDO_TEX", "PLACED", "LOCAL_LAMPS",
                  "AREA_LAMPS", "LIGHT_TILES"),
        values=(("PCF_TAPS", ("12", "4")), ("LOBE_TAPS", ("4", "2"))) + _LOBE_SIGNATURE),
    # a sun-like source's shadow map: depth only
    "shadow_depth": Spec(
        vertex=("passes/shadow_depth_vert.glsl",), fragment=("passes/shadow_depth_frag.glsl",),
        push_constants=_VIEW, vertex_inputs=(("VEC3", "pos"),)),
    # a local lamp's shadow faces: the distance to the lamp
    "shadow_distance": Spec(
        vertex=("passes/shadow_distance_vert.glsl",),
        fragment=("passes/shadow_distance_frag.glsl",),
        push_constants=_VIEW + (("VEC3", "lamp"), ("INT", "caster")),
        samplers=(("FLOAT_2D", "modelTex"),), vertex_inputs=(("VEC3", "pos"),),
        varyings=(("smooth", "VEC3", "vPos"),),
        # an instance over its source's shared batch (addon/gpu/lights.py _object_batches)
        switches=("PLACED",)),
    # glossy lobes too narrow for the cubemap (sharp.py)
    "sharp_lobe": Spec(
        vertex=("passes/sharp_lobe_vert.glsl",),
        fragment=_COMMON + ("lib/microfacet.glsl", "lib/texture.glsl",
                            "passes/sharp_lobe_frag.glsl"),
        push_constants=_VIEW + (("MAT3", "envRot"), ("FLOAT", "closedSide")),
        samplers=tuple(("FLOAT_2D", n) for n in ("envTex", "mipTex", "sourcesTex",
                                                 "sourcesMipTex", "worldSrcTex", "visTex",
                                                 "paramTex", "roughTex", "normalTex")),
        vertex_inputs=tuple(("VEC3", n) for n in ("pos", "nrm", "triPoints", "bary", "triN0",
                                                  "triN1", "triN2"))
        + (("VEC2", "uv"), ("VEC4", "tng")),
        varyings=(("smooth", "VEC3", "vPos"), ("smooth", "VEC3", "vNrm"),
                  ("smooth", "VEC3", "vBary"), ("smooth", "VEC2", "vUv"),
                  ("smooth", "VEC4", "vTng"), ("flat", "VEC3", "vTri"),
                  ("flat", "VEC3", "vTriN0"), ("flat", "VEC3", "vTriN1"),
                  ("flat", "VEC3", "vTriN2")),
        # a slot's textured Roughness and normal or bump map, left out of draws without
        switches=("ROUGH_TEX", "NORMAL_MAP"), values=_LOBE_SIGNATURE),
    # SSDF_SG's per-pixel pass (methods/ssdf_sg/gpu.py) ...
    "ssdf_sg": _SSDF_SG,
    # ... and its variant for flat triangles: eq. 39 from the pair table
    "ssdf_sg_flat": replace(
        _SSDF_SG, samplers=_SSDF_SG.samplers + (("FLOAT_2D", "pairTex"),),
        vertex_inputs=_SSDF_SG.vertex_inputs + (("VEC3", "triFlat"),),
        varyings=_SSDF_SG.varyings + (("flat", "VEC3", "vFlat"),),
        defines=(("FLAT_PAIRS", "1"),)),
    # SSDF_SG's pair pass: one fragment per texel of the pair table
    "ssdf_sg_pairs": Spec(
        vertex=("passes/fullscreen_vert.glsl",),
        fragment=_SSDF_SG_LIBS + ("methods/ssdf_sg_pairs_frag.glsl",),
        push_constants=(("MAT3", "envRot"), ("INT", "flatCount")),
        samplers=_SSDF_SG_SAMPLERS + (("FLOAT_2D", "flatTex"),),
        vertex_inputs=(("VEC2", "ndc"),)),
    # adaptive anti-aliasing: the samples of a pixel the pilot frame holds (render_offscreen)
    "adaptive": Spec(
        vertex=("passes/near_quad_vert.glsl",), fragment=("passes/adaptive_frag.glsl",),
        push_constants=(("INT", "samples"),),
        samplers=(("FLOAT_2D", "maskTex"), ("FLOAT_2D", "pilotTex")),
        vertex_inputs=(("VEC2", "ndc"),)),
    # the pixel filter along one axis (drawing.render_offscreen: x, then y)
    "resolve": Spec(
        vertex=("passes/fullscreen_vert.glsl",), fragment=("passes/resolve_frag.glsl",),
        push_constants=tuple(("INT", n) for n in ("axis", "samples", "margin", "taps")),
        samplers=(("FLOAT_2D", "frameTex"), ("FLOAT_2D", "tapTex")),
        vertex_inputs=(("VEC2", "ndc"),)),
    # REFERENCE's glossy or diffuse sums: one texel per shading point (methods/reference/gpu.py)
    "reference_sums": Spec(
        vertex=("passes/fullscreen_vert.glsl",),
        fragment=_COMMON + ("lib/microfacet.glsl", "methods/reference_sums_frag.glsl"),
        push_constants=tuple(("INT", n) for n in (
            "width", "rows", "firstRow", "pointCount", "stride", "envWidth", "envRows")),
        samplers=tuple(("FLOAT_2D", n) for n in ("pointData", "visTex", "envData", "matData")),
        vertex_inputs=(("VEC2", "ndc"),),
        # the diffuse sum (no material) instead of the glossy one
        switches=("IRRADIANCE",), values=_LOBE_SIGNATURE),
    # RSL's per-vertex pass: one texel per shading point (methods/rsl/shading.py)
    "rsl_vertex": Spec(
        vertex=("passes/fullscreen_vert.glsl",),
        fragment=_COMMON + ("methods/rsl_vertex_frag.glsl",),
        push_constants=tuple(("INT", n) for n in (
            "width", "pointCount", "lightCount", "termCount", "visMode", "visRes", "visTile",
            "brdfRes", "viewNodes", "blockCols")) + (("FLOAT", "viewStep"),),
        samplers=tuple(("FLOAT_2D", n) for n in ("pointData", "weights", "lights", "visTable",
                                                 "brdfTables")),
        vertex_inputs=(("VEC2", "ndc"),)),
}


# --------------------------------------------------------------------------- building

#: every built shader per (spec name, defines): a frame uses a few dozen (the lights pass's
#: feature sets and lobe signatures per slot, for its pilot and its samples).
#: addon/gpu/drawing.gpu_cache's kind of cache, made here (drawing imports this module)
_SHADERS = Cache(128, gpu=True)


def source(spec: Spec, stage: str) -> str:
    """The GLSL of one stage (``"vertex"`` or ``"fragment"``): its files joined in order."""
    return "".join((SHADER_DIR / name).read_text() for name in getattr(spec, stage))


def parse_defines(spec: Spec, defines) -> tuple[tuple[str, str], ...]:
    """``defines`` ("NAME" or "NAME VALUE") as sorted (name, value) pairs; a name the spec
    does not declare (:attr:`Spec.switches`, :attr:`Spec.values`) raises ValueError."""
    values = dict(spec.values)
    out = []
    for text in defines:
        name, _, value = str(text).partition(" ")
        if (name in spec.switches and not value) or (name in values and value):
            out.append((name, value or "1"))
        else:
            raise ValueError(f"define {text!r} is not a variant of this shader")
    return tuple(sorted(set(out)))


def create_info(spec: Spec, defines=(), name: str = "shader", tail: str = ""):
    """The ``gpu.types.GPUShaderCreateInfo`` of ``spec`` (called ``name``) with a variant's
    ``defines``; ``tail``: GLSL appended to the fragment stage (the tests' GLSL twins write
    their ``main`` there; the add-on never does)."""
    import gpu
    info = gpu.types.GPUShaderCreateInfo()
    for ident, value in spec.defines + parse_defines(spec, defines):
        info.define(ident, value)
    for kind, ident in spec.push_constants:
        info.push_constant(kind, ident)
    for slot, (kind, ident) in enumerate(spec.samplers):
        info.sampler(slot, kind, ident)
    for slot, (kind, ident) in enumerate(spec.vertex_inputs):
        info.vertex_in(slot, kind, ident)
    if spec.varyings:
        iface = gpu.types.GPUStageInterfaceInfo(f"prt_{name}_iface")
        for interpolation, kind, ident in spec.varyings:
            getattr(iface, interpolation)(kind, ident)
        info.vertex_out(iface)
    for slot, (kind, ident) in enumerate(spec.outputs):
        info.fragment_out(slot, kind, ident)
    info.vertex_source(source(spec, "vertex"))
    info.fragment_source(source(spec, "fragment") + tail)
    return info


def shader(name: str, defines=()):
    """The shader :data:`SPECS` ``[name]`` with a variant's ``defines`` ("NAME" or "NAME VALUE"),
    built once and kept in the GPU cache."""
    spec, defines = SPECS[name], tuple(defines)
    key = (name, parse_defines(spec, defines))
    sh = _SHADERS.get(key)
    if sh is None:
        import gpu
        sh = _SHADERS[key] = gpu.shader.create_from_info(create_info(spec, defines, name))
    return sh


def variants(name: str) -> list[tuple[str, ...]]:
    """Every define set a build of ``name`` may have that the tests build: each subset of its
    switches, and all switches with each listed value of each valued define."""
    spec = SPECS[name]
    out = [subset for k in range(len(spec.switches) + 1)
           for subset in combinations(spec.switches, k)]
    out += [spec.switches + (f"{n} {v}",) for n, vals in spec.values for v in vals]
    return out
