"""The world image's colour space against Cycles: an sRGB sky PNG matches Cycles whatever the
view transform, and a flat EXR tagged with each of Blender's colour spaces reads as Cycles
reads it: slow."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
import OpenImageIO as oiio

from prt_relight.addon.blender import scene_export
from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


pytestmark = pytest.mark.usefixtures("registered_addon")


# --------------------------------------------------------------------------- helpers

def _write(path, pixels, fmt):
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(np.ascontiguousarray(pixels, dtype=np.float32))
    out.close()


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
    scenes.reset()
    img = bpy.data.images.load(str(_sky_png(tmp_path)))
    assert img.colorspace_settings.name == "sRGB" and not img.is_float
    scenes.add_world(image=img)
    scenes.add_ground(size=6.0, cuts=16)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(0.0, 0.0, 0.8))
    bpy.ops.object.shade_smooth()
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 32)
    scene = bpy.context.scene
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ours = scenes.render_exr(tmp_path / "prt.exr", transparent=False)     # with the sky
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=256,
                           transparent=False)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err = rel_l2(ours, cycles)
    print(f"sRGB sky PNG vs Cycles rel-L2: {err:.4f}")
    assert err < 0.05, err
    tried = []
    for view in ("Standard", "AgX", "Filmic"):
        try:
            scene.view_settings.view_transform = view
        except TypeError:            # not in this Blender's config
            continue
        tried.append(view)
        again = scenes.render_exr(tmp_path / f"prt_{view}.exr", transparent=False)
        np.testing.assert_array_equal(again, ours, err_msg=view)
    assert {"Standard", "AgX"} <= set(tried)


FEW_SPACES = ("sRGB", "Non-Color", "Linear Rec.709", "Filmic sRGB", "ACEScg", "Rec.2100-PQ")


@pytest.mark.slow
@pytest.mark.parametrize("space", ["Linear Rec.709", "Linear Rec.2020", "ACEScg"])
def test_every_colour_space_reads_as_cycles_reads_it(tmp_path, space):
    """A flat float EXR tagged with each of Blender's colour spaces (a few of them in the
    other working spaces): the background Cycles shows equals our converted world."""
    scenes.reset()
    bpy.ops.wm.set_working_color_space(working_space=space)
    assert bpy.data.colorspace.working_space == space
    path = tmp_path / "flat.exr"
    _write(path, np.broadcast_to(np.float32([0.25, 0.5, 0.75]), (4, 8, 3)).copy(), "float")
    img = bpy.data.images.load(str(path))
    scenes.add_world(image=img)
    scenes.add_camera(location=(0.0, 0.0, 0.0), rotation=(1.57, 0.0, 0.0), resolution=None)
    scenes.set_resolution(4, 4)
    names = [i.identifier for i in img.colorspace_settings.bl_rna.properties["name"].enum_items]
    assert set(FEW_SPACES) <= set(names)
    for cs in names if space == "Linear Rec.709" else FEW_SPACES:     # ~2 s a render
        img.colorspace_settings.name = cs
        ours = scene_export.export_world(bpy.context.scene, []).image[0, 0]
        cycles = scenes.render_exr(tmp_path / "c.exr", engine="CYCLES", samples=1,
                               transparent=False)[2, 2, :3]
        # Cycles keeps out-of-gamut negatives; our world clamps them to 0.
        np.testing.assert_allclose(ours, np.maximum(cycles, 0.0), rtol=2e-4, atol=1e-5,
                                   err_msg=cs)
