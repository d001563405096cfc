"""Light that bounces against Cycles with its bounces (issue 29): a Cornell box lit by an
area lamp (colour bleeding), a room lit through a window by the sun and sky of an HDRI,
an object on a coloured ground under an HDRI, a plane seen from below; the Light Paths'
bounces set to 0 give the direct frame; turning the HDRI or a lamp's colour updates the
bounce without a precompute.  Cycles' references are two seeds, variance subtracted
(core.report.metrics.rel_l2_converged)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import storage
from prt_relight.core.report.metrics import rel_l2_converged

from prt_relight.bench import scenes

pytestmark = pytest.mark.slow


def _render(tmp_path, name, engine="PRT_RELIGHT", samples=256, seed=0, transparent=False):
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.film_transparent = transparent
    if engine == "CYCLES":
        cy = scene.cycles
        cy.device, cy.samples, cy.seed = "CPU", samples, seed
        cy.use_denoising = cy.use_adaptive_sampling = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    bpy.ops.render.render()
    path = tmp_path / f"{name}.exr"
    bpy.data.images["Render Result"].save_render(str(path))
    return scenes.read_exr(path)


def _cycles(tmp_path, name, samples=256, transparent=False):
    return [_render(tmp_path, f"{name}{k}", "CYCLES", samples, k, transparent)
            for k in range(2)]


def test_cornell_box_bleeds_colour_as_cycles_does(registered_addon, tmp_path):
    scenes.cornell_box()
    scenes.light_paths(4)
    bpy.ops.prt.precompute()
    ours = _render(tmp_path, "ours")
    cycles = _cycles(tmp_path, "cycles", 512)
    scenes.light_paths(0)
    direct = _render(tmp_path, "direct")
    err = rel_l2_converged(ours, cycles)[2]
    assert err < 0.06, err                               # measured 3.4 % at 96^2
    assert rel_l2_converged(direct, cycles)[2] > 0.35     # the bounce is 44 % of the light
    # the floor by the red wall gets red light, by the green wall green (colour bleeding)
    indirect, truth = ours - direct, np.mean(cycles, 0) - direct
    for img in (indirect, truth):
        left, right = img[78:90, 21:36, :3].mean((0, 1)), img[78:90, 60:75, :3].mean((0, 1))
        assert left[0] / left[1] > 1.2 and right[1] / right[0] > 1.2, (left, right)


def test_window_lit_room_with_and_without_bounces(registered_addon, tmp_path):
    room = scenes.window_room()
    scenes.light_paths(0)
    bpy.ops.prt.precompute()
    assert room.prt.back_sides                         # the camera sees the walls' backs
    direct = _render(tmp_path, "direct")
    assert rel_l2_converged(direct, _cycles(tmp_path, "cd"))[2] < 0.045   # measured 3.2 %
    scenes.light_paths(4)
    bpy.ops.prt.precompute()
    ours = _render(tmp_path, "ours")
    err = rel_l2_converged(ours, _cycles(tmp_path, "cb", 512))[2]
    assert err < 0.075, err                              # measured 4.9 % at 96 x 72


def test_object_on_a_coloured_ground_under_an_hdri(registered_addon, tmp_path):
    scenes.coloured_ground()
    scenes.light_paths(4)
    bpy.ops.prt.precompute()
    ours = _render(tmp_path, "ours", transparent=True)
    cycles = _cycles(tmp_path, "c", 512, transparent=True)
    err = rel_l2_converged(ours, cycles)[2]
    assert err < 0.045, err                               # measured 2.7 % at 96 x 72
    scenes.light_paths(0)
    direct = _render(tmp_path, "direct", transparent=True)
    assert rel_l2_converged(direct, cycles)[2] > 3 * err    # the bounce is what closes it


def test_plane_seen_from_below_is_lit_from_below(registered_addon, tmp_path):
    scenes.reset()
    scenes.add_world("forest")
    plane = scenes.add_ground(size=4, cuts=24)
    plane.location.z = 1.0
    plane.data.materials.append(scenes.bsdf_material("Plane", "ShaderNodeBsdfDiffuse",
                                                       Color=(0.7, 0.7, 0.7, 1.0)))
    scenes.add_camera(location=(0, -4.5, -0.8), rotation=(math.radians(100), 0, 0),
                       resolution=None)
    scenes.set_resolution(64, 48)
    scenes.light_paths(0)
    bpy.ops.prt.precompute()
    assert plane.prt.back_sides
    ours = _render(tmp_path, "ours", transparent=True)
    err = rel_l2_converged(ours, _cycles(tmp_path, "c", transparent=True))[2]
    assert err < 0.04, err                                # measured 2.0 % at 96 x 72


def test_no_bounces_is_the_direct_frame_and_edits_relight_the_bounce(registered_addon,
                                                                    tmp_path):
    """Light Paths at 0 on a precompute with bounces draws exactly the frame of a
    precompute without them; turning the HDRI and recolouring a lamp redraw the bounce
    as a fresh precompute would, with none."""
    lamp = scenes.cornell_box()
    scenes.light_paths(0)
    bpy.ops.prt.precompute()
    assert not any(storage.has(o, storage.BOUNCE) for o in bpy.data.objects)
    plain = _render(tmp_path, "plain")
    scenes.light_paths(4)
    bpy.ops.prt.precompute()
    assert all(storage.has(o, storage.BOUNCE) for o in bpy.data.objects if o.type == "MESH")
    scenes.light_paths(0)
    np.testing.assert_array_equal(_render(tmp_path, "zero"), plain)
    scenes.light_paths(4)
    lamp.data.color = (1.0, 0.6, 0.3)
    live = _render(tmp_path, "live")
    bpy.ops.prt.precompute()
    np.testing.assert_allclose(_render(tmp_path, "fresh"), live, rtol=1e-5, atol=1e-6)
