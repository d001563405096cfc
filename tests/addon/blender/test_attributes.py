"""addon.blender.attributes: after Precompute each mesh carries PRT AO, PRT Bent Normal and
the SH transfer as Face Corner attributes (what the Spreadsheet lists), checked against
quadrature on open ground; Cycles' Attribute node renders them (against our own AO pass);
they survive save and reload; Clear removes them; a mesh whose modifiers change its corners
gets none, with a note."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import attributes
from prt_relight.bench import scenes
from prt_relight.core.methods.sh import harmonics
from prt_relight.core.report import metrics

pytestmark = pytest.mark.usefixtures("registered_addon")


def _scene(subdiv=0):
    scenes.reset()
    scenes.add_world("sunset")
    scenes.add_ground(size=6.0, cuts=12)
    scenes.add_suzanne(subdiv=subdiv, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(48, 36)
    return bpy.context.scene


def _values(mesh, name):
    attr = mesh.attributes[name]
    assert attr.domain == "CORNER"
    width = {"FLOAT": 1, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4}[attr.data_type]
    out = np.empty(len(attr.data) * width, np.float32)
    attr.data.foreach_get({"FLOAT": "value", "FLOAT_VECTOR": "vector",
                           "FLOAT_COLOR": "color"}[attr.data_type], out)
    return out.reshape(len(attr.data), width) if width > 1 else out


def test_precompute_writes_attributes_against_quadrature(tmp_path):
    scene = _scene()
    scene.prt.attribute_sh_order = 3
    bpy.ops.prt.precompute()
    ground = bpy.data.objects["Ground"].data
    names = {a.name for a in ground.attributes if a.name.startswith("PRT ")}
    assert names == {"PRT AO", "PRT Bent Normal"} | {f"PRT SH {k}" for k in range(9)}
    ao = _values(ground, "PRT AO")
    bent = _values(ground, "PRT Bent Normal")
    sh = np.stack([_values(ground, f"PRT SH {k}") for k in range(9)], axis=1)
    corner_pos = np.array([v.co for v in ground.vertices])[
        np.array([l.vertex_index for l in ground.loops])]
    far = np.linalg.norm(corner_pos[:, :2], axis=1) > 2.5
    assert far.sum() > 20 and ao[far].min() > 0.9 and bent[far][:, 2].min() > 0.98
    # the transfer's band 0 is the clamped cosine's visible integral: pi AO Y00
    assert np.abs(sh[:, 0] - ao * math.pi * harmonics.basis(bent[:1], 1)[0, 0]).max() \
        < 1e-3 * sh[:, 0].max()
    # its band 1 is the first moment of the visible clamped cosine: along the bent normal
    y1 = harmonics.basis(bent.astype(np.float64), 2)[:, 1:4]
    cos = np.einsum("ij,ij->i", sh[:, 1:4], y1) / (
        np.linalg.norm(sh[:, 1:4], axis=1) * np.linalg.norm(y1, axis=1))
    assert cos.min() > 0.999
    # under Suzanne less sky; the bent normals are unit
    near = np.linalg.norm(corner_pos[:, :2], axis=1) < 0.6
    assert ao[near].max() < 0.95
    assert np.all(np.abs(np.linalg.norm(bent, axis=1) - 1.0) < 1e-4)
    # Geometry Nodes and render engines see them on the evaluated mesh
    ev = bpy.data.objects["Ground"].evaluated_get(bpy.context.evaluated_depsgraph_get())
    assert "PRT AO" in ev.data.attributes
    # saved with the file and back after reloading it
    path = str(tmp_path / "attrs.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    back = bpy.data.objects["Ground"].data
    assert np.array_equal(_values(back, "PRT AO"), ao)
    # Clear removes every PRT attribute
    bpy.ops.prt.clear()
    assert not [a.name for m in bpy.data.meshes for a in m.attributes
                if a.name.startswith("PRT ")]


def test_topology_changing_modifier_gets_no_attributes():
    _scene(subdiv=1)
    bpy.context.scene.prt.attribute_sh_order = 0
    bpy.ops.prt.precompute()
    assert "PRT AO" in bpy.data.objects["Ground"].data.attributes
    assert "PRT SH 0" not in bpy.data.objects["Ground"].data.attributes
    assert not any(a.name.startswith("PRT ") for a in bpy.data.objects["Suzanne"].data.attributes)


@pytest.mark.slow
def test_attribute_node_renders_ao_in_cycles(tmp_path):
    """An Emission material whose colour is the Attribute node's PRT AO, rendered by Cycles
    in a black world, is our F12's Ambient Occlusion pass."""
    scene = _scene()
    bpy.ops.prt.precompute()
    layer = bpy.context.view_layer
    layer.use_pass_ambient_occlusion = True
    from ..frame.test_passes import interior, render_layers
    ours = render_layers(tmp_path / "ours.exr")["Ambient Occlusion"]
    mat = bpy.data.materials.new("AO emission")
    nt = mat.node_tree
    nt.nodes.clear()
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "PRT AO"
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(attr.outputs["Fac"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    for ob in scene.objects:
        if ob.type == "MESH":
            ob.data.materials.clear()
            ob.data.materials.append(mat)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    cycles = scenes.render_exr(tmp_path / "cycles.exr", "CYCLES", samples=64, seed=1)
    mask = interior(ours[..., 0] > 0)        # the edges are filtered by different samples
    assert mask.mean() > 0.4
    assert metrics.rel_l2(ours, cycles[..., :3], mask) < 0.02      # 0.9 % measured
