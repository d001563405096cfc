"""The lights a frame draws per pixel, described in world space: the World's compact sources
split off its image (core.sphere.sources) and Blender's lamps, each a DrawnSource (a distant
disc, a sphere, a spot or an area), with the panel's line per source; and the plan of their
shadow maps (:func:`shadow_plan`): every source gets one, in atlases whose tiles shrink, as
the panel and the render log say, when many sources would pass the atlases' budgets."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from ...core.sphere import sources as core_lights
from ...core.pipeline import frame_status
from . import keys

#: below this angular radius (rad) a source is point-like: its power at its centre
POINT_RADIUS = 1e-4


# extraction per (image content, settings): (core sources, residual image)
_SPLITS = keys.cache(2, name="sources._SPLITS")


#: one line per source of the last synced frame, for the panel
LAST_SOURCES: list = []


def describe(source, total_power: float) -> str:
    """A panel line: elevation/azimuth, angular diameter and share of the world's light."""
    d = source.direction
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, float(d[2])))))
    azimuth = math.degrees(math.atan2(float(d[1]), float(d[0])))
    share = float(source.radiance @ core_lights.LUMINANCE) * (
        2.0 * math.pi * (1.0 - math.cos(source.radius))) / max(total_power, 1e-30)
    return (f"{source.name}: elevation {elevation:.0f}°, azimuth {azimuth:.0f}°, "
            f"{math.degrees(2.0 * source.radius):.2f}° wide, {share:.0%} of the light")


class DrawnSource:
    """A source as the pass draws it, in world space: a distant disc (the world's sources,
    sun lamps) or, with a ``position``, a local lamp (point or spot: a sphere of radius
    ``radius`` and power ``radiance`` (watts times colour); ``spot`` = (axis the lamp shines
    along, cos of its half angle, smoothstep width); ``area`` = (half_x, half_y, ellipse) of
    an area lamp: then ``radiance`` is its radiance, ``direction`` the way it faces and
    ``radius`` that of the disc of its area (its shadow's softness))."""

    __slots__ = ("direction", "radius", "radiance", "name", "position", "spot", "area")

    def __init__(self, direction, radius, radiance, name, position=None, spot=None, area=None):
        self.direction = np.asarray(direction, np.float64) / max(np.linalg.norm(direction),
                                                                 1e-300)
        self.radius = float(radius)
        #: (3,) radiance of the disc, the irradiance at normal incidence when point-like,
        #: or a local lamp's power
        self.radiance = np.asarray(radiance, np.float64)
        self.name = name
        self.position = None if position is None else np.asarray(position, np.float64)
        self.spot = spot
        self.area = area

    @property
    def point_like(self) -> bool:
        return self.radius < POINT_RADIUS

    @property
    def local(self) -> bool:
        return self.position is not None


def extraction_settings(prt) -> dict:
    return dict(max_sources=int(prt.light_sources), threshold=float(prt.light_threshold),
                min_share=float(prt.light_min_share))


def split_world(world, settings: dict):
    """``(residual world, sources)``: the world with its compact sources taken out (the
    same pixel array for the same image and settings, so caches keyed on it hold), and
    the sources in world space with the world's strength.  No split for a uniform world,
    ``max_sources = 0`` or a non-positive strength."""
    img = world.image
    LAST_SOURCES.clear()
    if img is None or settings["max_sources"] <= 0 or world.strength <= 0.0:
        return world, []
    # keyed on the pixels' content: a packed image is exported as a new array every sync
    key = (keys.image_key(img), tuple(sorted(settings.items())))

    def split():
        # the image's luminance power (the panel's shares) rides with its split: a turn
        # of the world changes neither
        unit = copy.copy(world)
        unit.strength = 1.0
        return (*core_lights.extract_sources(img, **settings),
                float(unit.total_power() @ core_lights.LUMINANCE))
    sources, residual, image_power = keys.held(_SPLITS, key, (), split)
    if not sources:
        return world, []
    out = copy.copy(world)
    out.image = residual
    R = np.asarray(world.rotation, np.float64)        # texture = R @ world
    drawn = [DrawnSource(R.T @ s.direction, s.radius, s.radiance * world.strength,
                         f"Source {k + 1}") for k, s in enumerate(sources)]
    total = image_power * world.strength
    LAST_SOURCES[:] = [describe(s, total) for s in drawn]
    return out, drawn


