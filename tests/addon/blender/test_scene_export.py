"""addon.blender.scene_export in headless Blender: materials read as Cycles' nodes define
them, Blender's lamps read in Cycles' units."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes

from ...cases.lights import add_light, lamp_scene


pytestmark = pytest.mark.usefixtures("registered_addon")


def test_materials_export():
    from prt_relight.addon.blender import scene_export

    warnings = []
    mat = scenes.bsdf_material("glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                           Roughness=0.3)
    nt = mat.node_tree
    glossy = nt.nodes["Glossy BSDF"]
    m = scene_export.export_material(mat, warnings)
    assert m.distribution == "BECKMANN" and m.roughness == pytest.approx(0.3)
    assert m.is_diffuse_only is False and m.diffuse_albedo == (0.0, 0.0, 0.0)
    nt.nodes.remove(glossy)
    emission = nt.nodes.new("ShaderNodeHoldout")
    nt.links.new(emission.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    scene_export.export_material(mat, warnings)
    assert any("not supported" in w for w in warnings)


def _principled(roughness):
    mat = bpy.data.materials.new("principled")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Metallic"].default_value = 0.0
    p.inputs["Roughness"].default_value = roughness
    return mat


def test_exported_materials_follow_cycles_nodes():
    from prt_relight.addon.blender import scene_export

    default = scene_export.DEFAULT_MATERIAL
    assert default.fresnel == "DIELECTRIC" and default.distribution == "MULTI_GGX"
    assert default.diffuse_albedo == pytest.approx((0.8, 0.8, 0.8))
    assert default.roughness == 0.5 and default.ior == pytest.approx(1.5)
    assert default.metallic == 0.0
    warnings = []
    mat = _principled(0.3)
    p = mat.node_tree.nodes["Principled BSDF"]
    # a fresh Principled node is the default surface (but roughness)
    m = scene_export.export_material(mat, warnings)
    for field, value in default.__dict__.items():
        want = 0.3 if field == "roughness" else value
        got = getattr(m, field)
        assert got == (want if isinstance(want, str) else pytest.approx(want, rel=1e-6)), field
    assert warnings == []
    p.inputs["Coat Weight"].default_value = 0.5
    p.inputs["Transmission Weight"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 1.0
    p.distribution = "GGX"
    m = scene_export.export_material(mat, warnings)
    assert any("coat" in w for w in warnings) and any("transmission" in w for w in warnings)
    assert m.specular_color == pytest.approx((0.08, 0.08, 0.08)) and m.distribution == "GGX"


# --------------------------------------------------------------------------- Blender lamps

@pytest.mark.usefixtures("registered_addon")
def test_export_lamps_reads_blender_lights():
    import bpy

    from prt_relight.addon.blender import scene_export

    lamp_scene()
    add_light("POINT", (1.0, 2.0, 3.0), energy=50.0, shadow_soft_size=0.2, color=(1.0, 0.5, 0.25))
    add_light("SUN", rotation=(0.3, 0.0, 0.0), energy=4.0, angle=0.02)
    add_light("SPOT", (0.0, 0.0, 4.0), energy=30.0, spot_size=1.0, spot_blend=0.3)
    add_light("AREA", (0.0, 0.0, 4.0), energy=30.0, size=2.0)
    warnings = []
    lamps = scene_export.export_lamps(bpy.context.evaluated_depsgraph_get(), warnings)
    kinds = sorted(l.kind for l in lamps)
    assert kinds == ["AREA", "POINT", "SPOT", "SUN"] and warnings == []
    area = [l for l in lamps if l.kind == "AREA"][0]       # a 2 m square facing down
    assert np.isclose(area.area, 4.0) and np.allclose(area.direction, (0.0, 0.0, -1.0))
    assert np.allclose(area.position, (0.0, 0.0, 4.0))
    point = [l for l in lamps if l.kind == "POINT"][0]
    assert np.allclose(point.position, (1, 2, 3)) and np.isclose(point.radius, 0.2)
    assert np.allclose(point.color, (50.0, 25.0, 12.5))
    sun = [l for l in lamps if l.kind == "SUN"][0]
    assert np.allclose(sun.direction, [0.0, math.sin(0.3), -math.cos(0.3)], atol=1e-6)
    spot = [l for l in lamps if l.kind == "SPOT"][0]
    assert np.isclose(spot.spot_size, 1.0) and np.isclose(spot.spot_blend, 0.3)
