"""Normal Map and Bump nodes (core/scene/textures.py NormalSource): the perturbed normal against
brute force (the geometric normal of the displaced surface by finite differences, a rotated
tangent frame)."""

from __future__ import annotations

import math

import numpy as np
import pytest


# --------------------------------------------------------------------------- Blender

def _ridges(res=128, amp=0.08, k=4):
    """A tangent-space normal image of ridges along v (h = amp sin(2 pi k u) on a unit
    UV square), top row first, and the height itself."""
    u = (np.arange(res) + 0.5) / res
    hu = amp * 2 * np.pi * k * np.cos(2 * np.pi * k * u)
    n = np.stack([-hu, np.zeros(res), np.ones(res)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    img = np.ones((res, res, 3), np.float32)
    img[:] = 0.5 * (n[None, :, :] + 1.0)
    h = np.repeat((amp * np.sin(2 * np.pi * k * u))[None, :, None], 3, axis=2)
    return img, np.ascontiguousarray(np.broadcast_to(h, (res, res, 3)), np.float32)


def _mapped_plane(kind, size=2.0, **node_inputs):
    """A grid with a Principled material whose Normal is a Normal Map or Bump node on a
    generated Non-Color image (None: no link, drawn flat)."""
    import bpy
    from . import blender_scene as bs
    plane = bs.add_ground(size=size, cuts=8)
    mat = bpy.data.materials.new("mapped")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    normal_img, height = _ridges()
    if kind is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = bs.float_image(kind, normal_img if kind == "NORMAL_MAP" else height)
        node = nt.nodes.new("ShaderNodeNormalMap" if kind == "NORMAL_MAP" else "ShaderNodeBump")
        for key, value in node_inputs.items():
            node.inputs[key].default_value = value
        nt.links.new(tex.outputs["Color"], node.inputs["Color" if kind == "NORMAL_MAP"
                                                       else "Height"])
        nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    plane.data.materials.append(mat)
    return plane


def _low_sun_world():
    """One bright pixel 20° above the horizon, toward -x, over a dim sky."""
    from . import blender_scene as bs
    el = math.radians(20.0)
    sky = bs.sun_image(256, 128, (-math.cos(el), 0.0, math.sin(el)), radiance=2e4)
    sky += 0.02
    bs.add_world(image=bs.float_image("sky", sky))


def _broad_sky_world():
    """A smooth sky, brightest 30° above the horizon toward -x (no compact source is split
    off: every method shades all of it from its transfer)."""
    from . import blender_scene as bs
    h, w = 64, 128
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)      # u = 0.5 - atan2(y, x) / 2 pi
    d = np.stack(np.broadcast_arrays(np.sin(theta)[:, None] * np.cos(phi)[None],
                                     np.sin(theta)[:, None] * np.sin(phi)[None],
                                     np.cos(theta)[:, None]), axis=-1)
    s = np.array([-math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    sky = 0.05 + 2.0 * np.maximum(d @ s, 0.0) ** 2
    bs.add_world(image=bs.float_image("sky", np.repeat(sky[..., None], 3, axis=2)))


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
    from . import blender_scene as bs
    bs.reset()
    (_low_sun_world if world == "sun" else _broad_sky_world)()
    # the bump's distance makes the same ridges as the normal image (its height in UV units
    # over a plane 2 units wide: distance 1 / 2 in world units per UV unit)
    plane = _mapped_plane(kind, **({"Distance": 2.0} if kind == "BUMP" else {}))
    bs.add_camera(location=(0.0, 0.0, 3.0), rotation=(0.0, 0.0, 0.0))
    bs.set_resolution(64, 64)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    truth = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    errors = {}
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method] = bs.rel_l2(bs.render_exr(tmp_path / f"{method}.exr"), truth)
    # drawn flat: the Normal link removed
    links = plane.active_material.node_tree.links
    links.remove(plane.active_material.node_tree.nodes["Principled BSDF"].inputs["Normal"]
                 .links[0])
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method + " flat"] = bs.rel_l2(bs.render_exr(tmp_path / f"{method}f.exr"),
                                             truth)
    print(kind, world, {k: round(v, 4) for k, v in errors.items()})
    # the figures: docs/measurements.md, Normal Map and Bump nodes
    bound = {("NORMAL_MAP", "sun"): 0.02, ("BUMP", "sun"): 0.03,
             ("NORMAL_MAP", "sky"): 0.05}[kind, world]
    flat = 0.6 if world == "sun" else 0.55
    for method in ("REFERENCE", "SSDF_SG") if world == "sun" else ("SSDF_SG",):
        assert errors[method] < bound, errors
        assert errors[method + " flat"] > flat, errors


def _evaluated(ob):
    import bpy
    bpy.context.view_layer.update()
    return ob.evaluated_get(bpy.context.evaluated_depsgraph_get())


@pytest.mark.usefixtures("registered_addon")
def test_export_reads_both_nodes_tangents_and_warns_other_links():
    from prt_relight.addon.blender import texture_export
    from . import blender_scene as bs
    bs.reset()
    plane = _mapped_plane("NORMAL_MAP", Strength=0.7)
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