def lamp_sources(lamps) -> list:
    """Blender lamps: a sun is a disc of half its angle whose strength is the irradiance
    at normal incidence (Cycles' distant light); a point or spot lamp a sphere of its
    radius giving Phi / (4 pi d^2) at normal incidence (Cycles), a spot masked by its
    cone's smoothstep (core.sg.lighting); an area lamp a rectangle or ellipse of
    radiance Phi / (pi A) on its front side."""
    out = []
    for lamp in lamps:
        if lamp.kind == "AREA":             # a one-sided Lambertian emitter of Phi / (pi A)
            A = lamp.area
            ellipse = lamp.shape in ("DISK", "ELLIPSE")
            out.append(DrawnSource(lamp.direction, math.sqrt(A / math.pi),
                                   np.asarray(lamp.color, np.float64) / (math.pi * A),
                                   _lamp_name(lamp), position=lamp.position,
                                   area=(np.asarray(lamp.half_x, np.float64),
                                         np.asarray(lamp.half_y, np.float64), ellipse)))
            continue
        if lamp.kind in ("POINT", "SPOT"):
            spot = None
            if lamp.kind == "SPOT":
                cos_half = math.cos(0.5 * lamp.spot_size)
                spot = (np.asarray(lamp.direction, np.float64), cos_half,
                        (1.0 - cos_half) * lamp.spot_blend)
            out.append(DrawnSource(lamp.direction, max(float(lamp.radius), 0.0),
                                   np.asarray(lamp.color, np.float64),
                                   _lamp_name(lamp), position=lamp.position,
                                   spot=spot))
            continue
        if lamp.kind != "SUN":
            continue
        r = 0.5 * float(lamp.angle)
        E = np.asarray(lamp.color, np.float64)
        if r < POINT_RADIUS:
            out.append(DrawnSource(-np.asarray(lamp.direction), 0.0, E, _lamp_name(lamp)))
        else:
            out.append(DrawnSource(-np.asarray(lamp.direction), r,
                                   E / (math.pi * math.sin(r) ** 2), _lamp_name(lamp)))
    return out


def _lamp_name(lamp) -> str:
    kind = f"{lamp.kind.lower()} lamp"
    return f"{kind} '{lamp.name}'" if getattr(lamp, "name", "") else kind


# --------------------------------------------------------------------------- shadow maps

#: the six 90-degree faces of a local lamp's shadow cube, in lights_frag.glsl's order
CUBE_AXES = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0],
                      [0, 0, -1.0]])
#: every direction of a cube face lies within acos(1 / sqrt 3) of its axis
FACE_CONE = math.acos(1.0 / math.sqrt(3.0))
#: the face choice's margin: the look-up offsets the receiver along its normal
FACE_MARGIN = math.radians(3.0)

#: texels per side of a distant source's shadow tile (an orthographic view of the scene),
#: and of a local lamp's cube face, at full size and at least
SHADOW_TILE, SHADOW_TILE_MIN = 2048, 256
CUBE_TILE, CUBE_TILE_MIN = 1024, 128
#: the atlases' budgets in texels (float32 maps: 4 bytes a texel, the cube faces' depth
#: buffer as much again): 8 distant tiles, or 48 faces (eight point lamps), at full size
SHADOW_BUDGET = 8 * SHADOW_TILE ** 2
CUBE_BUDGET = 48 * CUBE_TILE ** 2
#: an atlas's side at most (every OpenGL 4.3 device has 16384)
ATLAS_SIDE = 16384


