"""Glossy Principled objects against converged Cycles (several seeds, their variance
subtracted: core.report.metrics.rel_l2_converged): a Roughness image and a Normal Map of an image
(issue 16's glossy case; SSDF_SG reads both per pixel, Wang et al. 2009 §4, §7), and the
dielectric's view-dependent layering of its Lambert base."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.core.report import metrics as report
from prt_relight.bench import scenes

from ...cases.glossy import glossy_object, roughness_and_normal_images


pytestmark = pytest.mark.usefixtures("registered_addon")


def _converged_cycles_and_ssdf_sg(tmp_path, spp):
    """The camera of tests/integration/cycles/test_textures.py's sphere (64x64, 3x3 supersamples); Cycles
    direct light with four seeds of ``spp``; SSDF_SG precomputed: ``(frames, error of
    SSDF_SG's frame against them, the mean's noise)``."""
    scenes.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 64)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    frames = []
    for seed in range(4):
        scene.cycles.seed = seed
        frames.append(scenes.render_exr(tmp_path / f"cycles{seed}.exr", engine="CYCLES",
                                    samples=spp))
    scene.prt.method = "SSDF_SG"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _, noise, err = report.rel_l2_converged(scenes.render_exr(tmp_path / "ours.exr"), frames)
    return frames, err, noise


@pytest.mark.slow
@pytest.mark.parametrize("shape, metallic, bound", [("SUZANNE", 0.0, 0.035),
                                                    ("SPHERE", 1.0, 0.04),
                                                    ("SUZANNE", 1.0, 0.06)])
def test_roughness_texture_and_normal_map_against_converged_cycles(tmp_path, shape, metallic,
                                                                   bound):
    """Suzanne (subdivided twice) or a UV sphere under 'forest', 64x64: SSDF_SG against
    Cycles direct light converged (four seeds x 1024 spp, their variance subtracted), within
    the issue's 6 % (measured 2.4 % dielectric Suzanne, 2.4 % metal sphere, 4.9 % metal
    Suzanne: its concave parts need eq. 41's light read at the visible part of each lobe,
    docs/measurements.md "The visible part's light"); drawn with the roughness's mean and
    without the normal map it is further off."""
    scenes.reset()
    scenes.add_world("forest")
    bsdf = glossy_object(metallic, shape)
    frames, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 1024)
    nt = bsdf.id_data
    for socket in ("Roughness", "Normal"):
        nt.links.remove(bsdf.inputs[socket].links[0])
    bsdf.inputs["Roughness"].default_value = 0.45
    _, _, plain = report.rel_l2_converged(scenes.render_exr(tmp_path / "plain.exr"), frames)
    print(f"{shape} metallic {metallic}: SSDF_SG {100 * err:.2f} % (Cycles' mean's noise "
          f"{100 * noise:.2f} %), untextured {100 * plain:.2f} %")
    assert err < bound and plain > 3 * err, (err, plain)


@pytest.mark.slow
@pytest.mark.parametrize("roughness", [0.15, 0.3])
def test_principled_dielectric_sphere_against_converged_cycles(tmp_path, roughness):
    """A Principled dielectric sphere under 'forest' (64x64): Cycles' Lambert base is
    weighted per view by what the specular layer takes (closure_layering_weight), up to 40 %
    less at grazing views at r 0.3; SSDF_SG draws that weight per pixel (measured 0.8 / 1.0 %
    at r 0.15 / 0.3; with the weight's mean over views 6.0 / 4.7 %, the rim too bright)."""
    scenes.reset()
    scenes.add_world("forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(scenes.bsdf_material(
        "dielectric", "ShaderNodeBsdfPrincipled", Roughness=roughness,
        **{"Base Color": (0.9, 0.7, 0.5, 1.0)}))
    _, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 512)
    print(f"dielectric r {roughness}: SSDF_SG {100 * err:.2f} % (noise {100 * noise:.2f} %)")
    assert err < 0.02, err


