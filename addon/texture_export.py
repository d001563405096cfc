"""Blender node trees -> the textured colour inputs of core/textures.py (bpy only).

Recognised (a Principled BSDF's *Base Color*, a Diffuse BSDF's *Color*): an Image Texture
(its UV Map node or the active UV map, an optional Mapping node on the UVs, Closest /
Linear / Cubic interpolation, Repeat / Extend / Clip / Mirror, packed or on disk, read in
its colour space as Cycles does), a Color Attribute node, or a Mix node (colour mode,
*Mix* or *Multiply*, a constant factor) between one of those and a constant colour.
Anything else linked keeps the old behaviour: its default value and a warning naming the
node.
"""

from __future__ import annotations

import math

import numpy as np

from ..core import envmap, textures
from .scene_export import ExportError, _image_pixels, _surface_node

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
        rgb = _image_pixels(image)                     # top row first, working space
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
    node = _surface_node(material) if material is not None else None
    if node is None or node.type not in COLOR_INPUTS:
        return None
    return color_source(node.inputs.get(COLOR_INPUTS[node.type]))


def corner_uvs(ob_eval, uv_map: str = ""):
    """(C, 2) float32 UVs per face corner of the evaluated mesh (loops order), or None."""
    mesh = ob_eval.to_mesh()
    try:
        layers = mesh.uv_layers
        if not len(layers):
            return None
        layer = (layers.get(uv_map) if uv_map else None) or layers.active
        uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        return uv.reshape(-1, 2)
    finally:
        ob_eval.to_mesh_clear()


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
        try:
            src = slot_color_source(mat)
        except (RuntimeError, ExportError, envmap.EnvironmentError_, ValueError) as exc:
            warnings.append(f"Material '{mat.name}': its texture cannot be read ({exc}); "
                            "drawn with its default colour")
            continue
        if src is None:
            continue
        if src.texture is not None:
            values = corner_uvs(ob_eval, src.texture.uv_map)
            if values is None:
                warnings.append(f"Material '{mat.name}': '{ob_eval.name}' has no UV map for "
                                "its image texture; drawn with the texture's mean colour")
                continue
        else:
            values = corner_colours(ob_eval, src.attribute)
            if values is None:
                warnings.append(f"Material '{mat.name}': '{ob_eval.name}' has no colour "
                                f"attribute '{src.attribute}'; drawn with white")
                continue
        out[slot] = (src, values)
    return out


__all__ = ["color_source", "slot_color_source", "slot_sources", "image_texture",
           "corner_uvs", "corner_colours", "mean_albedo"]
