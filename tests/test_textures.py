"""Textured colour inputs (core/scene/textures.py, addon/blender/texture_export.py): sampling as Blender's
Image Texture node, the node patterns read, per-pixel drawing for every method."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.core.scene import textures

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "RSL", "BLOCKS", "SH", "WAVELET"]


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- Blender

def _image(name, rgba, colorspace="Non-Color"):
    h, w = rgba.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = colorspace         # first: it regenerates the buffer
    img.pixels.foreach_set(np.ascontiguousarray(rgba, np.float32).reshape(-1))
    img.pack()
    return img


def _checker(n=32, cells=4):
    yy, xx = np.mgrid[0:n, 0:n]
    chk = ((xx // (n // cells) + yy // (n // cells)) % 2).astype(np.float32)
    rgba = np.ones((n, n, 4), np.float32)
    rgba[..., 0] = 0.1 + 0.8 * chk
    rgba[..., 1] = 0.5
    rgba[..., 2] = 0.9 - 0.8 * chk
    return rgba


def _textured(name, img, interpolation="Linear", extension="REPEAT", uv_map=None,
              mapping=None, node="ShaderNodeBsdfDiffuse"):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    for n in list(nt.nodes):
        if n.type == "BSDF_PRINCIPLED":
            nt.nodes.remove(n)
    bsdf = nt.nodes.new(node)
    nt.links.new(bsdf.outputs[0], next(n for n in nt.nodes
                                      if n.type == "OUTPUT_MATERIAL").inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = img, interpolation, extension
    colour = "Color" if node == "ShaderNodeBsdfDiffuse" else "Base Color"
    nt.links.new(tex.outputs["Color"], bsdf.inputs[colour])
    vec = tex.inputs["Vector"]
    if mapping is not None:
        m = nt.nodes.new("ShaderNodeMapping")
        m.inputs["Location"].default_value = mapping
        nt.links.new(m.outputs["Vector"], vec)
        vec = m.inputs["Vector"]
    if uv_map is not None:
        uvn = nt.nodes.new("ShaderNodeUVMap")
        uvn.uv_map = uv_map
        nt.links.new(uvn.outputs["UV"], vec)
    return mat


def _white_world():
    bs.add_world(image=bs.float_image("white", np.ones((8, 16, 3), np.float32)))


def _plane_from_above(size=2.0, pixels=16):
    bpy.ops.mesh.primitive_plane_add(size=size)
    plane = bpy.context.object
    cam = bs.add_camera(location=(0.0, 0.0, 5.0), rotation=(0.0, 0.0, 0.0))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = size
    bs.set_resolution(pixels, pixels)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.render.filter_size = 0.0
    return plane


@pytest.mark.parametrize("interpolation, extension, mapping", [
    ("Linear", "REPEAT", None), ("Closest", "EXTEND", None), ("Cubic", "MIRROR", None),
    ("Linear", "CLIP", (0.3, -0.2, 0.0))])
def test_glsl_texture_equals_numpy_at_every_pixel(tmp_path, interpolation, extension, mapping):
    """An unoccluded Lambert plane under a white world shows its albedo: each pixel is the
    texture read (core.scene.textures.sample) at the pixel centre's UV."""
    bs.reset()
    _white_world()
    plane = _plane_from_above()
    rng = np.random.default_rng(4)
    rgba = np.ones((8, 8, 4), np.float32)
    rgba[..., :3] = rng.random((8, 8, 3))
    img = _image("noise", rgba)
    plane.data.materials.append(_textured("Tex", img, interpolation, extension,
                                          mapping=mapping))
    bpy.ops.prt.precompute()
    frame = bs.render_exr(tmp_path / "f.exr")[::-1]            # bottom row first, as v
    n = frame.shape[0]
    centres = (np.arange(n) + 0.5) / n
    uv = np.stack(np.meshgrid(centres, centres, indexing="xy"), axis=-1).reshape(-1, 2)
    transform = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    if mapping is not None:
        transform[:, 2] = mapping[:2]
    tex = textures.ImageTexture(rgba, transform=transform, interpolation=interpolation,
                                extension=extension)
    expected = textures.sample(tex, uv)[:, :3].reshape(n, n, 3)
    np.testing.assert_allclose(frame[..., :3], expected, atol=2e-4)


