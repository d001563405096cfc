"""Blender node trees -> the textured colour inputs of core/scene/textures.py (bpy only).

Recognised (a Principled BSDF's *Base Color*, a Diffuse BSDF's *Color*): an Image Texture
(its UV Map node or the render UV map, an optional Mapping node on the UVs, Closest /
Linear / Cubic interpolation, Repeat / Extend / Clip / Mirror, packed or on disk, read in
its colour space as Cycles does), a Color Attribute node, or a Mix node (colour mode,
*Mix* or *Multiply*, a constant factor) between one of those and a constant colour.
The scalar inputs of :data:`core.scene.textures.SCALAR_INPUTS` (Principled *Roughness*,
*Metallic*, *Specular IOR Level*, Glossy *Roughness*) driven by the same patterns are
:class:`core.scene.textures.ScalarSource` (the image's Color output, as a float).  Anything else
linked keeps the old behaviour: its default value and a warning naming the node.
A surface node's *Normal* (Principled, Diffuse, Glossy) driven by a Normal Map node
(tangent space, an image on its Color, constant Strength) or a Bump node (an image's Color
on its Height, constant Strength and Distance, no Normal chained in) is a
:class:`core.scene.textures.NormalSource`, with the mesh's per-corner tangents
(``mesh.calc_tangents``) for the map's UV map; anything else linked there is warned by name
and ignored (the surface normal).
"""

from __future__ import annotations

import math

import numpy as np

from ...core.sphere import envmap
from ...core.scene import textures
from .scene_export import ExportError, image_pixels, surface_node

#: the colour input of each supported surface node
COLOR_INPUTS = {"BSDF_PRINCIPLED": "Base Color", "BSDF_DIFFUSE": "Color"}
_BLEND_MODES = {"MIX": "MIX", "MULTIPLY": "MULTIPLY"}


def _linked(socket):
    if socket is None or not socket.is_linked or not socket.links:
        return None
    link = socket.links[0]
    return None if link.is_muted else link.from_node


def _mapping_transform(node) -> np.ndarray:
    """The Mapping node's 2D affine map on (u, v) (POINT / TEXTURE / VECTOR types; the
    rotation about Z only, which is what a UV transform uses)."""
    loc = tuple(node.inputs["Location"].default_value) if "Location" in node.inputs \
        else (0.0, 0.0, 0.0)
    rot = tuple(node.inputs["Rotation"].default_value)[2]
    scale = tuple(node.inputs["Scale"].default_value)
    c, s = math.cos(rot), math.sin(rot)
    R = np.array([[c, -s], [s, c]])
    S = np.diag(scale[:2])
    kind = getattr(node, "vector_type", "POINT")
    if kind == "TEXTURE":                  # the inverse of POINT
        A = np.linalg.inv(R @ S)
        t = -A @ np.asarray(loc[:2])
    elif kind == "VECTOR":
        A, t = R @ S, np.zeros(2)
    else:                                  # POINT: location + rotation @ (scale * v)
        A, t = R @ S, np.asarray(loc[:2])
    return np.concatenate([A, t[:, None]], axis=1)


def _texture_pixels(image) -> np.ndarray:
    """(H, W, 4) linear float32, row 0 at v = 0 (alpha = 1)."""
    try:
        rgb = image_pixels(image)                     # top row first, working space
    except ExportError as exc:
        raise ExportError(str(exc).replace("Environment image", "Image texture")) from exc
    rgba = np.ones(rgb.shape[:2] + (4,), np.float32)
    rgba[..., :3] = rgb[::-1]
    return rgba


def image_texture(node) -> textures.ImageTexture | None:
    if node.image is None:
        return None
    uv_map, transform = "", np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    src = _linked(node.inputs.get("Vector"))
    if src is not None and src.type == "MAPPING":
        transform = _mapping_transform(src)
        src = _linked(src.inputs.get("Vector"))
    if src is not None:
        if src.type == "UVMAP":
            uv_map = src.uv_map
        elif src.type != "TEX_COORD":
            return None
    interpolation = {"Closest": "CLOSEST", "Cubic": "CUBIC"}.get(node.interpolation, "LINEAR")
    return textures.ImageTexture(_texture_pixels(node.image), uv_map=uv_map,
                                 transform=transform, interpolation=interpolation,
                                 extension=node.extension, name=node.image.name)


def _source_of(node):
    if node is None:
        return None
    if node.type == "TEX_IMAGE":
        tex = image_texture(node)
        return textures.ColorSource(texture=tex) if tex is not None else None
    if node.type == "VERTEX_COLOR":
        return textures.ColorSource(attribute=node.layer_name)
    return None


