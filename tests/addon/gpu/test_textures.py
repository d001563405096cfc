"""Textured inputs drawn per pixel by every method (addon/gpu/drawing.py): painting or
swapping an image redraws without a recompute; SSDF_SG reads the base colour and scalar
inputs per pixel; the sun's pass reads a Roughness texture per pixel."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.core.scene import textures
from prt_relight.bench import scenes

from ...cases.textures import plane_from_above, rough_principled, texture_image, textured_material, white_world


pytestmark = pytest.mark.usefixtures("registered_addon")


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- Blender

def test_swapping_or_painting_the_image_redraws_without_recompute(tmp_path):
    scenes.reset()
    white_world()
    plane = plane_from_above(pixels=8)
    rgba = np.ones((4, 4, 4), np.float32) * 0.25
    img = texture_image("paint", rgba)
    plane.data.materials.append(textured_material("Tex", img, "Closest"))
    bpy.ops.prt.precompute()
    pid = plane.prt.precompute_id
    a = scenes.render_exr(tmp_path / "a.exr")
    np.testing.assert_allclose(a[..., :3], 0.25, atol=1e-5)
    rgba[..., :3] = (0.7, 0.2, 0.1)
    img.pixels.foreach_set(rgba.reshape(-1))                 # what Texture Paint does
    b = scenes.render_exr(tmp_path / "b.exr")
    np.testing.assert_allclose(b[..., :3], np.broadcast_to((0.7, 0.2, 0.1), b[..., :3].shape),
                               atol=1e-5)
    other = texture_image("other", np.full((2, 2, 4), 0.9, np.float32))
    plane.active_material.node_tree.nodes["Image Texture"].image = other
    c = scenes.render_exr(tmp_path / "c.exr")
    np.testing.assert_allclose(c[..., :3], 0.9, atol=1e-5)
    assert plane.prt.precompute_id == pid


# --------------------------------------------------------------------------- SSDF_SG

def _principled(name, base=None, img=None, **inputs):
    """A Principled material with a constant ``base`` colour or an image on Base Color."""
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    for key, value in inputs.items():
        bsdf.inputs[key].default_value = value
    if img is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = img
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    else:
        bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    return mat


def test_ssdf_sg_reads_the_base_colour_per_pixel(tmp_path):
    """SSDF_SG's kd and Principled Fresnel terms are linear in the base colour (GGX): at each
    pixel, the textured frame is the frames of base colour 0 and 1 mixed by the texture read
    at the pixel's UV (core.scene.textures.sample), a glossy metal-dielectric mix included."""
    scenes.reset()
    scenes.add_world("forest")
    plane = plane_from_above(pixels=16)
    bpy.context.scene.prt.method = "SSDF_SG"
    bpy.context.scene.prt.light_sources = 0        # the whole world through SSDF_SG
    rng = np.random.default_rng(7)
    rgba = np.ones((8, 8, 4), np.float32)
    rgba[..., :3] = rng.random((8, 8, 3))
    img = texture_image("noise", rgba)
    glossy = dict(Metallic=0.5, Roughness=0.4)
    frames = {}
    for key, mat in (("tex", _principled("T", img=img, **glossy)),
                     ("white", _principled("W", (1.0, 1.0, 1.0), **glossy)),
                     ("black", _principled("B", (0.0, 0.0, 0.0), **glossy))):
        # GGX: Multiscatter GGX's energy factor is not linear in the base colour (Cycles'
        # F_ms of the metal lobe), the rest is
        mat.node_tree.nodes["Principled BSDF"].distribution = "GGX"
        plane.data.materials.clear()
        plane.data.materials.append(mat)
        if key == "tex":
            bpy.ops.prt.precompute()
        frames[key] = scenes.render_exr(tmp_path / f"{key}.exr")[::-1, :, :3]
    n = frames["tex"].shape[0]
    centres = (np.arange(n) + 0.5) / n
    uv = np.stack(np.meshgrid(centres, centres, indexing="xy"), axis=-1)
    colour = textures.sample(textures.ImageTexture(rgba), uv.reshape(-1, 2))[:, :3]
    colour = colour.reshape(n, n, 3)
    expected = frames["black"] + (frames["white"] - frames["black"]) * colour
    assert frames["white"].mean() > 2 * frames["black"].mean() > 0
    np.testing.assert_allclose(frames["tex"], expected, rtol=1e-3, atol=1e-4)