def test_colour_attribute_and_mix_with_a_colour(tmp_path):
    bs.reset()
    _white_world()
    plane = _plane_from_above(pixels=8)
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
    frame = bs.render_exr(tmp_path / "a.exr")
    # a corner pixel reads close to its vertex's colour times 0.5 (Principled: a bit less)
    corner = frame[-1, 0, :3]                                  # bottom left: vertex 0
    assert corner[0] > 4 * max(corner[1], corner[2]) and 0.4 < corner[0] < 0.6


def test_unsupported_nodes_still_warn_by_name():
    bs.reset()
    _white_world()
    plane = _plane_from_above(pixels=8)
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


def test_swapping_or_painting_the_image_redraws_without_recompute(tmp_path):
    bs.reset()
    _white_world()
    plane = _plane_from_above(pixels=8)
    rgba = np.ones((4, 4, 4), np.float32) * 0.25
    img = _image("paint", rgba)
    plane.data.materials.append(_textured("Tex", img, "Closest"))
    bpy.ops.prt.precompute()
    pid = plane.prt.precompute_id
    a = bs.render_exr(tmp_path / "a.exr")
    np.testing.assert_allclose(a[..., :3], 0.25, atol=1e-5)
    rgba[..., :3] = (0.7, 0.2, 0.1)
    img.pixels.foreach_set(rgba.reshape(-1))                 # what Texture Paint does
    b = bs.render_exr(tmp_path / "b.exr")
    np.testing.assert_allclose(b[..., :3], np.broadcast_to((0.7, 0.2, 0.1), b[..., :3].shape),
                               atol=1e-5)
    other = _image("other", np.full((2, 2, 4), 0.9, np.float32))
    plane.active_material.node_tree.nodes["Image Texture"].image = other
    c = bs.render_exr(tmp_path / "c.exr")
    np.testing.assert_allclose(c[..., :3], 0.9, atol=1e-5)
    assert plane.prt.precompute_id == pid


def test_srgb_texture_is_linearised_and_non_color_is_not(tmp_path):
    bs.reset()
    _white_world()
    plane = _plane_from_above(pixels=4)
    # an 8-bit image: Blender stores bytes, Cycles linearises sRGB ones
    img = bpy.data.images.new("grey", 2, 2, alpha=True)
    img.pixels.foreach_set(np.full(16, 128 / 255, np.float32))
    img.pack()
    plane.data.materials.append(_textured("Tex", img, "Closest"))
    bpy.ops.prt.precompute()
    img.colorspace_settings.name = "sRGB"
    srgb = bs.render_exr(tmp_path / "s.exr")[..., 0].mean()
    img.colorspace_settings.name = "Non-Color"
    data = bs.render_exr(tmp_path / "n.exr")[..., 0].mean()
    assert srgb == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-3)
    assert data == pytest.approx(128 / 255, rel=1e-3)


def test_a_second_uv_map_is_read_when_the_node_names_it(tmp_path):
    bs.reset()
    _white_world()
    plane = _plane_from_above(pixels=8)
    second = plane.data.uv_layers.new(name="Shifted")
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers[0].data.foreach_get("uv", uv)
    second.data.foreach_set("uv", (uv.reshape(-1, 2)[:, ::-1]).reshape(-1))  # u <-> v
    plane.data.uv_layers.active = plane.data.uv_layers[0]
    px = np.ones((1, 2, 4), np.float32)
    px[0, 0, :3], px[0, 1, :3] = 0.1, 0.9                       # dark left, bright right
    plane.data.materials.append(_textured("Tex", _image("lr", px), "Closest", "EXTEND",
                                          uv_map="Shifted"))
    bpy.ops.prt.precompute()
    frame = bs.render_exr(tmp_path / "f.exr")
    # swapped UVs: the split runs along the image's rows (top bright, bottom dark)
    assert frame[0, :, 0].mean() == pytest.approx(0.9, abs=1e-4)
    assert frame[-1, :, 0].mean() == pytest.approx(0.1, abs=1e-4)