def lamp_faces(source) -> tuple:
    """Which faces of a local lamp's shadow cube it can light through (True per face of
    :data:`CUBE_AXES`): a spot the faces meeting its cone, an area lamp those meeting the
    half-space in front of it, a point lamp all six."""
    if source.area is not None:
        axis, reach = source.direction, 0.5 * math.pi
    elif source.spot is not None:
        axis, reach = source.spot[0], math.acos(max(-1.0, min(1.0, float(source.spot[1]))))
    else:
        return (True,) * 6
    angle = np.arccos(np.clip(CUBE_AXES @ np.asarray(axis, np.float64), -1.0, 1.0))
    return tuple(bool(a) for a in angle < reach + FACE_CONE + FACE_MARGIN)


def tile_size(count: int, full: int, least: int, budget: int) -> int:
    """The largest power-of-two halving of ``full``, down to ``least``, at which ``count``
    tiles fit ``budget`` texels."""
    size = full
    while size > least and count * size * size > budget:
        size //= 2
    return size


def atlas_grid(count: int, size: int) -> tuple[int, int]:
    """(columns, rows) of ``count`` square tiles of ``size`` texels in a near-square atlas
    whose sides stay within :data:`ATLAS_SIDE`."""
    cols = max(1, min(math.ceil(math.sqrt(max(count, 1))), ATLAS_SIDE // size))
    return cols, max(1, math.ceil(count / cols))


@dataclass
class ShadowPlan:
    """How a frame's sources get their shadow maps (addon/gpu/lights.py draws them):
    ``distant_tile`` texels per side of each distant source's tile, ``face_tile`` of each
    local lamp's cube face, ``faces`` per local lamp (in the frame's order) the faces it
    draws (none: drawn without a shadow, past the budget), ``distant_shadowed`` how many
    distant sources (the first) have a tile, and the messages saying what the budget
    changed."""

    distant_tile: int = SHADOW_TILE
    face_tile: int = CUBE_TILE
    faces: list = field(default_factory=list)
    distant_shadowed: int = 0
    messages: list = field(default_factory=list)


def _names(sources) -> str:
    return frame_status.listing(s.name for s in sources)


def shadow_plan(sources) -> ShadowPlan:
    """Every source's shadow map within the atlases' budgets: at full size while they fit,
    else every tile of that atlas halved until they do (down to the least size); sources
    past even that are drawn without a shadow.  Both are said in ``messages``."""
    distant = [s for s in sources if not s.local]
    local = [s for s in sources if s.local]
    plan = ShadowPlan()
    plan.distant_tile = tile_size(len(distant), SHADOW_TILE, SHADOW_TILE_MIN, SHADOW_BUDGET)
    plan.distant_shadowed = min(len(distant), SHADOW_BUDGET // plan.distant_tile ** 2)
    if plan.distant_tile < SHADOW_TILE:
        plan.messages.append(
            f"Shadow maps: {len(distant)} distant sources share the atlas at "
            f"{plan.distant_tile}² texels each ({SHADOW_TILE}² up to "
            f"{SHADOW_BUDGET // SHADOW_TILE ** 2})")
    if plan.distant_shadowed < len(distant):
        plan.messages.append(
            f"Shadow maps: {len(distant) - plan.distant_shadowed} distant sources past the "
            f"atlas's budget cast no shadow: {_names(distant[plan.distant_shadowed:])}")
    wanted = [lamp_faces(s) for s in local]
    count = sum(sum(f) for f in wanted)
    plan.face_tile = size = tile_size(count, CUBE_TILE, CUBE_TILE_MIN, CUBE_BUDGET)
    room, unshadowed = CUBE_BUDGET // (size * size), []
    for s, faces in zip(local, wanted):
        if sum(faces) > room:
            faces = (False,) * 6
            unshadowed.append(s)
        room -= sum(faces)
        plan.faces.append(faces)
    if size < CUBE_TILE:
        plan.messages.append(
            f"Shadow maps: {len(local)} local lamps draw {count} cube faces at {size}² "
            f"texels each ({CUBE_TILE}² up to {CUBE_BUDGET // CUBE_TILE ** 2} faces)")
    if unshadowed:
        plan.messages.append(
            f"Shadow maps: {len(unshadowed)} local lamps past the atlas's budget cast no "
            f"shadow: {_names(unshadowed)}")
    return plan
