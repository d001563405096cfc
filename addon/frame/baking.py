"""Baking (``prt.bake``): the relit irradiance, radiance or ambient occlusion of objects per
face corner, written into an image texture on a UV map (rasterized on the GPU, dilated at
the islands' seams) or into a Color Attribute, under the World's current rotation or for a
list of turns about +Z: a normal Blender image / attribute that EEVEE, Cycles, the glTF
exporter and game engines read.

The values are those of the frame at its shading points, interpolated across triangles:
*irradiance* is the whole World through each point's stored visibility (REFERENCE's exact
sum over the cubemap, its compact sources included), the lamps (each as a point, with a
shadow ray) and the bounced light; *radiance* is the active method's per-vertex radiance
(the World less its compact sources, the bounce) plus the diffuse light of the sources and
lamps toward the scene camera (their glossy highlights are drawn per pixel only); *AO* the
cosine-weighted open sky.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ...core.methods.reference import shading as reference
from ...core.scene import textures
from ...core.shading.materials import slot_material
from ...core.sphere import directions
from ...core.transport import bounce as core_bounce
from ..blender import attributes, texture_export
from ..gpu import drawing
from . import bounce, keys, relit, sources
from .engine import in_render, render_camera
from .state import FrameState

#: what can be baked, and its name in the images and attributes made
QUANTITIES = {"IRRADIANCE": "Irradiance", "RADIANCE": "Radiance", "AO": "Occlusion"}
TARGETS = ("IMAGE", "COLOR_ATTRIBUTE")


def parse_turns(text: str) -> list[float]:
    """World turns in radians from degrees separated by spaces or commas ("" = [0])."""
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        degrees = [float(p) for p in parts] or [0.0]
    except ValueError:
        raise ValueError(f"Rotations must be numbers of degrees (e.g. '0 90 180'), got "
                         f"'{text}'") from None
    if not all(math.isfinite(d) for d in degrees):
        raise ValueError("Rotations must be finite numbers of degrees")
    return [math.radians(d) for d in degrees]


def turned(state: FrameState, angle: float) -> FrameState:
    """``state`` lit by its World turned by ``angle`` about +Z (its compact sources with it,
    as the World's Mapping rotation turns them)."""
    if angle == 0.0:
        return state
    sub = copy.copy(state)
    sub.world = relit.rotated_world(state.world, angle)
    sub.full_world = relit.rotated_world(state.full_world, angle)
    sub.background = None
    c, s = math.cos(angle), math.sin(angle)
    back = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])    # the turn's transpose
    sub.sources = [sources.DrawnSource(back @ src.direction, src.radius, src.radiance, src.name)
                   for src in state.sources]
    return sub


def _lamp_light(state):
    """``(lamps, leaving)``: a state's lamps, and ``leaving(st)``, the occlusion test of the
    shadow rays that leave its object ``st`` (against its objects; None without one)."""
    lamps = list(state.lamps) + list(state.drawn_lamps)
    casters = [st for st in state.objects if st.status != "unshadowed"]
    test = bounce.occlusion_test(casters) if lamps and casters else None
    index = {id(c): j for j, c in enumerate(casters)}

    def leaving(st):
        if test is None:
            return None
        k = index.get(id(st), -1)
        return lambda o, d, t, rows: test(o, d, t, np.full(len(o), k))
    return lamps, leaving


def point_irradiance(state: FrameState) -> list:
    """Per object (P, 3) irradiance at its shading points (module docstring)."""
    cube = directions.cubemap(state.resolution)
    env = keys.environment_cubemap(state.full_world, state.resolution)
    lamps, leaving = _lamp_light(state)
    bounced = state.bounce.irradiance(state) if state.bounce is not None \
        else [None] * len(state.objects)
    out = []
    for st, extra in zip(state.objects, bounced):
        pts = st.points
        E = reference.diffuse_irradiance(st.bits, pts.normals, cube, env).astype(np.float64)
        if lamps:
            E += core_bounce.lamp_irradiance(lamps, pts.positions, pts.normals,
                                             leaving(st))
        if extra is not None:
            E += extra
        out.append(E)
    return out


def corner_radiance(state: FrameState, eye, view_dir) -> list:
    """Per object (C, 3) radiance toward the camera (module docstring)."""
    frame = state.shade(eye, view_dir)
    cube = directions.cubemap(state.resolution)
    full = keys.environment_cubemap(state.full_world, state.resolution)
    rest = keys.environment_cubemap(state.world, state.resolution)
    lamps, leaving = _lamp_light(state)
    out = []
    for st, rad in zip(state.objects, frame):
        pts = st.points
        pairs = reference.horizon_pairs(st.bits, pts.normals, cube)     # both sums' clamp
        E = (reference.diffuse_irradiance(st.bits, pts.normals, cube, full, pairs=pairs)
             - reference.diffuse_irradiance(st.bits, pts.normals, cube, rest, pairs=pairs)
             ).astype(np.float64)
        if lamps:
            E += core_bounce.lamp_irradiance(lamps, pts.positions, pts.normals,
                                             leaving(st))
        views = reference.point_views(pts.positions, eye, view_dir)
        lit = np.zeros((pts.count, 3))
        for m in np.unique(pts.materials):
            sel = np.nonzero(pts.materials == m)[0]
            lit[sel] = reference.lambert_layer(slot_material(st.materials, m), E[sel],
                                               pts.normals[sel], views[sel])
        out.append(np.asarray(rad, np.float64)[:, :3] + lit[pts.point_of_corner])
    return out