def test_a_roughness_image_reaching_below_the_sharp_limit_leaves_the_slot_to_the_sharp_pass(
        tmp_path):
    """A metal slot whose Roughness image is 0.1 on one half and 0.4 on the other (mean
    above the 6x32² sharp limit of 0.19, its low half below): every per-point variant of the
    slot is drawn per pixel (addon/gpu/sharp.py, by slot), so REFERENCE no longer drops the low
    half's lobes (it drew them black); SSDF_SG, which reads the image per pixel over its
    whole range, draws the slot itself.  A 0.3 / 0.6 image keeps its lobes in the methods."""
    from prt_relight.addon.frame import state as runtime
    from prt_relight.addon.gpu import sharp
    scenes.reset()
    scenes.add_world("forest")
    bsdf = glossy_object(1.0, "SPHERE")
    rough_tex = bsdf.inputs["Roughness"].links[0].from_node
    u = (np.arange(64) + 0.5) / 64
    halves = np.where(np.meshgrid(u, u)[0] < 0.5, 0.1, 0.4)
    rough_tex.image = scenes.float_image("halves", np.repeat(halves[..., None], 3, axis=2))
    scenes.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0),
                      resolution=None)
    scenes.set_resolution(24, 24)
    scene = bpy.context.scene
    scene.prt.method = "REFERENCE"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    st = state.objects[0]
    assert len(st.materials) > 2 and all(m.per_pixel_lobe for m in st.materials)
    assert sharp.sharp_slots(st) == [0]
    frame = scenes.render_exr(tmp_path / "reference.exr")
    ball = frame[..., 3] > 0.5
    assert np.mean(frame[ball][:, :3].sum(axis=1) < 1e-3) < 0.02       # no black half
    scene.prt.method = "SSDF_SG"
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert sharp.sharp_slots(state.objects[0]) == []
    scene.prt.method = "REFERENCE"
    rough_tex.image = scenes.float_image("rough halves", np.repeat(0.2 + halves[..., None], 3, 2))
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert not any(m.per_pixel_lobe for m in state.objects[0].materials)
    assert sharp.sharp_slots(state.objects[0]) == []


def _png(name, pixels_top_first, path, colorspace="Non-Color"):
    """An 8-bit PNG written to ``path`` and loaded from there (as an artist's image)."""
    h, w = pixels_top_first.shape[:2]
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = pixels_top_first
    img = bpy.data.images.new(name + " (written)", w, h)
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.filepath_raw, img.file_format = str(path), "PNG"
    img.save()
    bpy.data.images.remove(img)
    img = bpy.data.images.load(str(path))
    img.colorspace_settings.name = colorspace
    return img


