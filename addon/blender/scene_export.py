"""Blender scene -> core arrays: meshes, materials, world lighting.

Everything here reads Blender data and returns plain numpy/core objects (meshes,
materials, lamps, the world); it never writes to the scene.  Problems a user can fix are raised as
:class:`ExportError` with a message meant for the UI; things we can render
approximately are collected as warnings.
"""

from __future__ import annotations

import math
import os
import re

import bpy
import numpy as np

from ...core.sg import lamp_lobes
from ...core.sphere import envmap
from ...core.shading.materials import DEFAULT_MATERIAL, Material, principled_material
from ...core.scene.mesh import MeshArrays, normal_matrix
from ..frame import keys

#: Principled inputs we do not model: (socket, "is non-zero" test, what it is).
_PRINCIPLED_UNMODELLED = (
    ("Transmission Weight", lambda v: v > 0.0, "transmission"),
    ("Coat Weight", lambda v: v > 0.0, "coat"),
    ("Sheen Weight", lambda v: v > 0.0, "sheen"),
    ("Subsurface Weight", lambda v: v > 0.0, "subsurface"),
    ("Emission Strength", lambda v: v > 0.0, "emission"),
    ("Thin Film Thickness", lambda v: v > 0.0, "thin film"),
    ("Anisotropic", lambda v: v > 0.0, "anisotropy"),
    ("Diffuse Roughness", lambda v: v > 0.0, "diffuse roughness (Oren-Nayar)"),
    ("Alpha", lambda v: v < 1.0, "alpha"),
)


class ExportError(RuntimeError):
    """The scene cannot be exported; the message is shown to the user."""


# --------------------------------------------------------------------------- meshes

#: object types Cycles renders as surfaces; all of them convert with ``to_mesh()``.
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}


def hidden_in_viewport(view_layer, depsgraph) -> list:
    """Names of the view layer's geometry objects that renders show but a viewport
    depsgraph does not evaluate (``hide_viewport`` or hidden with the eye): they cannot
    be traced from the viewport, so the precompute reports them."""
    if depsgraph.mode == "RENDER":
        return []
    evaluated = {inst.object.original.name for inst in depsgraph.object_instances
                 if not inst.is_instance}
    return sorted(ob.name for ob in view_layer.objects
                  if ob.type in GEOMETRY_TYPES and not ob.hide_render
                  and ob.name not in evaluated
                  and (ob.hide_viewport or ob.hide_get(view_layer=view_layer)))