@pytest.mark.slow
def test_textured_statue_on_a_textured_ground_matches_cycles(tmp_path):
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    ground = bs.add_ground(size=6.0, cuts=48)
    img = _image("checker", _checker(64, 8))
    ground.data.materials.append(_textured("Ground", img, node="ShaderNodeBsdfPrincipled"))
    suzanne = bs.add_suzanne(subdiv=2)
    photo = np.ones((32, 32, 4), np.float32)
    yy, xx = np.mgrid[0:32, 0:32] / 32.0
    photo[..., 0] = 0.5 + 0.4 * np.sin(9 * xx)
    photo[..., 1] = 0.4 + 0.3 * np.cos(7 * yy)
    photo[..., 2] = 0.3 + 0.2 * xx * yy
    suzanne.data.materials.append(_textured("Statue", _image("photo", photo, "sRGB")))
    bs.add_camera()
    bs.set_resolution(96, 72)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    errors = {}
    for method in METHODS:
        bpy.context.scene.prt.method = method
        errors[method] = bs.rel_l2(bs.render_exr(tmp_path / f"{method}.exr"), truth)
    assert errors["REFERENCE"] < 0.02, errors
    assert all(e < 0.08 for e in errors.values()), errors


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
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    plane = _plane_from_above(pixels=16)
    bpy.context.scene.prt.method = "SSDF_SG"
    bpy.context.scene.prt.light_sources = 0        # the whole world through SSDF_SG
    rng = np.random.default_rng(7)
    rgba = np.ones((8, 8, 4), np.float32)
    rgba[..., :3] = rng.random((8, 8, 3))
    img = _image("noise", rgba)
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
        frames[key] = bs.render_exr(tmp_path / f"{key}.exr")[::-1, :, :3]
    n = frames["tex"].shape[0]
    centres = (np.arange(n) + 0.5) / n
    uv = np.stack(np.meshgrid(centres, centres, indexing="xy"), axis=-1)
    colour = textures.sample(textures.ImageTexture(rgba), uv.reshape(-1, 2))[:, :3]
    colour = colour.reshape(n, n, 3)
    expected = frames["black"] + (frames["white"] - frames["black"]) * colour
    assert frames["white"].mean() > 2 * frames["black"].mean() > 0
    np.testing.assert_allclose(frames["tex"], expected, rtol=1e-3, atol=1e-4)


def _photo(n=32):
    photo = np.ones((n, n, 4), np.float32)
    yy, xx = np.mgrid[0:n, 0:n] / float(n)
    photo[..., 0] = 0.5 + 0.4 * np.sin(9 * xx)
    photo[..., 1] = 0.4 + 0.3 * np.cos(7 * yy)
    photo[..., 2] = 0.3 + 0.2 * xx * yy
    return photo


@pytest.mark.slow
def test_ssdf_sg_textured_error_is_its_untextured_error(tmp_path):
    """A textured statue on a textured ground under an HDRI: SSDF_SG's distance to REFERENCE
    (exact for a textured Lambert base) is within half a point of the same scene drawn with
    each texture's mean colour."""
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    ground = bs.add_ground(size=6.0, cuts=48)
    suzanne = bs.add_suzanne(subdiv=2)
    checker, photo = _checker(64, 8), _photo()
    textured = {ground: _textured("Ground", _image("checker", checker)),
                suzanne: _textured("Statue", _image("photo", photo),
                                   node="ShaderNodeBsdfPrincipled")}
    plain = {ground: bs.bsdf_material("GroundMean", "ShaderNodeBsdfDiffuse",
                                      Color=(*checker[..., :3].mean(axis=(0, 1)), 1.0)),
             suzanne: bs.bsdf_material("StatueMean", "ShaderNodeBsdfPrincipled",
                                       **{"Base Color": (*photo[..., :3].mean(axis=(0, 1)),
                                                         1.0)})}
    bs.add_camera()
    bs.set_resolution(96, 72)
    scene = bpy.context.scene
    scene.prt.supersampling = 2
    errors = {}
    for kind, mats in (("textured", textured), ("plain", plain)):
        for ob, mat in mats.items():
            ob.data.materials.clear()
            ob.data.materials.append(mat)
        frames = {}
        for method in ("REFERENCE", "SSDF_SG"):
            scene.prt.method = method
            bpy.ops.prt.precompute()
            frames[method] = bs.render_exr(tmp_path / f"{kind}_{method}.exr")
        errors[kind] = bs.rel_l2(frames["SSDF_SG"], frames["REFERENCE"])
    print("SSDF_SG vs REFERENCE", errors)
    assert errors["textured"] < errors["plain"] + 0.005, errors
    assert errors["plain"] < 0.04, errors


