"""Normal Map and Bump nodes against Cycles: a mapped plane under a low sun and a broad sky,
drawn by every method: slow."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2

from ...cases.normal_maps import mapped_plane


# --------------------------------------------------------------------------- Blender

def _low_sun_world():
    """One bright pixel 20° above the horizon, toward -x, over a dim sky."""
    el = math.radians(20.0)
    sky = scenes.sun_image(256, 128, (-math.cos(el), 0.0, math.sin(el)), radiance=2e4)
    sky += 0.02
    scenes.add_world(image=scenes.float_image("sky", sky))


def _broad_sky_world():
    """A smooth sky, brightest 30° above the horizon toward -x (no compact source is split
    off: every method shades all of it from its transfer)."""
    h, w = 64, 128
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)      # u = 0.5 - atan2(y, x) / 2 pi
    d = np.stack(np.broadcast_arrays(np.sin(theta)[:, None] * np.cos(phi)[None],
                                     np.sin(theta)[:, None] * np.sin(phi)[None],
                                     np.cos(theta)[:, None]), axis=-1)
    s = np.array([-math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    sky = 0.05 + 2.0 * np.maximum(d @ s, 0.0) ** 2
    scenes.add_world(image=scenes.float_image("sky", np.repeat(sky[..., None], 3, axis=2)))


@pytest.mark.slow
@pytest.mark.usefixtures("registered_addon")
@pytest.mark.parametrize("kind,world", [("NORMAL_MAP", "sun"), ("BUMP", "sun"),
                                        ("NORMAL_MAP", "sky")])
def test_mapped_plane_against_cycles(tmp_path, kind, world):
    """Direct light only; the ridges face toward and away from a 20° sun (drawn per pixel
    by the sources' pass for every method) or a broad sky (SSDF_SG per pixel, REFERENCE
    per vertex: the normal map ignored): drawn with the mapped normal the frame follows
    Cycles', drawn flat it does not."""
    import bpy
    scenes.reset()
    (_low_sun_world if world == "sun" else _broad_sky_world)()
    # the bump's distance makes the same ridges as the normal image (its height in UV units
    # over a plane 2 units wide: distance 1 / 2 in world units per UV unit)
    plane = mapped_plane(kind, **({"Distance": 2.0} if kind == "BUMP" else {}))
    scenes.add_camera(location=(0.0, 0.0, 3.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 64)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    errors = {}
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method] = rel_l2(scenes.render_exr(tmp_path / f"{method}.exr"), truth)
    # drawn flat: the Normal link removed
    links = plane.active_material.node_tree.links
    links.remove(plane.active_material.node_tree.nodes["Principled BSDF"].inputs["Normal"]
                 .links[0])
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method + " flat"] = rel_l2(scenes.render_exr(tmp_path / f"{method}f.exr"), truth)
    print(kind, world, {k: round(v, 4) for k, v in errors.items()})
    # the figures: docs/measurements.md, Normal Map and Bump nodes
    bound = {("NORMAL_MAP", "sun"): 0.02, ("BUMP", "sun"): 0.03,
             ("NORMAL_MAP", "sky"): 0.05}[kind, world]
    flat = 0.6 if world == "sun" else 0.55
    for method in ("REFERENCE", "SSDF_SG") if world == "sun" else ("SSDF_SG",):
        assert errors[method] < bound, errors
        assert errors[method + " flat"] > flat, errors
