"""addon.frame.passes through F12: the light group passes (World, its compact sources, each
lamp, or the view layer's Light Groups) sum to Combined, the data passes hold what a camera
sees (depth along its axis, world positions, unit normals), written to a multilayer EXR as
Cycles names them."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report import metrics

pytestmark = [pytest.mark.usefixtures("registered_addon"), pytest.mark.slow]


def _lamp(name, kind, location, energy, **settings):
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    for k, v in settings.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(name, data)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _scene(bounces=0, method="REFERENCE"):
    scenes.reset(bounces)
    scenes.add_world("sunset")
    scenes.add_ground(size=6.0, cuts=12)
    scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(48, 36)
    scene = bpy.context.scene
    scene.prt.supersampling = 2
    scene.prt.method = method
    _lamp("Key Lamp", "POINT", (2.0, -2.0, 3.0), 300.0, shadow_soft_size=0.2)
    sun = _lamp("Rim", "SUN", (0.0, 0.0, 5.0), 2.0, angle=math.radians(5.0))
    sun.rotation_euler = (0.6, 0.3, 0.0)
    bpy.ops.prt.precompute()
    return scene


def interior(mask, steps=2):
    """``mask`` less ``steps`` pixels at its border (beyond a pixel filter's reach)."""
    inner = mask.copy()
    for _ in range(steps):
        inner[1:] &= inner[:-1].copy()
        inner[:-1] &= inner[1:].copy()
        inner[:, 1:] &= inner[:, :-1].copy()
        inner[:, :-1] &= inner[:, 1:].copy()
    return inner


def render_layers(path, engine="PRT_RELIGHT"):
    """F12 (of ``engine``) written as a multilayer EXR: {pass name: (H, W, C)}."""
    import OpenImageIO as oiio
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.film_transparent = False
    settings = scene.render.image_settings
    saved = (settings.media_type, scene.render.filepath)
    settings.media_type = "MULTI_LAYER_IMAGE"          # Blender 5's multilayer EXR
    settings.color_depth = "32"
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        settings.media_type, scene.render.filepath = saved
    out = {}
    inp = oiio.ImageInput.open(str(path))          # a part per pass
    part = 0
    while inp.seek_subimage(part, 0):
        names = list(inp.spec().channelnames)
        px = np.asarray(inp.read_image(part, 0, 0, len(names), oiio.FLOAT), np.float32)
        for i, full in enumerate(names):
            layer_pass = full.rsplit(".", 1)[0].split(".", 1)[-1]
            out.setdefault(layer_pass, []).append(px[..., i])
        part += 1
    inp.close()
    return {k: np.stack(v, axis=-1) for k, v in out.items()}


@pytest.mark.parametrize("bounces, method", [(0, "REFERENCE"), (1, "REFERENCE"),
                                             (1, "SH"), (0, "SSDF_SG")])
def test_light_group_passes_sum_to_combined(tmp_path, bounces, method):
    """Per-vertex methods (with bounced light) and the per-pixel SSDF_SG (its own lamps)."""
    scene = _scene(bounces, method)
    scene.prt.light_group_passes = True
    got = render_layers(tmp_path / "passes.exr")
    groups = {k: v for k, v in got.items() if k.startswith("Combined_")}
    # the World, its sun (split off the sunset), each lamp
    assert {"Combined_World", "Combined_Key_Lamp", "Combined_Rim"} <= set(groups)
    assert any(k.startswith("Combined_World_Source_") for k in groups)
    combined = got["Combined"][..., :3]
    total = sum(groups.values())
    assert metrics.rel_l2(total, combined, np.ones(combined.shape[:2], bool)) < 1e-3
    # each group lights the frame: none is empty, none is the whole
    norm = float(np.linalg.norm(combined))
    for name, px in groups.items():
        assert 1e-3 * norm < float(np.linalg.norm(px)) < 0.999 * norm, name


def test_blender_light_groups_gather_lamps_and_world(tmp_path):
    """The view layer's Light Groups: two lamps in one group, the World (its sources with
    it) in another: two passes, summing to Combined."""
    scene = _scene()
    layer = bpy.context.view_layer
    for name in ("lamps", "sky"):
        layer.lightgroups.add(name=name)
    bpy.data.objects["Key Lamp"].lightgroup = "lamps"
    bpy.data.objects["Rim"].lightgroup = "lamps"
    scene.world.lightgroup = "sky"
    got = render_layers(tmp_path / "groups.exr")
    groups = {k: v for k, v in got.items() if k.startswith("Combined_")}
    assert set(groups) == {"Combined_lamps", "Combined_sky"}
    combined = got["Combined"][..., :3]
    total = groups["Combined_lamps"] + groups["Combined_sky"]
    assert metrics.rel_l2(total, combined, np.ones(combined.shape[:2], bool)) < 1e-3


def test_data_passes(tmp_path):
    scene = _scene()
    layer = bpy.context.view_layer
    layer.use_pass_z = layer.use_pass_normal = layer.use_pass_position = True
    layer.use_pass_ambient_occlusion = layer.use_pass_environment = True
    got = render_layers(tmp_path / "data.exr")
    depth, pos, nrm = got["Depth"][..., 0], got["Position"], got["Normal"]
    covered = depth < 1e9
    assert covered.mean() > 0.5 and (~covered).any()       # ground and Suzanne, and sky
    cam = scene.camera.matrix_world
    axis = -np.array(cam.col[2][:3])
    eye = np.array(cam.translation)
    # the depth is the position's distance along the camera's axis
    along = (pos[covered] - eye) @ axis
    assert np.abs(along - depth[covered]).max() < 1e-3 * depth[covered].max()
    # unit normals where covered, none elsewhere; the ground's point up
    lengths = np.linalg.norm(nrm[covered], axis=1)
    assert np.abs(lengths - 1.0).max() < 1e-3
    assert np.abs(nrm[~covered]).max() == 0.0
    ground = covered & (np.abs(pos[..., 2]) < 1e-3)
    assert ground.sum() > 50 and np.abs(nrm[ground][:, 2] - 1.0).max() < 1e-3
    ao = got["Ambient Occlusion"]
    assert ao.min() >= 0.0 and ao.max() <= 1.0 + 1e-5
    # under Suzanne the ground sees less sky than at the frame's open ground
    assert ao[ground][:, 0].min() < 0.8 < ao[ground][:, 0].max()
    env = got["Environment"]
    inner = interior(covered)              # beyond the pixel filter's reach of the sky
    assert inner.sum() > 100
    assert np.abs(env[inner]).max() == 0.0 and env[~covered].min() > 0.0
    # the sky pixels of Combined are the environment's
    comb = got["Combined"][..., :3]
    assert metrics.rel_l2(env, comb, ~covered & (ao[..., 0] == 0)) < 1e-3


def _checker_ground():
    """The ground's base colour an image texture (a checker on its UV map)."""
    px = np.full((8, 8, 4), 1.0, np.float32)
    px[..., :3] = 0.15
    px[(np.add.outer(np.arange(8), np.arange(8)) % 2) == 0, :3] = (0.8, 0.5, 0.2)
    image = scenes.float_image("checker", px, is_data=False)
    mat = bpy.data.materials.new("Checker")
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Closest"
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    ground = bpy.data.objects["Ground"]
    ground.data.materials.clear()
    ground.data.materials.append(mat)


@pytest.mark.parametrize("method", ["REFERENCE", "SH"])
def test_light_passes_compose_combined(tmp_path, method):
    """(Diffuse Direct + Indirect) × Diffuse Color + (Glossy Direct + Indirect) × Glossy
    Color + Environment is Combined: a textured ground, a glossy Suzanne, the World with
    its sun drawn per pixel, two lamps, a bounce."""
    scene = _scene(1, method)
    _checker_ground()
    scenes.add_bsdf_material(bpy.data.objects["Suzanne"], "Glossy", "ShaderNodeBsdfPrincipled",
                             Roughness=0.3)
    layer = bpy.context.view_layer
    for attr in ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct",
                 "glossy_indirect", "glossy_color", "environment"):
        setattr(layer, f"use_pass_{attr}", True)
    got = render_layers(tmp_path / "light.exr")
    rebuilt = ((got["Diffuse Direct"] + got["Diffuse Indirect"]) * got["Diffuse Color"]
               + (got["Glossy Direct"] + got["Glossy Indirect"]) * got["Glossy Color"]
               + got["Environment"])
    combined = got["Combined"][..., :3]
    assert metrics.rel_l2(rebuilt, combined, np.ones(combined.shape[:2], bool)) < 1e-3
    # each part is there: the checker's two colours, light bounced, a glossy Suzanne
    ground = got["Diffuse Color"][..., 0]
    assert np.any(np.abs(ground - 0.8) < 1e-3) and np.any(np.abs(ground - 0.15) < 1e-3)
    assert got["Diffuse Indirect"].max() > 0.0 and got["Glossy Indirect"].max() > 0.0
    # (the lamps' highlights on Suzanne are spread over the pixel's footprint at 2 % of the
    # frame's peak and more: present, not a point's value)
    assert got["Glossy Direct"].max() > 0.02 * combined.max()