def _rough_principled(name, cells, **inputs):
    """(material, its Principled node) whose Roughness is the Non-Color image ``cells``
    read with Closest interpolation."""
    mat = bs.bsdf_material(name, "ShaderNodeBsdfPrincipled", **inputs)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = _image("cells", cells), "Closest"
    bsdf = next(nd for nd in mat.node_tree.nodes if nd.type == "BSDF_PRINCIPLED")
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
    return mat, bsdf


@pytest.mark.parametrize("socket, values, base", [
    ("Roughness", (0.25, 0.75), dict(Metallic=0.3)),
    ("Metallic", (0.0, 1.0), dict(Roughness=0.4)),
    ("Specular IOR Level", (0.25, 0.75), dict(Roughness=0.35))])
def test_ssdf_sg_reads_scalar_inputs_per_pixel(tmp_path, socket, values, base):
    """A Non-Color checker of two values on Roughness / Metallic / Specular IOR Level: each
    cell of the SSDF_SG frame is the frame of the constant input there (the values are
    nodes of the shader's table, so exactly)."""
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    plane = _plane_from_above(pixels=16)
    scene = bpy.context.scene
    scene.prt.method = "SSDF_SG"
    scene.prt.light_sources = 0
    cells = np.zeros((2, 2, 4), np.float32)
    cells[...] = values[0]
    cells[0, 1, :3] = cells[1, 0, :3] = values[1]
    cells[..., 3] = 1.0
    img = _image("cells", cells)
    inputs = dict(base, **{"Base Color": (0.7, 0.5, 0.3, 1.0)})
    mat = bs.bsdf_material("Tex", "ShaderNodeBsdfPrincipled", **inputs)
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
    frame = bs.render_exr(tmp_path / "tex.exr")[::-1, :, :3]        # bottom row = v 0
    n = frame.shape[0]
    cell = (np.arange(n) * 2 // n)
    second = (cell[:, None] + cell[None, :]) % 2 == 1              # where values[1] is
    for k, v in enumerate(values):
        bsdf.inputs[socket].default_value = v
        mat.node_tree.links.remove(bsdf.inputs[socket].links[0]) if k == 0 else None
        const = bs.render_exr(tmp_path / f"c{k}.exr")[::-1, :, :3]
        sel = second if k else ~second
        np.testing.assert_allclose(frame[sel], const[sel], rtol=2e-3, atol=1e-4)
    assert abs(frame[second].mean() - frame[~second].mean()) > 0.01


def test_sun_pass_reads_a_roughness_texture_per_pixel(tmp_path):
    """The compact sources' pass (a sun lamp over a black world): each cell of a Roughness
    checker (0.25 / 0.75, nodes of the pass's roughness table) shows the frame of that
    constant roughness."""
    bs.reset()
    bs.add_world(image=bs.float_image("black", np.zeros((8, 16, 3), np.float32)))
    plane = _plane_from_above(pixels=16)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.1
    lamp = bpy.data.objects.new("Sun", sun)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.rotation_euler = (0.45, 0.0, 0.0)
    cells = np.full((2, 2, 4), 0.25, np.float32)
    cells[0, 1, :3] = cells[1, 0, :3] = 0.75
    cells[..., 3] = 1.0
    mat, bsdf = _rough_principled("Tex", cells, Metallic=0.6,
                                  **{"Base Color": (0.7, 0.5, 0.3, 1.0)})
    plane.data.materials.append(mat)
    bpy.ops.prt.precompute()
    frame = bs.render_exr(tmp_path / "tex.exr")[::-1, :, :3]
    n = frame.shape[0]
    cell = np.arange(n) * 2 // n
    second = (cell[:, None] + cell[None, :]) % 2 == 1
    mat.node_tree.links.remove(bsdf.inputs["Roughness"].links[0])
    for v, sel in ((0.25, ~second), (0.75, second)):
        bsdf.inputs["Roughness"].default_value = v
        const = bs.render_exr(tmp_path / f"c{v}.exr")[::-1, :, :3]
        np.testing.assert_allclose(frame[sel], const[sel], rtol=2e-3, atol=1e-4)
    assert abs(frame[second].mean() - frame[~second].mean()) > 0.02 * frame.mean()


@pytest.mark.slow
def test_roughness_texture_on_a_glossy_sphere_against_cycles(tmp_path):
    """A metal sphere whose Roughness is a Non-Color checker (0.3 / 0.7) under 'forest',
    64x64, against Cycles direct light: SSDF_SG and the sun pass read it per pixel, the
    per-vertex methods per point (quantized variants); each against its error at the two
    constant roughnesses (per vertex: + the band along the checker's edges), and SSDF_SG's
    rough metal (constant 0.7, and the checker) within its measured bound."""
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    sphere = bpy.context.object
    bpy.ops.object.shade_smooth()
    n = 8
    yy, xx = np.mgrid[0:n, 0:n]
    cells = np.ones((n, n, 4), np.float32)
    cells[..., :3] = np.where((xx + yy) % 2 == 1, 0.7, 0.3)[..., None]
    mat, bsdf = _rough_principled("Rough", cells, Metallic=1.0,
                                  **{"Base Color": (0.9, 0.7, 0.5, 1.0)})
    sphere.data.materials.append(mat)
    bs.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0))
    bs.set_resolution(64, 64)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    methods = ("REFERENCE", "SSDF_SG", "BLOCKS")

    def frames(tag):
        out = {"CYCLES": bs.render_exr(tmp_path / f"cycles{tag}.exr", engine="CYCLES",
                                       samples=256)}
        for method in methods:
            scene.prt.method = method
            bpy.ops.prt.precompute()
            out[method] = bs.render_exr(tmp_path / f"{method}{tag}.exr")
        return out

    def rel(pairs):
        num = sum(np.sum((f[..., :3] - t[..., :3]) ** 2 * (t[..., 3:] > 0.5)) for f, t in pairs)
        den = sum(np.sum(t[..., :3] ** 2 * (t[..., 3:] > 0.5)) for _, t in pairs)
        return float(np.sqrt(num / den))

    textured = frames("")
    mat.node_tree.links.remove(bsdf.inputs["Roughness"].links[0])
    constant = {}
    for v in (0.3, 0.7):
        bsdf.inputs["Roughness"].default_value = v
        constant[v] = frames(f"_{v}")
    errors = {m: (rel([(textured[m], textured["CYCLES"])]),
                  rel([(constant[v][m], constant[v]["CYCLES"]) for v in constant]))
              for m in methods}
    each = {v: rel([(constant[v]["SSDF_SG"], constant[v]["CYCLES"])]) for v in constant}
    print("roughness texture vs Cycles (textured, constant 0.3 and 0.7):", errors,
          "SSDF_SG at 0.3 / 0.7:", each)
    for m, (tex_err, const_err) in errors.items():
        # per vertex: a triangle-wide band along each cell edge (measured + 6.3 points);
        # SSDF_SG + 0.9 (four lobes, against 1024 spp: 4.32 % textured, 4.15 % the constant
        # frames composed by the checker, 4.09 % pooled: the rim's error falls on either)
        assert tex_err < const_err + (0.01 if m == "SSDF_SG" else 0.08), (m, errors)
    # SSDF_SG's GGX view slice as four fitted lobes (docs/measurements.md "SG lobes of a rough
    # metal", "Fitted warp of the GGX lobes", "Four fitted lobes of the GGX view slice"):
    # measured 6.1 % textured, 5.2 % pooled, 6.0 / 2.7 % at 0.3 / 0.7 (E against the open
    # hemisphere's visibility; without: 6.3, 5.6, 6.2 / 4.1 %; two fitted lobes 7.1, 7.2,
    # 7.7 / 6.2 %; plain warp 7.7, 7.8, 8.0 / 7.5 %; a Beckmann lobe 12.8, 13.9, 10.0 / 19.8 %);
    # Cycles' own noise at 256 spp is part of it (REFERENCE: 5.6 % pooled)
    assert errors["SSDF_SG"][0] < 0.07 and errors["SSDF_SG"][1] < 0.06, errors
    assert each[0.3] < 0.07 and each[0.7] < 0.035, each
