"""shaders/texture_lib.glsl against core.scene.textures: an unoccluded Lambert plane under a
white world shows its albedo, each pixel the texture read in numpy."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.core.scene import textures
from prt_relight.bench import scenes

from ..cases.textures import plane_from_above, texture_image, textured_material, white_world


pytestmark = pytest.mark.usefixtures("registered_addon")


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- Blender

@pytest.mark.parametrize("interpolation, extension, mapping", [
    ("Linear", "REPEAT", None), ("Closest", "EXTEND", None), ("Cubic", "MIRROR", None),
    ("Linear", "CLIP", (0.3, -0.2, 0.0)),
    # many periods away (texel indices far below zero and past the size): the wrap's modulo
    ("Linear", "REPEAT", (-13.3, 25.7, 0.0)), ("Cubic", "MIRROR", (-9.4, 31.2, 0.0))])
def test_glsl_texture_equals_numpy_at_every_pixel(tmp_path, interpolation, extension, mapping):
    """An unoccluded Lambert plane under a white world shows its albedo: each pixel is the
    texture read (core.scene.textures.sample) at the pixel centre's UV."""
    scenes.reset()
    white_world()
    plane = plane_from_above()
    rng = np.random.default_rng(4)
    rgba = np.ones((8, 8, 4), np.float32)
    rgba[..., :3] = rng.random((8, 8, 3))
    img = texture_image("noise", rgba)
    plane.data.materials.append(textured_material("Tex", img, interpolation, extension,
                                          mapping=mapping))
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "f.exr")[::-1]            # bottom row first, as v
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
