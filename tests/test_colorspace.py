"""The world image's colour space: read as Cycles reads it.

A texture is converted from its image's colour space to the blend file's working space;
Non-Color is read as stored and the view transform (a display transform) never matters.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import scene_export, storage
from prt_relight.core.sphere import envmap

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")

GREY = 128 / 255
GREY_LINEAR = ((GREY + 0.055) / 1.055) ** 2.4          # 0.21586
ALBEDO = 0.8


# --------------------------------------------------------------------------- core


@pytest.mark.skipif(not envmap.have_opencolorio(), reason="OpenImageIO without OpenColorIO")
def test_core_blender_config_converts_like_blender_float_images(tmp_path):
    """Blender's config through OpenImageIO: a float EXR tagged with a colour space reads
    back from ``image.pixels`` converted by Blender itself; ours agrees."""
    config = scene_export.ocio_config_path()
    rng = np.random.default_rng(3)
    raw = rng.uniform(0.0, 1.0, (4, 8, 3)).astype(np.float32)
    path = tmp_path / "raw.exr"
    _write(path, raw, "float")
    img = bpy.data.images.load(str(path), check_existing=False)
    for cs in ("Filmic sRGB", "AgX Base sRGB", "ACEScg", "Linear Rec.2020", "Rec.1886"):
        img.colorspace_settings.name = cs
        blender = _pixels(img)
        ours = envmap.to_working_space(raw, cs, "Linear Rec.709", config)
        np.testing.assert_allclose(ours, blender, rtol=2e-4, atol=2e-5, err_msg=cs)
    with pytest.raises(envmap.EnvironmentError_, match="'no such space'"):
        envmap.to_working_space(raw, "no such space", "Linear Rec.709", config)


# --------------------------------------------------------------------------- helpers

def _write(path, pixels, fmt):
    h, w, c = pixels.shape
    out = bs.oiio.ImageOutput.create(str(path))
    out.open(str(path), bs.oiio.ImageSpec(w, h, c, fmt))
    out.write_image(np.ascontiguousarray(pixels, dtype=np.float32))
    out.close()


def _pixels(img):
    """(H, W, 3) of ``image.pixels``, top row first."""
    w, h = img.size
    buf = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(buf)
    return buf.reshape(h, w, img.channels)[::-1, :, :3]


def _grey_png(tmp_path, name="grey128.png"):
    path = tmp_path / name
    _write(path, np.full((16, 32, 3), GREY, np.float32), "uint8")
    return path


def _plane_scene(path):
    """A Diffuse plane lit by the image at ``path`` alone, filling a 32×32 camera looking
    down; returns the image."""
    bs.reset()
    _, env = bs.add_world(path=str(path))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    bpy.context.object.data.materials.append(
        bs.bsdf_material("Grey", "ShaderNodeBsdfDiffuse", Color=(ALBEDO, ALBEDO, ALBEDO, 1.0)))
    bs.add_camera(location=(0.0, 0.0, 2.0), rotation=(0.0, 0.0, 0.0))
    bs.set_resolution(32, 32)
    return env.image


def _lit(tmp_path, name):
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    img = bs.render_exr(tmp_path / f"{name}.exr")
    assert img[..., 3].min() > 0.999          # the plane fills the frame
    return img[..., :3]


# --------------------------------------------------------------------------- F12

def test_srgb_png_world_lights_a_plane_by_its_linear_value(tmp_path):
    """Constant radiance L on an open upward Lambert plane: radiance albedo·L (irradiance
    π·L).  sRGB 128 is L = 0.2159; the same file as Non-Color is L = 128/255."""
    img = _plane_scene(_grey_png(tmp_path))
    assert img.colorspace_settings.name == "sRGB"
    srgb = _lit(tmp_path, "srgb")
    np.testing.assert_allclose(srgb.mean(axis=(0, 1)), ALBEDO * GREY_LINEAR, rtol=0.005)
    img.colorspace_settings.name = "Non-Color"             # the same file, read again
    data = _lit(tmp_path, "data")
    np.testing.assert_allclose(data.mean(axis=(0, 1)), ALBEDO * GREY, rtol=0.005)


def test_packed_8bit_srgb_png_is_linearised_not_refused(tmp_path):
    path = _grey_png(tmp_path, "packed.png")
    img = _plane_scene(path)
    img.pack()
    path.unlink()                                    # only the packed bytes are left
    assert img.packed_file is not None and not img.is_float
    world = scene_export.export_world(bpy.context.scene, [])
    np.testing.assert_allclose(world.image, GREY_LINEAR, rtol=1e-5)
    np.testing.assert_allclose(_lit(tmp_path, "packed").mean(axis=(0, 1)),
                               ALBEDO * GREY_LINEAR, rtol=0.005)


def test_float_image_pixels_are_not_converted_twice(tmp_path):
    """Blender converts float buffers on load: a packed sRGB-tagged EXR of 0.5 reads 0.214."""
    path = tmp_path / "half.exr"
    _write(path, np.full((4, 8, 3), 0.5, np.float32), "float")
    bs.reset()
    img = bpy.data.images.load(str(path))
    img.colorspace_settings.name = "sRGB"
    bs.add_world(image=img)
    from_file = scene_export.export_world(bpy.context.scene, []).image
    img.pack()
    packed = scene_export.export_world(bpy.context.scene, []).image
    want = ((0.5 + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(from_file, want, rtol=1e-5)
    np.testing.assert_allclose(packed, want, rtol=1e-4)


def test_unconvertible_colour_space_is_a_clear_error_and_leaves_the_scene(tmp_path,
                                                                         monkeypatch):
    img = _plane_scene(_grey_png(tmp_path))
    img.colorspace_settings.name = "Filmic sRGB"
    monkeypatch.setattr(envmap, "have_opencolorio", lambda: False)
    before = sorted(i.name for i in bpy.data.images)
    with pytest.raises(RuntimeError, match="Filmic sRGB"):
        bpy.ops.prt.precompute()
    assert sorted(i.name for i in bpy.data.images) == before
    assert not any(storage.has(o, storage.VISIBILITY) for o in bpy.data.objects)
    img.colorspace_settings.name = "sRGB"             # sRGB needs no OpenColorIO
    np.testing.assert_allclose(scene_export.export_world(bpy.context.scene, []).image,
                               GREY_LINEAR, rtol=1e-6)


# --------------------------------------------------------------------------- Cycles

def _sky_png(tmp_path):
    """8-bit sRGB sky: blue-white gradient over a darker ground, a soft bright patch."""
    h, w = 64, 128
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    sky = np.empty((h, w, 3), np.float32)
    up = np.clip(1.0 - v / 0.5, 0.0, 1.0)[:, None]
    sky[:] = np.where(v[:, None, None] < 0.5,
                      (0.55 + 0.35 * up[..., None]) * np.array([0.6, 0.75, 1.0]),
                      np.array([0.3, 0.25, 0.2]))
    glow = np.exp(-(((u[None, :] - 0.3) / 0.08) ** 2 + ((v[:, None] - 0.3) / 0.08) ** 2))
    sky = np.clip(sky + glow[..., None] * np.array([0.4, 0.35, 0.2]), 0.0, 1.0)
    path = tmp_path / "sky.png"
    _write(path, sky, "uint8")
    return path


@pytest.mark.slow
def test_srgb_sky_png_matches_cycles_and_ignores_the_view_transform(tmp_path):
    bs.reset()
    img = bpy.data.images.load(str(_sky_png(tmp_path)))
    assert img.colorspace_settings.name == "sRGB" and not img.is_float
    bs.add_world(image=img)
    bs.add_ground(size=6.0, cuts=16)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(0.0, 0.0, 0.8))
    bpy.ops.object.shade_smooth()
    bs.add_camera()
    bs.set_resolution(32, 32)
    scene = bpy.context.scene
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ours = bs.render_exr(tmp_path / "prt.exr", transparent=False)     # with the sky
    cycles = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=256,
                           transparent=False)
    err = bs.rel_l2(ours, cycles)
    print(f"sRGB sky PNG vs Cycles rel-L2: {err:.4f}")
    assert err < 0.05, err
    tried = []
    for view in ("Standard", "AgX", "Filmic"):
        try:
            scene.view_settings.view_transform = view
        except TypeError:            # not in this Blender's config
            continue
        tried.append(view)
        again = bs.render_exr(tmp_path / f"prt_{view}.exr", transparent=False)
        np.testing.assert_array_equal(again, ours, err_msg=view)
    assert {"Standard", "AgX"} <= set(tried)


FEW_SPACES = ("sRGB", "Non-Color", "Linear Rec.709", "Filmic sRGB", "ACEScg", "Rec.2100-PQ")


@pytest.mark.slow
@pytest.mark.parametrize("space", ["Linear Rec.709", "Linear Rec.2020", "ACEScg"])
def test_every_colour_space_reads_as_cycles_reads_it(tmp_path, space):
    """A flat float EXR tagged with each of Blender's colour spaces (a few of them in the
    other working spaces): the background Cycles shows equals our converted world."""
    bs.reset()
    bpy.ops.wm.set_working_color_space(working_space=space)
    assert bpy.data.colorspace.working_space == space
    path = tmp_path / "flat.exr"
    _write(path, np.broadcast_to(np.float32([0.25, 0.5, 0.75]), (4, 8, 3)).copy(), "float")
    img = bpy.data.images.load(str(path))
    bs.add_world(image=img)
    bs.add_camera(location=(0.0, 0.0, 0.0), rotation=(1.57, 0.0, 0.0))
    bs.set_resolution(4, 4)
    names = [i.identifier for i in img.colorspace_settings.bl_rna.properties["name"].enum_items]
    assert set(FEW_SPACES) <= set(names)
    for cs in names if space == "Linear Rec.709" else FEW_SPACES:     # ~2 s a render
        img.colorspace_settings.name = cs
        ours = scene_export.export_world(bpy.context.scene, []).image[0, 0]
        cycles = bs.render_exr(tmp_path / "c.exr", engine="CYCLES", samples=1,
                               transparent=False)[2, 2, :3]
        # Cycles keeps out-of-gamut negatives; our world clamps them to 0.
        np.testing.assert_allclose(ours, np.maximum(cycles, 0.0), rtol=2e-4, atol=1e-5,
                                   err_msg=cs)
