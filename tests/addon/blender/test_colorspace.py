"""The world image's colour space as addon.blender.scene_export reads it: converted from the
image's colour space to the blend file's working space as Blender converts float images;
Non-Color read as stored, sRGB PNGs (packed or not) linearised once, float buffers not
converted twice; a space that cannot be converted is a clear error."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
import OpenImageIO as oiio

from prt_relight.addon.blender import scene_export, storage
from prt_relight.core.sphere import envmap
from prt_relight.bench import scenes


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
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
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
    scenes.reset()
    env = scenes.environment_node(scenes.add_world(path=str(path)))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    bpy.context.object.data.materials.append(
        scenes.bsdf_material("Grey", "ShaderNodeBsdfDiffuse", Color=(ALBEDO, ALBEDO, ALBEDO, 1.0)))
    scenes.add_camera(location=(0.0, 0.0, 2.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 32)
    return env.image


def _lit(tmp_path, name):
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    img = scenes.render_exr(tmp_path / f"{name}.exr")
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
    scenes.reset()
    img = bpy.data.images.load(str(path))
    img.colorspace_settings.name = "sRGB"
    scenes.add_world(image=img)
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
