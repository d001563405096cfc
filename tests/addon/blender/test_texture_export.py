"""addon.blender.texture_export in headless Blender: the node patterns read (Image Texture,
Color Attribute, Mix with a colour, a second UV map), colour spaces, unsupported nodes
warned by name; the Normal Map and Bump nodes with their tangents."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes

from ...cases.textures import plane_from_above, texture_image, textured_material, white_world
from ...cases.normal_maps import mapped_plane


pytestmark = pytest.mark.usefixtures("registered_addon")


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- Blender

def test_colour_attribute_and_mix_with_a_colour(tmp_path):
    scenes.reset()
    white_world()
    plane = plane_from_above(pixels=8)
    attr = plane.data.color_attributes.new("Paint", "FLOAT_COLOR", "POINT")
    cols = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 1, 1]], np.float32)
    attr.data.foreach_set("color", cols.reshape(-1))
    mat = bpy.data.materials.new("Attr")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    node = nt.nodes.new("ShaderNodeVertexColor")
    node.layer_name = "Paint"
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
    mix.inputs[0].default_value = 1.0
    nt.links.new(node.outputs["Color"], mix.inputs[6])
    mix.inputs[7].default_value = (0.5, 0.5, 0.5, 1.0)
    nt.links.new(mix.outputs[2], bsdf.inputs["Base Color"])
    plane.data.materials.append(mat)
    from prt_relight.addon.frame import state as runtime
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert 0 in state.objects[0].textures
    assert not any("driven by a node link" in w for w in state.warnings), state.warnings
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "a.exr")
    # a corner pixel reads close to its vertex's colour times 0.5 (Principled: a bit less)
    corner = frame[-1, 0, :3]                                  # bottom left: vertex 0
    assert corner[0] > 4 * max(corner[1], corner[2]) and 0.4 < corner[0] < 0.6


def test_unsupported_nodes_still_warn_by_name():
    scenes.reset()
    white_world()
    plane = plane_from_above(pixels=8)
    mat = bpy.data.materials.new("Noise")
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(noise.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    plane.data.materials.append(mat)
    from prt_relight.addon.frame import state as runtime
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert state.objects[0].textures == {}
    assert any("'Base Color' is driven by a node link" in w for w in state.warnings)


def test_srgb_texture_is_linearised_and_non_color_is_not(tmp_path):
    scenes.reset()
    white_world()
    plane = plane_from_above(pixels=4)
    # an 8-bit image: Blender stores bytes, Cycles linearises sRGB ones
    img = bpy.data.images.new("grey", 2, 2, alpha=True)
    img.pixels.foreach_set(np.full(16, 128 / 255, np.float32))
    img.pack()
    plane.data.materials.append(textured_material("Tex", img, "Closest"))
    bpy.ops.prt.precompute()
    img.colorspace_settings.name = "sRGB"
    srgb = scenes.render_exr(tmp_path / "s.exr")[..., 0].mean()
    img.colorspace_settings.name = "Non-Color"
    data = scenes.render_exr(tmp_path / "n.exr")[..., 0].mean()
    assert srgb == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-3)
    assert data == pytest.approx(128 / 255, rel=1e-3)


def test_a_second_uv_map_is_read_when_the_node_names_it(tmp_path):
    scenes.reset()
    white_world()
    plane = plane_from_above(pixels=8)
    second = plane.data.uv_layers.new(name="Shifted")
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers[0].data.foreach_get("uv", uv)
    second.data.foreach_set("uv", (uv.reshape(-1, 2)[:, ::-1]).reshape(-1))  # u <-> v
    plane.data.uv_layers.active = plane.data.uv_layers[0]
    px = np.ones((1, 2, 4), np.float32)
    px[0, 0, :3], px[0, 1, :3] = 0.1, 0.9                       # dark left, bright right
    plane.data.materials.append(textured_material("Tex", texture_image("lr", px), "Closest", "EXTEND",
                                          uv_map="Shifted"))
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "f.exr")
    # swapped UVs: the split runs along the image's rows (top bright, bottom dark)
    assert frame[0, :, 0].mean() == pytest.approx(0.9, abs=1e-4)
    assert frame[-1, :, 0].mean() == pytest.approx(0.1, abs=1e-4)


# --------------------------------------------------------------------------- Blender

def _evaluated(ob):
    import bpy
    bpy.context.view_layer.update()
    return ob.evaluated_get(bpy.context.evaluated_depsgraph_get())


@pytest.mark.usefixtures("registered_addon")
def test_export_reads_both_nodes_tangents_and_warns_other_links():
    from prt_relight.addon.blender import texture_export
    scenes.reset()
    plane = mapped_plane("NORMAL_MAP", Strength=0.7)
    plane.rotation_euler = (0.0, 0.0, math.pi / 2)                 # tangents turn with it
    ob = _evaluated(plane)
    warnings = []
    got = texture_export.slot_normals(ob, warnings)
    src, uvs, tng = got[0]
    assert warnings == [] and src.kind == "NORMAL_MAP" and src.strength == pytest.approx(0.7)
    assert uvs.shape == (len(tng), 2)
    # the grid's u runs along its local x, turned to world y; bitangent sign +1
    np.testing.assert_allclose(tng, np.tile([0.0, 1.0, 0.0, 1.0], (len(tng), 1)), atol=1e-5)
    nt = plane.active_material.node_tree
    bump = nt.nodes.new("ShaderNodeBump")
    bump.invert = True
    bump.inputs["Distance"].default_value = 0.3
    nt.links.new(nt.nodes["Image Texture"].outputs["Color"], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], nt.nodes["Principled BSDF"].inputs["Normal"])
    ob = _evaluated(plane)
    src = texture_export.slot_normals(ob, warnings)[0][0]
    assert src.kind == "BUMP" and src.distance == pytest.approx(-0.3)
    coord = nt.nodes.new("ShaderNodeNewGeometry")
    nt.links.new(coord.outputs["Normal"], nt.nodes["Principled BSDF"].inputs["Normal"])
    ob = _evaluated(plane)
    assert texture_export.slot_normals(ob, warnings) == {}
    assert len(warnings) == 1 and "'Geometry'" in warnings[0], warnings