def color_source(socket):
    """The ColorSource driving a colour input, or None when it is not one we draw."""
    node = _linked(socket)
    if node is None:
        return None
    direct = _source_of(node)
    if direct is not None:
        return direct
    if node.type not in ("MIX", "MIX_RGB"):
        return None
    if node.type == "MIX" and getattr(node, "data_type", "RGBA") != "RGBA":
        return None
    mode = _BLEND_MODES.get(node.blend_type)
    if mode is None:
        return None
    if node.type == "MIX":
        fac_sock = node.inputs[0]
        a, b = (s for s in node.inputs if s.type == "RGBA")
    else:
        fac_sock, a, b = node.inputs[0], node.inputs[1], node.inputs[2]
    if fac_sock.is_linked:
        return None
    sources = [_source_of(_linked(s)) for s in (a, b)]
    for first, (src, other) in ((True, (sources[0], b)), (False, (sources[1], a))):
        if src is not None and not other.is_linked:
            src.mix = (mode, float(fac_sock.default_value),
                       tuple(other.default_value)[:3], first)
            return src
    return None


def slot_color_source(material):
    """The textured colour input of a material's surface (None if constant)."""
    node = surface_node(material) if material is not None else None
    if node is None or node.type not in COLOR_INPUTS:
        return None
    return color_source(node.inputs.get(COLOR_INPUTS[node.type]))


#: the scalar inputs read per surface node
SCALAR_INPUTS = {"BSDF_PRINCIPLED": ("Roughness", "Metallic", "Specular IOR Level"),
                 "BSDF_GLOSSY": ("Roughness",)}


def slot_scalar_sources(material) -> dict:
    """{input name: ScalarSource} of a material's textured scalar inputs."""
    node = surface_node(material) if material is not None else None
    if node is None or node.type not in SCALAR_INPUTS:
        return {}
    out = {}
    for name in SCALAR_INPUTS[node.type]:
        sock = node.inputs.get(name)
        link = sock.links[0] if sock is not None and sock.is_linked and sock.links else None
        if link is None or link.from_socket.name != "Color":
            continue                  # e.g. an image's Alpha output: not read (warned)
        src = color_source(sock)
        if src is not None:
            out[name] = textures.ScalarSource(src, name)
    return out


def principled_constants(material) -> dict | None:
    """The Principled node's constant IOR, Specular Tint and distribution (what a textured
    Specular IOR Level is combined with), or None."""
    node = surface_node(material) if material is not None else None
    if node is None or node.type != "BSDF_PRINCIPLED":
        return None
    return {"IOR": float(node.inputs["IOR"].default_value),
            "Specular Tint": tuple(node.inputs["Specular Tint"].default_value)[:3],
            "distribution": getattr(node, "distribution", "MULTI_GGX")}


def _corner_values(ob_eval, mat, source, warnings):
    """The UVs or attribute colours per corner a source is read at, or None (warned)."""
    if source.texture is not None:
        values = _resolved_uvs(ob_eval, source.texture)
        if values is None:
            warnings.append(f"Material '{mat.name}': '{ob_eval.name}' has no UV map for "
                            "its image texture; drawn with the texture's mean")
        return values
    values = corner_colours(ob_eval, source.attribute)
    if values is None:
        warnings.append(f"Material '{mat.name}': '{ob_eval.name}' has no colour "
                        f"attribute '{source.attribute}'; drawn with white")
    return values


def _read(mat, read, warnings: list, what: str, instead: str):
    """``(True, read(mat))``, or ``(False, None)`` with a warning naming the material when
    its image cannot be read (``what`` cannot be read ...; ``instead``)."""
    try:
        return True, read(mat)
    except (RuntimeError, ExportError, envmap.EnvironmentError_, ValueError) as exc:
        warnings.append(f"Material '{mat.name}': {what} cannot be read ({exc}); {instead}")
        return False, None


def slot_scalars(ob_eval, warnings: list) -> dict:
    """{slot: {input: (ScalarSource, corner values)}} of an evaluated object's textured
    scalar inputs (UVs (C, 2) or attribute colours (C, 4), as :func:`slot_sources`)."""
    out = {}
    for slot, ms in enumerate(ob_eval.material_slots):
        mat = ms.material
        ok, found = _read(mat, slot_scalar_sources, warnings, "a texture",
                          "its inputs keep their default values")
        if not ok:
            continue
        got = {}
        for name, scalar in found.items():
            values = _corner_values(ob_eval, mat, scalar.source, warnings)
            if values is not None:
                got[name] = (scalar, values)
        if got:
            out[slot] = got
    return out


def mean_scalars(inputs: dict) -> dict:
    """{input: mean value over the corners} of one slot's :func:`slot_scalars` entry."""
    return {name: float(np.mean(scalar.value(textures.corner_colours(scalar.source,
                                                                     values)[:, :3])))
            for name, (scalar, values) in inputs.items()}