def mesh_arrays(ob_eval, matrix=None) -> MeshArrays:
    """World-space arrays of an evaluated mesh object (modifiers applied), placed by
    ``matrix`` (its own world matrix when None; the identity gives object space)."""
    mesh = ob_eval.to_mesh()
    try:
        mesh.calc_loop_triangles()
        nv, nc, nt = len(mesh.vertices), len(mesh.loops), len(mesh.loop_triangles)
        co = np.empty(nv * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        corner_verts = np.empty(nc, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", corner_verts)
        normals = np.empty(nc * 3, dtype=np.float32)
        if nc:
            mesh.corner_normals.foreach_get("vector", normals)
        tris = np.empty(nt * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("loops", tris)
        poly_mat = np.empty(len(mesh.polygons), dtype=np.int32)
        mesh.polygons.foreach_get("material_index", poly_mat)
        loop_start = np.empty(len(mesh.polygons), dtype=np.int32)
        mesh.polygons.foreach_get("loop_start", loop_start)
        loop_total = np.empty(len(mesh.polygons), dtype=np.int32)
        mesh.polygons.foreach_get("loop_total", loop_total)
    finally:
        ob_eval.to_mesh_clear()
    corner_mat = np.repeat(poly_mat, loop_total) if len(poly_mat) else np.zeros(nc, np.int32)
    M = np.array(ob_eval.matrix_world if matrix is None else matrix, dtype=np.float64)
    pos, nrm = transformed(co.reshape(-1, 3), normals.reshape(-1, 3), M)
    return MeshArrays(pos, corner_verts, nrm, tris.reshape(-1, 3), corner_mat)


def transformed(positions, normals, M):
    """Positions and unit normals (float64) placed by the 4x4 matrix ``M`` (normals by its
    inverse transpose)."""
    pos = positions.astype(np.float64) @ M[:3, :3].T + M[:3, 3]
    nrm = normals.astype(np.float64) @ normal_matrix(M).T
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        nrm = nrm / length
    return pos, nrm


def light_bounces(scene) -> int:
    """The bounces of diffuse light the scene's Cycles *Light Paths* allow:
    ``min(max_bounces, diffuse_bounces)`` (0: direct light only, as without Cycles)."""
    cycles = getattr(scene, "cycles", None)
    if cycles is None:
        return 0
    return max(0, min(int(cycles.max_bounces), int(cycles.diffuse_bounces)))


# --------------------------------------------------------------------------- materials

def _input_value(node, name, warnings, label, given=None):
    """A socket's value: ``given[name]`` when a texture drives it (its mean,
    addon.blender.texture_export), else its default (warned when another link drives it)."""
    if given and name in given:
        return given[name]
    sock = node.inputs.get(name)
    if sock is None:
        return None
    if sock.is_linked:
        warnings.append(f"{label}: '{name}' is driven by a node link; using its default value")
    v = sock.default_value
    try:
        return tuple(v)[:3]
    except TypeError:
        return float(v)


def _uses_nodes(idblock) -> bool:
    """Blender 5.0 always uses node trees (``use_nodes`` is deprecated there)."""
    return idblock.node_tree is not None and (bpy.app.version >= (5, 0, 0) or idblock.use_nodes)


def surface_node(material):
    if material is None or not _uses_nodes(material):
        return None
    out = None
    for node in material.node_tree.nodes:
        if node.type == "OUTPUT_MATERIAL" and node.target in {"ALL", "CYCLES"}:
            if out is None or node.is_active_output:
                out = node
    if out is None:
        return None
    surf = out.inputs.get("Surface")
    if surf is None or not surf.is_linked:
        return None
    return surf.links[0].from_node


def _export_principled(node, warnings, label, colour=None, given=None) -> Material:
    base = colour or _input_value(node, "Base Color", warnings, label) or (0.8, 0.8, 0.8)
    rough = _input_value(node, "Roughness", warnings, label, given)
    metal = _input_value(node, "Metallic", warnings, label, given)
    ior = _input_value(node, "IOR", warnings, label)
    level = _input_value(node, "Specular IOR Level", warnings, label, given)
    tint = _input_value(node, "Specular Tint", warnings, label)
    for name, active, what in _PRINCIPLED_UNMODELLED:
        sock = node.inputs.get(name)
        if sock is None:
            continue
        if not sock.is_linked and not active(float(sock.default_value)):
            continue
        if name == "Emission Strength":
            col = node.inputs.get("Emission Color")
            if col is not None and not col.is_linked and max(tuple(col.default_value)[:3]) <= 0.0:
                continue
        warnings.append(f"{label}: Principled {what} ('{name}') is not modelled; ignored")
    dist = getattr(node, "distribution", "MULTI_GGX")
    return principled_material(
        base_color=base,
        metallic=0.0 if metal is None else metal,
        roughness=0.5 if rough is None else rough,
        ior=1.5 if ior is None else ior,
        specular_ior_level=0.5 if level is None else level,
        specular_tint=(1.0, 1.0, 1.0) if tint is None else tint,
        distribution=dist)


def export_material(material, warnings: list, colour=None, given=None) -> Material:
    """Translate a Blender material into a core :class:`Material`.

    Supported: Diffuse BSDF (Lambert), Glossy BSDF (Beckmann, GGX, Multiscatter
    GGX with Cycles' energy compensation), Principled BSDF (base colour,
    metallic, roughness, IOR, specular IOR level, specular tint, GGX or
    Multiscatter GGX: Cycles' dielectric layer with its view-dependent
    attenuation of the base, and the F82-tint metal lobe; sheen, coat,
    transmission, subsurface, emission, thin film, alpha, anisotropy and
    diffuse roughness are reported as not modelled).  ``None`` (no material)
    is Cycles' default surface :data:`DEFAULT_MATERIAL`.  Anything else falls
    back to the material's viewport colour as a Lambert surface, with a warning.
    ``colour`` / ``given`` ({input: value}): the mean of a textured colour / scalar input.
    """
    if material is None:
        return DEFAULT_MATERIAL
    label = f"Material '{material.name}'"
    node = surface_node(material)
    if node is None:
        if _uses_nodes(material):
            return DEFAULT_MATERIAL
        c = tuple(material.diffuse_color)[:3]
        return Material(diffuse_albedo=c)
    if node.type == "BSDF_DIFFUSE":
        color = colour or _input_value(node, "Color", warnings, label)
        rough = node.inputs.get("Roughness")
        if rough is not None and (rough.is_linked or float(rough.default_value) >= 1e-5):
            warnings.append(f"{label}: Diffuse roughness (Oren-Nayar) is not modelled; "
                            "drawn as Lambert")
        return Material(diffuse_albedo=color)
    if node.type in {"BSDF_GLOSSY", "BSDF_ANISOTROPIC"}:
        color = _input_value(node, "Color", warnings, label)
        rough = _input_value(node, "Roughness", warnings, label, given)
        dist = getattr(node, "distribution", "GGX")
        if dist not in {"BECKMANN", "GGX", "MULTI_GGX"}:
            warnings.append(f"{label}: glossy distribution {dist} is drawn as GGX")
            dist = "GGX"
        aniso = node.inputs.get("Anisotropy")
        if aniso is not None and (aniso.is_linked or abs(aniso.default_value) > 1e-6):
            warnings.append(f"{label}: anisotropy is not supported yet; drawn isotropic")
        color = tuple(max(float(c), 0.0) for c in color)
        return Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=color,
                        roughness=float(rough), distribution=dist, fresnel="NONE")
    if node.type == "BSDF_PRINCIPLED":
        return _export_principled(node, warnings, label, colour, given)
    if node.type == "EMISSION":
        warnings.append(f"{label}: Emission is not a reflectance; drawn as black diffuse")
        return Material(diffuse_albedo=(0.0, 0.0, 0.0))
    warnings.append(f"{label}: '{node.bl_label}' is not supported; drawn as Lambert with the "
                    "material's viewport colour")
    return Material(diffuse_albedo=tuple(material.diffuse_color)[:3])


def object_materials(ob_eval, warnings: list, colours=None, scalars=None) -> list:
    """Core materials per material slot of an evaluated object (at least one).
    ``colours``: {slot: RGB} for slots whose colour input is textured (the mean colour of
    the texture, addon.blender.texture_export; drawn per pixel where a pass can); ``scalars``:
    {slot: {input: mean value}} of its textured scalar inputs."""
    colours, scalars = colours or {}, scalars or {}
    mats = [export_material(slot.material, warnings, colours.get(i), scalars.get(i))
            for i, slot in enumerate(ob_eval.material_slots)]
    return mats or [DEFAULT_MATERIAL]


# --------------------------------------------------------------------------- lamps

def pass_name(name: str) -> str:
    """``name`` as a render pass / light group name: letters, digits and underscores (the
    characters Blender allows in a Light Group's name; a dot would split an EXR layer)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", str(name)) or "_"


def light_group(id_block, view_layer, fallback: str) -> str:
    """The light group a lamp or the World (``id_block``) is drawn in for the
    ``Combined_<group>`` passes: its Blender Light Group (Object / World properties) when
    the view layer has one of that name, else ``fallback`` (its own name) made a pass name."""
    name = getattr(id_block, "lightgroup", "") or ""
    if name and view_layer is not None and name in {g.name for g in view_layer.lightgroups}:
        return name
    return pass_name(fallback)


def world_groups(scene, view_layer, sources: int) -> tuple[str, list]:
    """(the World's light group, each of its ``sources`` compact sources'): in the World's
    Blender Light Group its sources go with it, else each is ``<World>_Source_<k>``."""
    world = light_group(scene.world, view_layer, "World")
    grouped = scene.world is not None and view_layer is not None and \
        scene.world.lightgroup in {g.name for g in view_layer.lightgroups}
    return world, [world if grouped else f"{world}_Source_{k + 1}" for k in range(sources)]


def export_lamps(depsgraph, warnings: list | None = None) -> list:
    """Visible point/spot/sun/area lights as :class:`core.sg.lighting.Lamp` (eq. 32-33 for
    point and spot lamps; others are reported in ``warnings`` and skipped)."""
    warnings = [] if warnings is None else warnings
    lamps = []
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type != "LIGHT":
            continue
        light = ob.data
        group = light_group(ob.original, depsgraph.view_layer, ob.original.name)
        M = np.array(inst.matrix_world, dtype=np.float64)
        direction = -M[:3, 2]
        color = np.asarray(tuple(light.color), dtype=np.float64) * float(light.energy)
        if light.type == "SUN":
            lamps.append(lamp_lobes.Lamp("SUN", color=color, direction=direction,
                                          angle=float(light.angle), name=ob.name, group=group))
        elif light.type in ("POINT", "SPOT"):
            kw = dict(color=color, position=M[:3, 3], direction=direction,
                      radius=float(light.shadow_soft_size), name=ob.name, group=group)
            if light.type == "SPOT":
                kw.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
            lamps.append(lamp_lobes.Lamp(light.type, **kw))
        elif light.type == "AREA":
            sx = float(light.size)
            sy = sx if light.shape in ("SQUARE", "DISK") else float(light.size_y)
            if getattr(light, "spread", math.pi) < math.pi - 1e-4:
                warnings.append(f"Light '{ob.name}': area light spread below 180° is drawn "
                                "as 180°")
            lamp = lamp_lobes.Lamp("AREA", color=color, position=M[:3, 3],
                                    direction=direction, half_x=0.5 * sx * M[:3, 0],
                                    half_y=0.5 * sy * M[:3, 1], shape=light.shape,
                                    name=ob.name, group=group)
            if lamp.area > 0.0:
                lamps.append(lamp)
        else:
            warnings.append(f"Light '{ob.name}': {light.type} lights are not supported")
    return lamps


# --------------------------------------------------------------------------- world

def _find_world_output(tree):
    out = None
    for node in tree.nodes:
        if node.type == "OUTPUT_WORLD" and node.target in {"ALL", "CYCLES"}:
            if out is None or node.is_active_output:
                out = node
    return out


# Pixels of the newest images read from files (per path, time, colour space): the world's
# and a few textures'
_PIXEL_CACHE = keys.cache(8)


def ocio_config_path() -> str:
    """The OpenColorIO config Blender uses: ``$OCIO`` if set to a file, else its own."""
    env = os.environ.get("OCIO", "")
    if env and os.path.isfile(env):
        return env
    folder = bpy.utils.system_resource("DATAFILES", path="colormanagement")
    return os.path.join(folder, "config.ocio") if folder else ""


def working_space() -> str:
    """The blend file's scene-linear working space (configurable from Blender 5.0)."""
    cs = getattr(bpy.data, "colorspace", None)
    return getattr(cs, "working_space", "") or envmap.LINEAR_REC709


def image_pixels(image) -> np.ndarray:
    """(H, W, 3) float32 of a Blender image, top row first, scene-linear (cached)."""
    path = bpy.path.abspath(image.filepath_raw or image.filepath, library=image.library)
    from_file = (image.source == "FILE" and image.packed_file is None and not image.is_dirty
                 and path and os.path.isfile(path))
    if not from_file:          # packed/generated/edited pixels: no cheap way to tell a change
        return _read_image_pixels(image, path)
    key = (image.name_full, path, os.path.getmtime(path), os.path.getsize(path),
           image.colorspace_settings.name, working_space(), ocio_config_path())
    return keys.held(_PIXEL_CACHE, key, (), lambda: _read_image_pixels(image, path))


def _to_working_space(image, pixels) -> np.ndarray:
    cs = image.colorspace_settings
    return envmap.to_working_space(pixels, cs.name, working_space(), ocio_config_path(),
                                   is_data=cs.is_data)


def _read_image_pixels(image, path) -> np.ndarray:
    """Pixels converted once from the image's colour space to the working space."""
    if image.packed_file is None and image.source == "FILE":
        if not path or not os.path.isfile(path):
            raise ExportError(f"Environment image '{image.name}' is missing: {path or '(no path)'}")
        if envmap.have_openimageio():
            return _to_working_space(image, envmap.load_equirect(path))   # raw file values
    # Packed, generated or no OpenImageIO: Blender's own pixels (bottom row first).
    w, h = image.size
    if w == 0 or h == 0 or not image.has_data and not _try_load(image):
        raise ExportError(f"Environment image '{image.name}' has no pixels")
    buf = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    buf = envmap.as_rgb(buf.reshape(h, w, image.channels)[::-1])
    # Blender converts float buffers to the working space on load; byte buffers read
    # back as the stored bytes / 255, still in the image's colour space.
    return buf if image.is_float else _to_working_space(image, buf)


def _try_load(image):
    try:
        image.reload()
        return image.has_data or image.size[0] > 0
    except RuntimeError:
        return False


def _mapping_rotation(node, warnings) -> np.ndarray:
    """World -> texture rotation of a Mapping node feeding the Environment Texture."""
    rot_sock = node.inputs.get("Rotation")
    if rot_sock is None:
        return np.eye(3)
    if rot_sock.is_linked:
        warnings.append("World: Mapping rotation is driven by a link; using its default value")
    R = envmap.euler_xyz_matrix(*rot_sock.default_value)
    vtype = getattr(node, "vector_type", "POINT")
    scale = node.inputs.get("Scale")
    if scale is not None and not np.allclose(tuple(scale.default_value), 1.0):
        warnings.append("World: Mapping scale is ignored for directions")
    return R.T if vtype == "TEXTURE" else R        # TEXTURE applies the inverse


def export_world(scene, warnings: list) -> envmap.WorldLighting:
    """The scene's world as :class:`WorldLighting` (raises :class:`ExportError`)."""
    world = scene.world
    if world is None:
        raise ExportError("The scene has no World: add one with an Environment Texture")
    if not _uses_nodes(world):
        return envmap.WorldLighting(color=tuple(world.color)[:3], strength=1.0)
    out = _find_world_output(world.node_tree)
    if out is None or not out.inputs["Surface"].is_linked:
        raise ExportError(f"World '{world.name}' has no World Output with a Surface link")
    bg = out.inputs["Surface"].links[0].from_node
    if bg.type != "BACKGROUND":
        raise ExportError(f"World '{world.name}': the surface must be a Background node "
                          f"(found '{bg.bl_label}')")
    strength_sock = bg.inputs["Strength"]
    if strength_sock.is_linked:
        warnings.append("World: Background strength is linked; using its default value")
    strength = float(strength_sock.default_value)
    if strength < 0.0:
        warnings.append(f"World: Background Strength is negative ({strength:g}): negative light "
                        "is not drawn (the frame is clamped at zero); use a positive Strength")
    color_sock = bg.inputs["Color"]
    if not color_sock.is_linked:
        return envmap.WorldLighting(color=tuple(color_sock.default_value)[:3], strength=strength)
    tex = color_sock.links[0].from_node
    if tex.type != "TEX_ENVIRONMENT":
        raise ExportError(f"World '{world.name}': Background colour must come from an "
                          f"Environment Texture (found '{tex.bl_label}')")
    if tex.projection != "EQUIRECTANGULAR":
        raise ExportError("World: only Equirectangular environment projection is supported")
    if tex.image is None:
        raise ExportError(f"World '{world.name}': the Environment Texture has no image")
    rotation = np.eye(3)
    vec = tex.inputs.get("Vector")
    if vec is not None and vec.is_linked:
        src = vec.links[0].from_node
        if src.type == "MAPPING":
            rotation = _mapping_rotation(src, warnings)
        elif src.type != "TEX_COORD":
            warnings.append(f"World: '{src.bl_label}' before the Environment Texture is ignored")
    try:    # WorldLighting validates the pixels (NaN/Inf) once
        return envmap.WorldLighting(image=image_pixels(tex.image), strength=strength,
                                    rotation=rotation)
    except envmap.EnvironmentError_ as exc:
        raise ExportError(f"Environment image '{tex.image.name}': {exc}") from exc
