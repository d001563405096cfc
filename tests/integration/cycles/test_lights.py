"""Compact sources and lamps against Cycles: a one-pixel sun's shadow for every method, a
4-degree sun's penumbra, a glossy statue under a low sun gaining from the split, lamps of
each type and area lamps: slow."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2

from ...cases.lights import area_lamp, black_world, local_lamp, plate_over_ground, sun_lamp


pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET"]


# --------------------------------------------------------------------------- Cycles

def _sun_scene(img, cuts=48):
    scenes.reset()
    scenes.add_world(image=scenes.float_image("sky", img))
    scenes.add_ground(size=5.0, cuts=cuts)
    scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.5), rotation=(1.1, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    bpy.context.scene.prt.supersampling = 3


def _dim_sky_with_sun(h=256, w=512, direction=(0.5, -0.6, 0.6), sun=2e4, sun_pixels=1):
    theta = (np.arange(h) + 0.5) / h * math.pi
    sky = (0.03 + 0.05 * np.clip(np.cos(theta), 0.0, 1.0))[:, None, None] \
        * np.array([0.6, 0.8, 1.0])
    img = np.repeat(sky, w, axis=1).astype(np.float32)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    u = (0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0
    v = math.acos(d[2]) / math.pi
    dirs, _ = __import__("prt_relight.core.sphere.envmap", fromlist=["x"]).equirect_directions(h, w, 1)
    if sun_pixels == 1:
        img[min(int(v * h), h - 1), min(int(u * w), w - 1)] = sun
    else:                     # a disc of sun_pixels degrees radius
        img[dirs @ d > math.cos(math.radians(sun_pixels))] = sun
    return img


@pytest.mark.slow
def test_one_pixel_sun_shadow_matches_cycles_for_every_method(tmp_path):
    """A character on a ground under one 1-pixel sun over a dim sky: the sun drawn per pixel
    with its shadow map brings every method close to Cycles (per-vertex transport alone
    smears the shadow)."""
    _sun_scene(_dim_sky_with_sun())
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    errors = {}
    for method in METHODS:
        scene.prt.method = method
        errors[method] = rel_l2(scenes.render_exr(tmp_path / f"{method}.exr"), truth)
    scene.prt.method = "REFERENCE"
    scene.prt.light_sources = 0
    errors["REFERENCE without split"] = rel_l2(scenes.render_exr(tmp_path / "nosplit.exr"), truth)
    assert errors["REFERENCE"] < 0.02, errors
    assert errors["REFERENCE"] < 0.75 * errors["REFERENCE without split"], errors
    assert all(errors[m] < 0.03 for m in METHODS if m != "SH"), errors


@pytest.mark.slow
def test_four_degree_sun_penumbra_matches_cycles(tmp_path):
    scenes.reset()
    black_world()
    plate_over_ground(1.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0.8, 0.6, 0.4))
    sun_lamp(3.0, math.radians(4.0), tilt=0.4)
    scenes.add_camera(location=(0.0, -5.0, 4.0), rotation=(0.9, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    ours = scenes.render_exr(tmp_path / "ours.exr")
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    assert rel_l2(ours, truth) < 0.04


@pytest.mark.slow
def test_glossy_statue_under_a_low_sun_gains_from_the_split(tmp_path):
    """Glossy Beckmann 0.3 under 'sunrise' (the sun carries over half the energy): per
    vertex, the sun's highlight and shadow are smeared; drawn per pixel they follow
    Cycles (measured 12 % against 34 % off at 2048 spp; the rest is the residual's
    per-vertex gloss and sub-pixel highlights)."""
    scenes.reset()
    scenes.add_world("sunrise")
    scenes.add_ground(size=5.0, cuts=24)
    suzanne = scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    suzanne.data.materials.append(scenes.bsdf_material("Glossy", "ShaderNodeBsdfGlossy",
                                                   Roughness=0.3, distribution="BECKMANN"))
    scenes.add_camera(location=(0.0, -6.0, 3.5), rotation=(1.1, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    after = rel_l2(scenes.render_exr(tmp_path / "ours.exr"), truth)
    scene.prt.light_sources = 0
    before = rel_l2(scenes.render_exr(tmp_path / "nosplit.exr"), truth)
    assert after < 0.16 and after < 0.5 * before, (after, before)


@pytest.mark.slow
def test_lamps_of_each_type_against_cycles(tmp_path):
    scenes.reset()
    black_world()
    scenes.add_ground(size=6.0, cuts=24)
    scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    sun_lamp(2.0, math.radians(3.0), tilt=0.5)
    local_lamp("POINT", 300.0, (2.0, -1.5, 2.5), radius=0.15)
    local_lamp("SPOT", 600.0, (-2.0, -2.0, 3.0), radius=0.1,
                rotation=(math.radians(40), 0.0, math.radians(-45)), size=math.radians(50))
    scenes.add_camera(location=(0.0, -6.0, 3.5), rotation=(1.1, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    for method in ("REFERENCE", "SH"):
        bpy.context.scene.prt.method = method
        err = rel_l2(scenes.render_exr(tmp_path / f"{method}.exr"), truth)
        assert err < 0.04, (method, err)


@pytest.mark.slow
def test_area_lamps_against_cycles(tmp_path):
    """A rectangle and a disc area lamp over Suzanne on a ground (diffuse and the default
    Principled): REFERENCE and SH against Cycles' direct light."""
    scenes.reset()
    black_world()
    scenes.add_ground(size=6.0, cuts=24)
    scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    area_lamp(300.0, (1.5, -1.5, 2.5), 1.0, 0.5, shape="RECTANGLE",
               rotation=(math.radians(35), 0.0, math.radians(45)))
    area_lamp(200.0, (-1.8, -0.5, 2.0), 0.8, shape="DISK",
               rotation=(math.radians(20), math.radians(-30), 0.0))
    scenes.add_camera(location=(0.0, -6.0, 3.5), rotation=(1.1, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    for method in ("REFERENCE", "SH"):
        bpy.context.scene.prt.method = method
        err = rel_l2(scenes.render_exr(tmp_path / f"{method}.exr"), truth)
        assert err < 0.05, (method, err)