def slot_uvs(st, slot):
    """(UV map name, per-corner UVs) a per-pixel pass's batch of a slot carries (``st``: an
    addon.frame.state.ObjectState): its colour texture's, else
    its first textured scalar input's, else its normal map's; None without an image
    texture."""
    source, values = st.textures.get(slot, (None, None))
    found = [(source, values)] + list(st.inputs[0].get(slot, {}).values())
    normal = st.normals.get(slot)
    if normal is not None:
        found.append(normal[:2])
    for src, vals in found:
        src = getattr(src, "source", src)
        if src is not None and src.texture is not None:
            return src.texture.uv_map, vals
    return None


def shader_inputs(st, slot) -> dict:
    """{input: (ScalarSource, values)} of a slot's textured scalar inputs the shader reads
    per pixel: images on the batch's UV map (others keep the slot's mean value)."""
    uvs = slot_uvs(st, slot)
    return {name: (s, v) for name, (s, v) in st.inputs[0].get(slot, {}).items()
            if s.source.texture is not None and uvs is not None
            and s.source.texture.uv_map == uvs[0]}


def shader_normal(st, slot):
    """(NormalSource, per-corner tangents (C, 4)) of a slot's normal or bump map when its
    image is on the batch's UV map (else None: drawn with the surface normal)."""
    got = st.normals.get(slot)
    uvs = slot_uvs(st, slot)
    if got is None or uvs is None or got[0].source.texture.uv_map != uvs[0]:
        return None
    return got[0], got[2]


def _uv_layer(layers, uv_map: str):
    """The UV map ``uv_map`` names, else the one Cycles renders with by default (the
    camera icon, ``active_render``: a map added in the UI is active but not that one)."""
    named = layers.get(uv_map) if uv_map else None
    return named or next((l for l in layers if l.active_render), None) or layers.active


def corner_uvs(ob_eval, uv_map: str = "", named=None):
    """(C, 2) float32 UVs per face corner of the evaluated mesh (loops order), or None;
    ``named``: a list the UV map's name is appended to."""
    mesh = ob_eval.to_mesh()
    try:
        layers = mesh.uv_layers
        if not len(layers):
            return None
        layer = _uv_layer(layers, uv_map)
        uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        if named is not None:
            named.append(layer.name)
        return uv.reshape(-1, 2)
    finally:
        ob_eval.to_mesh_clear()


def _resolved_uvs(ob_eval, texture):
    """:func:`corner_uvs` of an image texture, its ``uv_map`` set to the map's name ("" is
    the render UV map): the per-pixel passes compare the maps of a slot's images by name."""
    named = []
    uvs = corner_uvs(ob_eval, texture.uv_map, named)
    if named:
        texture.uv_map = named[0]
    return uvs


def corner_colours(ob_eval, name: str = ""):
    """(C, 4) linear float32 of a colour attribute per face corner, or None."""
    mesh = ob_eval.to_mesh()
    try:
        attrs = mesh.color_attributes
        attr = (attrs.get(name) if name else None) or attrs.active_color
        if attr is None:
            return None
        data = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", data)              # linear, byte colours included
        data = data.reshape(-1, 4)
        if attr.domain == "POINT":
            corner_verts = np.empty(len(mesh.loops), dtype=np.int32)
            mesh.loops.foreach_get("vertex_index", corner_verts)
            return data[corner_verts]
        return data if attr.domain == "CORNER" else None
    finally:
        ob_eval.to_mesh_clear()


def mean_albedo(source, values) -> tuple:
    """The input's mean colour (for what cannot vary per pixel): ``values`` are the corner
    colours of an attribute source (ignored for a texture)."""
    return tuple(float(c) for c in textures.mean_colour(
        source, None if source.texture is not None else values))


def slot_sources(ob_eval, warnings: list) -> dict:
    """{slot: (ColorSource, corner values)} of an evaluated object's textured slots: the
    UVs (C, 2) a texture is read at, or the attribute's colours (C, 4)."""
    out = {}
    for slot, ms in enumerate(ob_eval.material_slots):
        mat = ms.material
        ok, src = _read(mat, slot_color_source, warnings, "its texture",
                        "drawn with its default colour")
        if not ok:
            continue
        if src is None:
            continue
        values = _corner_values(ob_eval, mat, src, warnings)
        if values is not None:
            out[slot] = (src, values)
    return out


#: the surface nodes whose Normal input is read
NORMAL_NODES = ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_GLOSSY")


def _image_on(socket):
    """The Image Texture node whose Color output drives ``socket`` (None otherwise)."""
    if socket is None or not socket.is_linked or not socket.links:
        return None
    link = socket.links[0]
    if link.is_muted or link.from_node.type != "TEX_IMAGE" or link.from_socket.name != "Color":
        return None
    return link.from_node


