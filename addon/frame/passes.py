"""F12's render passes beside Combined, named as Cycles names them: the data passes (Depth,
Position, Normal), Ambient Occlusion, Environment, Diffuse / Glossy Direct, Indirect and
Color, and one ``Combined_<group>`` pass per light group (the World, each compact source of
it, each lamp, or the view layer's Light Groups), so a compositor can rebalance the lights
after the render.

A light group's pass is the frame drawn again with every light outside the group muted
(its radiance zero; the World's strength zero): every part of a frame (the method's World
radiance, the per-pixel sources and lamps, the sharp lobes, the bounced light, the
background) is linear in the lights, so the groups' passes sum to Combined.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np

from ...core.methods.reference import shading as reference
from ...core.shading import pixel_filter
from ...core.shading.materials import slot_material
from ...core.sphere import directions
from ..blender import scene_export
from ..gpu import drawing
from . import sources as frame_sources

#: (view layer toggle, pass name, channels, channel ids, type) of the passes drawn beside
#: Combined when the view layer asks for them (Cycles' names: cycles/engine.py)
DATA_PASSES = (
    ("use_pass_z", "Depth", 1, "Z", "VALUE"),
    ("use_pass_position", "Position", 3, "XYZ", "VECTOR"),
    ("use_pass_normal", "Normal", 3, "XYZ", "VECTOR"),
    ("use_pass_ambient_occlusion", "Ambient Occlusion", 3, "RGB", "COLOR"),
    ("use_pass_environment", "Environment", 3, "RGB", "COLOR"),
)
#: the light passes Cycles splits Combined into: (Diffuse Direct + Indirect) × Diffuse Color
#: + (Glossy Direct + Indirect) × Glossy Color + Environment (``engine.light_passes``)
LIGHT_PASSES = (
    ("use_pass_diffuse_direct", "Diffuse Direct", 3, "RGB", "COLOR"),
    ("use_pass_diffuse_indirect", "Diffuse Indirect", 3, "RGB", "COLOR"),
    ("use_pass_diffuse_color", "Diffuse Color", 3, "RGB", "COLOR"),
    ("use_pass_glossy_direct", "Glossy Direct", 3, "RGB", "COLOR"),
    ("use_pass_glossy_indirect", "Glossy Indirect", 3, "RGB", "COLOR"),
    ("use_pass_glossy_color", "Glossy Color", 3, "RGB", "COLOR"),
)
#: the Depth of a pixel no surface covers (Cycles writes 1e10 there)
FAR_DEPTH = 1e10


def groups_wanted(scene, view_layer) -> bool:
    """Whether F12 writes light group passes: ``scene.prt.light_group_passes``, or the view
    layer has Blender Light Groups."""
    return bool(scene.prt.light_group_passes or len(view_layer.lightgroups))


def light_groups(state) -> list[str]:
    """The frame's light groups in order, each once: the World's, its sources', its lamps'."""
    names = [state.world_group, *state.source_groups,
             *(lamp.group or "Lamp" for lamp in list(state.lamps) + list(state.drawn_lamps))]
    return list(dict.fromkeys(names))


def scene_light_groups(scene, view_layer) -> list[str]:
    """:func:`light_groups` as the scene describes them before a frame is drawn (the
    compositor's sockets): the sources of the newest split (``frame.sources.LAST_SOURCES``)
    and the view layer's visible lamps."""
    world, source_groups = scene_export.world_groups(scene, view_layer,
                                                     len(frame_sources.LAST_SOURCES))
    names = [world, *source_groups]
    for ob in scene.objects:
        if ob.type == "LIGHT" and ob.visible_get(view_layer=view_layer):
            names.append(scene_export.light_group(ob, view_layer, ob.name))
    return list(dict.fromkeys(names))


def wanted(scene, view_layer) -> list[tuple]:
    """(name, channels, channel ids, type) of every pass beside Combined F12 writes."""
    out = [(name, n, chan, kind) for attr, name, n, chan, kind in DATA_PASSES + LIGHT_PASSES
           if getattr(view_layer, attr, False)]
    if groups_wanted(scene, view_layer):
        out += [(f"Combined_{g}", 3, "RGB", "COLOR") for g in scene_light_groups(scene,
                                                                                  view_layer)]
    return out


def _muted_world(world):
    if world is None:
        return None
    out = copy.copy(world)
    out.strength = 0.0
    return out


def muted(state, group: str):
    """A copy of ``state`` lit by the lights of ``group`` alone (the others' radiance zero,
    their shadow maps and order kept, so each light is drawn exactly as in Combined)."""
    sub = copy.copy(state)
    if state.world_group != group:
        sub.world, sub.full_world = _muted_world(state.world), _muted_world(state.full_world)
        sub.world_muted = True
        sub.background = None
    sub.sources = [s if g == group else
                   frame_sources.DrawnSource(s.direction, s.radius, 0.0 * s.radiance, s.name,
                                             s.position, s.spot, s.area)
                   for s, g in zip(state.sources, state.source_groups)]
    dark = (0.0, 0.0, 0.0)
    sub.lamps = [lamp if lamp.group == group else replace(lamp, color=dark)
                 for lamp in state.lamps]
    sub.drawn_lamps = [lamp if lamp.group == group else replace(lamp, color=dark)
                       for lamp in state.drawn_lamps]
    return sub


def with_base(state, base: float):
    """A copy of ``state`` without bounced light whose every slot has the diffuse base
    colour ``base`` (0 or 1; textured colours dropped): its frame is the glossy light
    (0) or the glossy light plus the diffuse light of a white base (1).  A frame is linear
    in each slot's base colour (``FrameState.shade``), so the diffuse part of a frame is
    its own minus the one of base 0."""
    sub = copy.copy(state)
    sub.bounce = None
    sub.objects = []
    for st in state.objects:
        twin = copy.copy(st)
        twin.data = st.data
        twin.materials = [replace(m, diffuse_albedo=(base, base, base)) for m in st.materials]
        twin.textures = {}
        sub.objects.append(twin)
    return sub


def base_colours(state) -> list:
    """Per object the per-corner base colour (C, 3) a frame's diffuse light is multiplied
    by; a textured slot's as ``TexturedRadiance`` whose texture multiplies 1 per pixel."""
    from .state import TexturedRadiance
    out = []
    for st in state.objects:
        pts = st.points
        table = np.array([slot_material(st.materials, m).diffuse_albedo
                          for m in range(max(len(st.materials), 1))], np.float32)
        colour = table[np.clip(pts.materials, 0, len(table) - 1)][pts.point_of_corner]
        if st.textures:
            textured = np.isin(st.slot_of[np.clip(pts.materials, 0, len(st.slot_of) - 1)],
                               list(st.textures))[pts.point_of_corner]
            unit = np.where(textured[:, None], 1.0, colour).astype(np.float32)
            colour = TexturedRadiance.of(colour, unit, np.zeros_like(colour))
        out.append(colour)
    return out


def divided(light: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """A light pass: ``light`` (a colour times the light, filtered) over its filtered
    ``colour``, 0 where the colour is (Cycles' division, so pass × colour = ``light``)."""
    safe = np.abs(colour) > 1e-8
    return np.where(safe, light / np.where(safe, colour, 1.0), 0.0).astype(np.float32)


# --------------------------------------------------------------------------- data passes

def _corner_values(state, view, name):
    """Per object, per corner (C, 3): what the data pass ``name`` draws."""
    V = np.array(view, dtype=np.float64)
    cube = directions.cubemap(state.resolution)
    out = []
    for st in state.objects:
        arrays = st.arrays
        pos = arrays.positions[arrays.corner_verts].astype(np.float64)
        if name == "Position":
            out.append(pos)
        elif name == "Normal":
            out.append(np.asarray(arrays.corner_normals, np.float64))
        elif name == "Depth":         # along the camera's axis (Cycles' camera_z_depth)
            z = -(pos @ V[2, :3] + V[2, 3])
            out.append(np.repeat(z[:, None], 3, axis=1))
        else:                         # Ambient Occlusion: the cosine-weighted open sky
            ao = st.data.get("pass_ao")
            if ao is None:
                ao = st.data["pass_ao"] = reference.sky_visibility(
                    st.bits, st.points.normals, cube)
            out.append(np.repeat(ao[st.points.point_of_corner][:, None], 3, axis=1))
    return out


def _draw_values(state, values, view_projection, width, height):
    """Per-corner ``values`` drawn unclamped at pixel centres: (H, W, 4), alpha the coverage."""
    batches = [drawing.data_batch(st.arrays.positions[st.arrays.corner_verts], v,
                                  st.arrays.triangles, st.closed_side)
               for st, v in zip(state.objects, values)]
    return drawing.render_offscreen(batches, None, view_projection, width, height, True,
                                    shader=drawing.data_shader())


def data_pass(state, name, view, projection, width, height, supersampling=1,
              filter_width=0.0) -> np.ndarray:
    """One data pass, (H, W, channels) bottom row first: Depth, Position and Normal at each
    pixel's centre (not filtered: a mean of depths or normals across an edge is no surface's);
    Ambient Occlusion filtered as Combined is."""
    values = _corner_values(state, view, name)
    if name == "Ambient Occlusion":
        s = max(1, int(supersampling))
        big = _draw_values(state, values, projection @ view, width * s, height * s)
        px = pixel_filter.resolve(big, s, filter_width) if s > 1 else big
        return px[..., :3]
    px = _draw_values(state, values, projection @ view, width, height)
    covered = px[..., 3] > 0.5
    if name == "Depth":
        return np.where(covered, px[..., 0], FAR_DEPTH)[..., None].astype(np.float32)
    rgb = px[..., :3]
    if name == "Normal":
        length = np.linalg.norm(rgb, axis=2, keepdims=True)
        rgb = np.where(length > 1e-12, rgb / np.maximum(length, 1e-12), 0.0)
    return np.where(covered[..., None], rgb, 0.0).astype(np.float32)
