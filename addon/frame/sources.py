"""The lights a frame draws per pixel, described in world space: the World's compact sources
split off its image (core.sphere.sources) and Blender's lamps, each a DrawnSource (a distant
disc, a sphere, a spot or an area), with the panel's line per source."""

from __future__ import annotations

import copy
import math

import numpy as np

from ...core.sphere import sources as core_lights
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
                                   "area lamp", position=lamp.position,
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
                                   f"{lamp.kind.lower()} lamp", position=lamp.position,
                                   spot=spot))
            continue
        if lamp.kind != "SUN":
            continue
        r = 0.5 * float(lamp.angle)
        E = np.asarray(lamp.color, np.float64)
        if r < POINT_RADIUS:
            out.append(DrawnSource(-np.asarray(lamp.direction), 0.0, E, "sun lamp"))
        else:
            out.append(DrawnSource(-np.asarray(lamp.direction), r,
                                   E / (math.pi * math.sin(r) ** 2), "sun lamp"))
    return out