def corner_values(state: FrameState, quantity: str, camera=None) -> list:
    """Per object (C, 3): ``quantity`` at every corner (``camera``: frame_camera's dict,
    needed by RADIANCE)."""
    if quantity == "RADIANCE":
        return corner_radiance(state, camera["eye"], camera["view_dir"])
    if quantity == "IRRADIANCE":
        return [E[st.points.point_of_corner] for st, E in zip(state.objects,
                                                               point_irradiance(state))]
    cube = directions.cubemap(state.resolution)
    return [np.repeat(reference.sky_visibility(st.bits, st.points.normals, cube)[
        st.points.point_of_corner][:, None], 3, axis=1) for st in state.objects]


def rasterize(scene, uvs, values, triangles, size: int, margin: int) -> np.ndarray:
    """(size, size, 4) float32 rows from v = 0: per-corner ``values`` drawn in UV space
    (each texel centre inside a triangle gets its interpolated value), dilated by
    ``margin`` texels (:func:`core.scene.textures.dilate`); alpha 1 where filled."""
    from mathutils import Matrix
    to_clip = Matrix(((2.0, 0.0, 0.0, -1.0), (0.0, 2.0, 0.0, -1.0), (0.0, 0.0, 1.0, 0.0),
                      (0.0, 0.0, 0.0, 1.0)))
    pos = np.zeros((len(uvs), 3), np.float32)
    pos[:, :2] = uvs

    def task(_depsgraph):
        batch = drawing.data_batch(pos, values, triangles)
        return drawing.render_offscreen([batch], None, to_clip, size, size, True,
                                        shader=drawing.data_shader())
    with drawing.temporary_camera(scene):
        px = in_render(scene, task)
    rgb, covered = textures.dilate(px[..., :3], px[..., 3] > 0.5, margin)
    out = np.zeros((size, size, 4), np.float32)
    out[..., :3] = np.where(covered[..., None], rgb, 0.0)
    out[..., 3] = covered
    return out


def _image(name: str, rgba: np.ndarray):
    import bpy
    size = rgba.shape[0]
    img = bpy.data.images.get(name)
    if img is not None and (tuple(img.size) != (size, size) or not img.is_float):
        bpy.data.images.remove(img)
        img = None
    if img is None:
        img = bpy.data.images.new(name, size, size, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    img.pixels.foreach_set(np.ascontiguousarray(rgba, np.float32).reshape(-1))
    img.file_format = "OPEN_EXR"
    img.pack()                          # saved inside the .blend, as linear EXR
    return img


def bake(scene, depsgraph, names, quantity: str, target: str, uv_map: str = "",
         size: int = 1024, margin: int = 16, turns=(0.0,)) -> tuple[list, list]:
    """Bake ``quantity`` of the objects named ``names`` into ``target``; returns (names of
    the images / attributes made, notes).  Checks everything before writing anything:
    bad input raises ValueError and leaves the scene as it was."""
    import bpy
    if quantity not in QUANTITIES or target not in TARGETS:
        raise ValueError(f"Unknown bake {quantity} into {target}")
    state = FrameState()
    state.sync(depsgraph)
    if state.error:
        raise ValueError(state.error)
    chosen = [st for st in state.objects if st.name in set(names)]
    if not chosen:
        raise ValueError("Select the mesh objects to bake (visible ones the engine draws)")
    notes = [f"'{st.name}' has no precompute: baked without its shadows"
             for st in chosen if st.status != "ok"]
    camera = None
    if quantity == "RADIANCE":
        camera = render_camera(scene, depsgraph)
        if camera is None:
            raise ValueError("Radiance depends on the view: the scene needs a camera")
    uvs, meshes = {}, {}
    for st in chosen:
        ob = bpy.data.objects[st.name]
        if target == "IMAGE":
            layers = [layer.name for layer in ob.data.uv_layers]
            if uv_map and uv_map not in layers or not layers:
                raise ValueError(f"'{st.name}' has no UV map '{uv_map}' (it has: "
                                 f"{', '.join(layers) or 'none'})")
            uvs[st.name] = texture_export.corner_uvs(ob.evaluated_get(depsgraph), uv_map)
        else:
            why = []
            meshes[st.name] = attributes.mesh_for(ob, st.arrays.front_corners, why.append)
            if meshes[st.name] is None:
                raise ValueError(why[0] if why else f"'{st.name}' cannot take attributes")
    made = []
    label = QUANTITIES[quantity]
    index = {id(st): i for i, st in enumerate(state.objects)}
    for angle in turns:
        sub = turned(state, angle)
        values = corner_values(sub, quantity, camera)
        suffix = "" if list(turns) == [0.0] else f" {math.degrees(angle):g}°"
        for st in chosen:
            v = values[index[id(st)]][:st.arrays.front_corners]
            if target == "COLOR_ATTRIBUTE":
                rgba = np.ones((len(v), 4), np.float32)
                rgba[:, :3] = v
                name = f"PRT {label}{suffix}"
                attributes.write(meshes[st.name], name, rgba, "FLOAT_COLOR")
                meshes[st.name].update()
            else:
                tris = st.arrays.triangles[:st.arrays.front_triangles]
                name = f"PRT {label} {st.name}{suffix}"
                _image(name, rasterize(scene, uvs[st.name], v, tris, int(size), int(margin)))
            made.append(name)
    return made, notes
