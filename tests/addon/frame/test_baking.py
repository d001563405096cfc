"""addon.frame.baking (``prt.bake``): a baked radiance lightmap on an Emission material,
rendered by EEVEE, is our F12 of the same diffuse scene; irradiance baked into a Color
Attribute is the radiance times pi over the albedo; a list of World turns makes one result
each; bad input leaves the scene as it was."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report import metrics
from .test_passes import interior

pytestmark = pytest.mark.usefixtures("registered_addon")


def _scene():
    scenes.reset()
    scenes.add_world("forest")
    scenes.add_ground(size=6.0, cuts=16)
    suzanne = scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    scene = bpy.context.scene
    scene.prt.light_sources = 0              # the whole World per vertex: no per-pixel pass
    scene.prt.supersampling = 2
    # Suzanne's own UVs mirror her halves onto one another: one island each
    bpy.ops.object.select_all(action="DESELECT")
    suzanne.select_set(True)
    bpy.context.view_layer.objects.active = suzanne
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=0.02)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.prt.precompute()
    return scene


def _select(*names):
    bpy.ops.object.select_all(action="DESELECT")
    for name in names:
        bpy.data.objects[name].select_set(True)


def _emission_from(ob, image):
    """``ob`` drawn as an Emission of ``image`` on its UV map (strength 1)."""
    mat = bpy.data.materials.new(f"lightmap {ob.name}")
    nt = mat.node_tree
    nt.nodes.clear()
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    # read the texels as baked: at a 64×48 frame a 512² map's mip maps blur it (2.6 %)
    tex.interpolation = "Closest"
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(tex.outputs["Color"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    ob.data.materials.clear()
    ob.data.materials.append(mat)


@pytest.mark.slow
def test_baked_lightmap_in_eevee_matches_f12(tmp_path):
    scene = _scene()
    ours = scenes.render_exr(tmp_path / "ours.exr")
    _select("Ground", "Suzanne")
    assert bpy.ops.prt.bake(quantity="RADIANCE", target="IMAGE", size=512,
                            margin=8) == {"FINISHED"}
    for name in ("Ground", "Suzanne"):
        image = bpy.data.images[f"PRT Radiance {name}"]
        assert image.is_float and image.packed_file is not None
        _emission_from(bpy.data.objects[name], image)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.eevee.taa_render_samples = 16
    eevee = scenes.render_exr(tmp_path / "eevee.exr", "BLENDER_EEVEE")
    mask = interior(ours[..., 3] > 0.999)
    assert mask.mean() > 0.4
    assert metrics.rel_l2(eevee, ours, mask) < 0.02          # 0.8 % measured


def test_color_attribute_irradiance_and_turns():
    """Irradiance into a Color Attribute is radiance × π / albedo (a Diffuse BSDF of 0.8);
    two turns of the World make two attributes that differ."""
    scene = _scene()
    scenes.add_bsdf_material(bpy.data.objects["Ground"], "Diffuse", "ShaderNodeBsdfDiffuse",
                             Color=(0.8, 0.8, 0.8, 1.0))
    _select("Ground")
    assert bpy.ops.prt.bake(quantity="RADIANCE", target="COLOR_ATTRIBUTE") == {"FINISHED"}
    assert bpy.ops.prt.bake(quantity="IRRADIANCE", target="COLOR_ATTRIBUTE",
                            rotations="0, 90") == {"FINISHED"}
    mesh = bpy.data.objects["Ground"].data

    def colours(name):
        attr = mesh.color_attributes[name]
        assert attr.domain == "CORNER" and attr.data_type == "FLOAT_COLOR"
        out = np.empty(len(attr.data) * 4, np.float32)
        attr.data.foreach_get("color", out)
        return out.reshape(-1, 4)[:, :3]
    radiance, e0, e90 = (colours(n) for n in ("PRT Radiance", "PRT Irradiance 0°",
                                               "PRT Irradiance 90°"))
    np.testing.assert_allclose(radiance * math.pi / 0.8, e0, rtol=1e-3, atol=1e-6)
    assert np.abs(e90 - e0).mean() > 0.02 * e0.mean()
    assert scene.prt.precompute_id          # nothing else changed


def test_bad_input_leaves_the_scene_unchanged():
    _scene()
    images = len(bpy.data.images)
    _select("Ground")
    with pytest.raises(RuntimeError, match="no UV map 'missing'"):
        bpy.ops.prt.bake(target="IMAGE", uv_map="missing")
    with pytest.raises(RuntimeError, match="Rotations must be numbers"):
        bpy.ops.prt.bake(target="IMAGE", rotations="ninety")
    _select()
    with pytest.raises(RuntimeError, match="Select the mesh objects"):
        bpy.ops.prt.bake(target="COLOR_ATTRIBUTE")
    # Suzanne's Subdivision modifier changes her corners: no attribute can hold them
    _select("Ground", "Suzanne")
    with pytest.raises(RuntimeError, match="modifiers change its corners"):
        bpy.ops.prt.bake(target="COLOR_ATTRIBUTE")
    assert len(bpy.data.images) == images
    assert not any(a.name.startswith("PRT Irr") for m in bpy.data.meshes
                   for a in m.attributes)