def _imported_figure(tmp_path):
    """A lumpy figure written as an OBJ with normals and no UVs, imported (custom split
    normals) and unwrapped with Smart UV Project, as the issue's figure was."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=1.0)
    ob = bpy.context.object
    co = np.empty(3 * len(ob.data.vertices))
    ob.data.vertices.foreach_get("co", co)
    p = co.reshape(-1, 3)
    p *= (1.0 + 0.2 * np.sin(3.0 * p[:, :1]) * np.cos(2.0 * p[:, 1:2]) + 0.3 * p[:, 2:] ** 2)
    ob.data.vertices.foreach_set("co", p.reshape(-1))
    bpy.ops.object.shade_smooth()
    path = tmp_path / "figure.obj"
    bpy.ops.wm.obj_export(filepath=str(path), export_selected_objects=True, export_uv=False,
                          export_normals=True, export_materials=False)
    bpy.data.objects.remove(ob)
    bpy.ops.wm.obj_import(filepath=str(path))
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    assert not ob.data.uv_layers
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode="OBJECT")
    return ob


@pytest.mark.slow
@pytest.mark.parametrize("low, high, bounds", [(0.05, 0.15, (0.09, 0.075)),
                                               (0.1, 0.3, (0.12, 0.045))])
def test_imported_metal_figure_with_low_roughness_image_and_normal_map_against_cycles(
        tmp_path, low, high, bounds):
    """The issue's figure: an OBJ unwrapped in Blender, Principled metallic 1 with 8-bit
    PNG images (Non-Color, on disk) on Roughness and through a Normal Map (UV map field
    empty) under 'forest', 64x64.  Its roughness reaches below the sharp limit, so the slot
    is drawn per pixel by addon/gpu/sharp.py (REFERENCE) at each pixel's roughness and with the
    mapped normal, or by SSDF_SG itself, which reads the image per pixel (both were
    ignored: the slot's mean roughness on the flat surface, 72 % off in the issue; here
    192 % for both methods at 0.05-0.15, REFERENCE 72 % at 0.1-0.3).  Against Cycles
    converged (four seeds x 1024 spp): REFERENCE 6.6 % / 9.1 %, SSDF_SG 5.5 % / 2.9 %;
    without the normal map it is further off."""
    scenes.reset()
    scenes.add_world("forest")
    ob = _imported_figure(tmp_path)
    rough, normal = roughness_and_normal_images()
    rough = low + (high - low) * (rough - 0.2) / 0.5
    mat = bpy.data.materials.new("metal figure")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
    bsdf.inputs["Metallic"].default_value = 1.0
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _png("roughness", rough, tmp_path / "roughness.png")
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _png("normal", normal, tmp_path / "normal.png")
    node = nt.nodes.new("ShaderNodeNormalMap")
    nt.links.new(tex.outputs["Color"], node.inputs["Color"])
    nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    ob.data.materials.append(mat)
    scenes.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0),
                      resolution=None)
    scenes.set_resolution(64, 64)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    frames = []
    for seed in range(4):
        scene.cycles.seed = seed
        frames.append(scenes.render_exr(tmp_path / f"cycles{seed}.exr", engine="CYCLES",
                                    samples=1024))
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    errors = {}
    for method in ("REFERENCE", "SSDF_SG"):
        scene.prt.method = method
        errors[method] = report.rel_l2_converged(scenes.render_exr(tmp_path / f"{method}.exr"),
                                                 frames)[2]
    nt.links.remove(bsdf.inputs["Normal"].links[0])
    flat = report.rel_l2_converged(scenes.render_exr(tmp_path / "flat.exr"), frames)[2]
    print(f"roughness {low}-{high}: " + ", ".join(f"{m} {100 * e:.2f} %"
                                                  for m, e in errors.items())
          + f", without the normal map {100 * flat:.2f} %")
    assert all(errors[m] < b for m, b in zip(("REFERENCE", "SSDF_SG"), bounds)), errors
    assert flat > 3 * max(errors.values()), (errors, flat)


def _textured_metal(ob, tmp_path, rough_uv_map=None):
    """Principled metallic 1 with the roughness (0.2-0.7) and normal images as 8-bit PNGs
    on ``ob``; ``rough_uv_map``: a UV Map node naming it on the roughness image only."""
    rough, normal = roughness_and_normal_images()
    mat = bpy.data.materials.new("metal")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
    bsdf.inputs["Metallic"].default_value = 1.0
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _png("roughness", rough, tmp_path / "roughness.png")
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
    if rough_uv_map is not None:
        node = nt.nodes.new("ShaderNodeUVMap")
        node.uv_map = rough_uv_map
        nt.links.new(node.outputs["UV"], tex.inputs["Vector"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _png("normal", normal, tmp_path / "normal.png")
    node = nt.nodes.new("ShaderNodeNormalMap")
    nt.links.new(tex.outputs["Color"], node.inputs["Color"])
    nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    ob.data.materials.append(mat)


@pytest.mark.slow
def test_images_without_a_uv_map_node_read_the_render_uv_map(tmp_path):
    """A second UV map added in the UI (active for editing, its UVs moved) while the
    first keeps the camera icon: Cycles reads an Image Texture without a UV Map node, and
    a Normal Map's tangents with its UV map field empty, on the render UV map (the passes
    read the active one: SSDF_SG 80 % off here, 59 % on spot.obj; 2.2 % now)."""
    scenes.reset()
    scenes.add_world("forest")
    ob = _imported_figure(tmp_path)
    bpy.ops.mesh.uv_texture_add()
    layers = ob.data.uv_layers
    assert layers[1].active and layers[0].active_render and not layers[1].active_render
    uv = np.empty(2 * len(ob.data.loops))
    layers[1].data.foreach_get("uv", uv)
    layers[1].data.foreach_set("uv", (0.5 * uv.reshape(-1, 2)[:, ::-1] + 0.2).ravel())
    _textured_metal(ob, tmp_path)
    frames, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 1024)
    print(f"SSDF_SG {100 * err:.2f} % (noise {100 * noise:.2f} %)")
    assert err < 0.04, err


@pytest.mark.slow
def test_a_uv_map_node_on_one_image_keeps_the_other_images_on_the_same_map(tmp_path):
    """The roughness image through a UV Map node naming the render UV map, the normal
    map's image without one: both read the same map, so SSDF_SG draws both (the names
    '' and 'UVMap' differed, and the normal map was silently dropped: 40 % off, 2.2 %
    now)."""
    scenes.reset()
    scenes.add_world("forest")
    ob = _imported_figure(tmp_path)
    _textured_metal(ob, tmp_path, rough_uv_map=ob.data.uv_layers[0].name)
    frames, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 1024)
    print(f"SSDF_SG {100 * err:.2f} % (noise {100 * noise:.2f} %)")
    assert err < 0.04, err
