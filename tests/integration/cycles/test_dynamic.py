"""A keyframed dynamic object against Cycles: precomputed at frame 1, rendered at frame 24
after it moved and turned: slow."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


pytestmark = pytest.mark.usefixtures("registered_addon")


def _scene(detail="MEDIUM", hdri="city"):
    """A 4x4 ground of 40^2 quads and a dynamic cube above it (edge 1)."""
    scene = scenes.reset()
    scenes.add_world(hdri)
    scenes.add_ground(size=4.0, cuts=40)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 0.9))
    cube = bpy.context.object
    cube.prt.dynamic = True
    scene.prt.light_sources = 0
    scene.prt.field_detail = detail
    return scene, cube


@pytest.mark.slow
@pytest.mark.parametrize("sky", ["sunrise", "sun"])
def test_keyframed_object_against_cycles(tmp_path, sky):
    """Precomputed at frame 1, rendered at frame 24 after the cube moved and turned
    (keyframes): REFERENCE's F12 against Cycles' direct light at that frame, under a
    soft HDRI and under a one-pixel sun over a dim sky (its shadow drawn per pixel)."""
    scene, cube = _scene(detail="HIGH", hdri="sunrise")
    if sky == "sun":
        img = scenes.sun_image(512, 256, (0.4, -0.3, 0.8), 2e4) + np.float32(0.05)
        scenes.add_world(image=scenes.float_image("sun", img))
    scene.prt.light_sources = 8
    scenes.add_camera(location=(0.0, -5.0, 4.0), rotation=(0.9, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    scene.frame_start, scene.frame_end = 1, 24
    for frame, loc, rot in ((1, (-0.8, 0.0, 0.8), 0.0), (24, (0.7, 0.5, 0.7), 1.3)):
        cube.location, cube.rotation_euler = loc, (0.0, 0.2, rot)
        cube.keyframe_insert("location", frame=frame)
        cube.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_set(1)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    scene.frame_set(24)
    ours = scenes.render_exr(tmp_path / "ours.exr")
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err = rel_l2(ours, truth)
    assert err < 0.05, err