def normal_source(material):
    """(NormalSource or None, the tangents' UV map name, the node that drives Normal but
    is not read (or None))."""
    node = surface_node(material) if material is not None else None
    if node is None or node.type not in NORMAL_NODES:
        return None, "", None
    src = _linked(node.inputs.get("Normal"))
    if src is None:
        return None, "", None
    if src.type == "NORMAL_MAP":
        img = _image_on(src.inputs["Color"])
        tex = image_texture(img) if img is not None else None
        if (tex is None or src.space != "TANGENT" or src.inputs["Strength"].is_linked):
            return None, "", src
        return (textures.NormalSource("NORMAL_MAP", textures.ColorSource(texture=tex),
                                      float(src.inputs["Strength"].default_value)),
                src.uv_map or tex.uv_map, None)
    if src.type == "BUMP":
        img = _image_on(src.inputs["Height"])
        tex = image_texture(img) if img is not None else None
        if (tex is None or src.inputs["Normal"].is_linked or src.inputs["Strength"].is_linked
                or src.inputs["Distance"].is_linked):
            return None, "", src
        distance = float(src.inputs["Distance"].default_value)
        return (textures.NormalSource("BUMP", textures.ColorSource(texture=tex),
                                      float(src.inputs["Strength"].default_value),
                                      -distance if src.invert else distance),
                tex.uv_map, None)
    return None, "", src


def corner_tangents(ob_eval, uv_map: str = "", matrix=None):
    """(C, 4) world-space unit tangents per face corner and the bitangent sign (MikkTSpace,
    ``mesh.calc_tangents`` on ``uv_map`` or the render's UV map), or None when the mesh has
    no such UV map or a face of more than four corners.  ``matrix``: where the mesh is
    placed (an instance's world matrix; the object's own when None)."""
    mesh = ob_eval.to_mesh()
    try:
        layers = mesh.uv_layers
        if not len(layers):
            return None
        layer = _uv_layer(layers, uv_map)
        try:
            mesh.calc_tangents(uvmap=layer.name)
        except RuntimeError:
            return None
        n = len(mesh.loops)
        t = np.empty(n * 3, dtype=np.float32)
        sign = np.empty(n, dtype=np.float32)
        mesh.loops.foreach_get("tangent", t)
        mesh.loops.foreach_get("bitangent_sign", sign)
    finally:
        ob_eval.to_mesh_clear()
    M = np.array(ob_eval.matrix_world if matrix is None else matrix, dtype=np.float64)[:3, :3]
    tw = t.reshape(-1, 3).astype(np.float64) @ M.T          # a surface direction: M t
    length = np.linalg.norm(tw, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        tw = np.where(length > 0.0, tw / length, 0.0)
    # a mirroring transform flips the world bitangent N x T against the object's
    flip = -1.0 if np.linalg.det(M) < 0.0 else 1.0
    return np.concatenate([tw, (sign * flip)[:, None]], axis=1).astype(np.float32)


def slot_normals(ob_eval, warnings: list, matrix=None) -> dict:
    """{slot: (NormalSource, per-corner UVs (C, 2), per-corner tangents (C, 4))} of an
    evaluated object's normal- or bump-mapped slots, its mesh placed by ``matrix`` (its
    own world matrix when None); other nodes driving Normal warned."""
    out = {}
    for slot, ms in enumerate(ob_eval.material_slots):
        mat = ms.material
        ok, got = _read(mat, normal_source, warnings, "its normal map",
                        "drawn with the surface normal")
        if not ok:
            continue
        src, uv_map, other = got
        if other is not None:
            warnings.append(f"Material '{mat.name}': '{other.bl_label}' ('{other.name}') "
                            "drives Normal and is not supported; drawn with the surface "
                            "normal")
        if src is None:
            continue
        uvs = _resolved_uvs(ob_eval, src.source.texture)
        tangents = corner_tangents(ob_eval, uv_map, matrix) if uvs is not None else None
        if tangents is None:
            warnings.append(f"Material '{mat.name}': '{ob_eval.name}' has no UV map (or a "
                            "face of more than 4 corners) for its normal map; drawn with "
                            "the surface normal")
            continue
        out[slot] = (src, uvs, tangents)
    return out


__all__ = ["normal_source", "corner_tangents", "slot_normals", "shader_normal",
           "color_source", "slot_color_source", "slot_sources", "image_texture",
           "corner_uvs", "corner_colours", "mean_albedo", "slot_scalar_sources",
           "principled_constants", "slot_scalars", "mean_scalars", "slot_uvs",
           "shader_inputs"]