@pytest.mark.parametrize("socket, values, base", [
    ("Roughness", (0.25, 0.75), dict(Metallic=0.3)),
    ("Metallic", (0.0, 1.0), dict(Roughness=0.4)),
    ("Specular IOR Level", (0.25, 0.75), dict(Roughness=0.35))])
def test_ssdf_sg_reads_scalar_inputs_per_pixel(tmp_path, socket, values, base):
    """A Non-Color checker of two values on Roughness / Metallic / Specular IOR Level: each
    cell of the SSDF_SG frame is the frame of the constant input there (the values are
    nodes of the shader's table, so exactly)."""
    scenes.reset()
    scenes.add_world("forest")
    plane = plane_from_above(pixels=16)
    scene = bpy.context.scene
    scene.prt.method = "SSDF_SG"
    scene.prt.light_sources = 0
    cells = np.zeros((2, 2, 4), np.float32)
    cells[...] = values[0]
    cells[0, 1, :3] = cells[1, 0, :3] = values[1]
    cells[..., 3] = 1.0
    img = texture_image("cells", cells)
    inputs = dict(base, **{"Base Color": (0.7, 0.5, 0.3, 1.0)})
    mat = scenes.bsdf_material("Tex", "ShaderNodeBsdfPrincipled", **inputs)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Closest"
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs[socket])
    plane.data.materials.append(mat)
    from prt_relight.addon.frame import state as runtime
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert not any("driven by a node link" in w for w in state.warnings), state.warnings
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "tex.exr")[::-1, :, :3]        # bottom row = v 0
    n = frame.shape[0]
    cell = (np.arange(n) * 2 // n)
    second = (cell[:, None] + cell[None, :]) % 2 == 1              # where values[1] is
    for k, v in enumerate(values):
        bsdf.inputs[socket].default_value = v
        mat.node_tree.links.remove(bsdf.inputs[socket].links[0]) if k == 0 else None
        const = scenes.render_exr(tmp_path / f"c{k}.exr")[::-1, :, :3]
        sel = second if k else ~second
        np.testing.assert_allclose(frame[sel], const[sel], rtol=2e-3, atol=1e-4)
    assert abs(frame[second].mean() - frame[~second].mean()) > 0.01


def test_sun_pass_reads_a_roughness_texture_per_pixel(tmp_path):
    """The compact sources' pass (a sun lamp over a black world): each cell of a Roughness
    checker (0.25 / 0.75, nodes of the pass's roughness table) shows the frame of that
    constant roughness."""
    scenes.reset()
    scenes.add_world(image=scenes.float_image("black", np.zeros((8, 16, 3), np.float32)))
    plane = plane_from_above(pixels=16)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.1
    lamp = bpy.data.objects.new("Sun", sun)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.rotation_euler = (0.45, 0.0, 0.0)
    cells = np.full((2, 2, 4), 0.25, np.float32)
    cells[0, 1, :3] = cells[1, 0, :3] = 0.75
    cells[..., 3] = 1.0
    mat, bsdf = rough_principled("Tex", cells, Metallic=0.6,
                                  **{"Base Color": (0.7, 0.5, 0.3, 1.0)})
    plane.data.materials.append(mat)
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "tex.exr")[::-1, :, :3]
    n = frame.shape[0]
    cell = np.arange(n) * 2 // n
    second = (cell[:, None] + cell[None, :]) % 2 == 1
    mat.node_tree.links.remove(bsdf.inputs["Roughness"].links[0])
    for v, sel in ((0.25, ~second), (0.75, second)):
        bsdf.inputs["Roughness"].default_value = v
        const = scenes.render_exr(tmp_path / f"c{v}.exr")[::-1, :, :3]
        np.testing.assert_allclose(frame[sel], const[sel], rtol=2e-3, atol=1e-4)
    assert abs(frame[second].mean() - frame[~second].mean()) > 0.02 * frame.mean()
