"""What a new user hits in the first hour: orthographic and panoramic cameras, objects
hidden from renders or the viewport, the inside of closed meshes, negative light, and
messages that must be true."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import precompute, storage
from prt_relight.addon.frame import state as runtime
from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2

from .. import viewport


pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET", "AUTO"]


def _ball_scene(hdri="forest", cuts=12, size=(48, 32)):
    """A ground, a smooth sphere above it (no material: Cycles' default Principled, so
    the view direction matters) and a camera."""
    scenes.reset()
    scenes.add_world(hdri)
    scenes.add_ground(size=4.0, cuts=cuts)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 1.0), radius=0.8)
    bpy.ops.object.shade_smooth()
    cam = scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(*size)
    bpy.context.scene.prt.supersampling = 1
    return cam


def _ortho(cam):
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 6.0


def _sync():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def test_orthographic_camera_renders_every_method_in_f12_and_the_viewport(tmp_path):
    """An orthographic camera (and Blender's numpad views) crashed every method in
    ``_eye``; the viewport path draws exactly the F12 pixels of the same view."""
    from prt_relight.addon.frame.engine import in_render, render_pixels

    cam = _ball_scene()
    _ortho(cam)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()                      # gives the gpu module a context in -b
    w, h = 40, 28
    for method in METHODS:
        scene.prt.method = method
        frame = scenes.render_exr(tmp_path / f"{method}.exr")
        assert np.isfinite(frame).all(), method
        lit = frame[..., 3] > 0.5
        assert lit.mean() > 0.3 and frame[lit][:, :3].mean() > 0.05, method
        def draw_viewport(depsgraph):
            cam_eval = cam.evaluated_get(depsgraph)
            view = cam_eval.matrix_world.inverted()
            window = cam_eval.calc_matrix_camera(depsgraph, x=w, y=h)
            engine, shown = viewport.view_draw(depsgraph, view, window, w, h, perspective=False)
            return shown, render_pixels(engine._state, view, window, w, h,
                                        scene.render.film_transparent, False)

        shown, direct = in_render(scene, draw_viewport)      # a GPU context of its own in -b
        np.testing.assert_array_equal(shown, direct)
        assert shown[..., :3].max() > 0.05, method


@pytest.mark.slow
def test_orthographic_frame_matches_cycles_as_the_perspective_one_does(tmp_path):
    """REFERENCE against Cycles through an orthographic camera is as close as through the
    perspective one: the view direction of a Principled sphere is the camera's axis."""
    cam = _ball_scene(size=(64, 48))
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    errors = {}
    for kind in ("PERSP", "ORTHO"):
        if kind == "ORTHO":
            _ortho(cam)
        ours = scenes.render_exr(tmp_path / f"ours_{kind}.exr")
        truth = scenes.render_exr(tmp_path / f"cycles_{kind}.exr", engine="CYCLES", samples=512)
        assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
        errors[kind] = rel_l2(ours, truth)
    assert errors["ORTHO"] < 0.04, errors
    assert errors["ORTHO"] < errors["PERSP"] + 0.01, errors


def test_panoramic_camera_is_refused_with_a_message():
    cam = _ball_scene()
    cam.data.type = "PANO"
    bpy.ops.prt.precompute()
    bpy.context.scene.render.engine = "PRT_RELIGHT"
    with pytest.raises(RuntimeError, match="panoramic"):
        bpy.ops.render.render()


def test_inside_of_a_closed_mesh_is_black_and_its_outside_lit(tmp_path):
    """Seen from inside a closed sphere every direction is blocked: Cycles' direct light
    is black there.  A mirrored (negative scale) closed mesh winds inward and must still
    be lit from outside."""
    scenes.reset()
    scenes.add_world("forest")
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 0.0), radius=3.0)
    cam = scenes.add_camera(location=(0.0, 0.0, 0.0), rotation=(1.4, 0.0, 0.3), resolution=None)
    scenes.set_resolution(32, 24)
    bpy.ops.prt.precompute()
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        inside = scenes.render_exr(tmp_path / f"inside_{method}.exr")
        assert inside[..., 3].min() > 0.99                  # the sphere fills the frame
        assert np.abs(inside[..., :3]).max() < 1e-6, method
    cam.location = (0.0, -12.0, 2.0)
    cam.rotation_euler = (1.45, 0.0, 0.0)
    sphere = bpy.data.objects["Sphere"]
    sphere.scale = (1.0, -1.0, 1.0)                         # winds its triangles inward
    bpy.ops.prt.precompute()
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        outside = scenes.render_exr(tmp_path / f"outside_{method}.exr")
        lit = outside[..., 3] > 0.5
        assert lit.mean() > 0.1 and outside[lit][:, :3].mean() > 0.05, method


def test_objects_hidden_from_renders_cast_no_ghost_shadow(tmp_path):
    """``hide_render`` objects are neither traced nor drawn in F12: the frame equals the
    scene without them, with no false 'changed' message; the viewport still draws them,
    without shadows."""
    _ball_scene()
    bpy.ops.mesh.primitive_cube_add(location=(1.2, 0.0, 0.5), size=1.0)
    cube = bpy.context.object
    cube.hide_render = True
    bpy.ops.prt.precompute()
    assert not storage.has(cube, storage.VISIBILITY)
    with_hidden = scenes.render_exr(tmp_path / "hidden.exr")
    state = _sync()                                         # the viewport's depsgraph
    statuses = {st.name: st.status for st in state.objects}
    assert statuses["Cube"] == "unshadowed" and statuses["Sphere"] == "ok"
    assert not any("changed" in w.lower() or "stale" in w.lower() for w in state.warnings)
    bpy.data.objects.remove(cube)
    bpy.ops.prt.precompute()
    without = scenes.render_exr(tmp_path / "without.exr")
    np.testing.assert_allclose(with_hidden, without, rtol=1e-5, atol=1e-6)


def test_objects_hidden_in_the_viewport_but_rendered_are_reported_at_precompute():
    _ball_scene()
    bpy.ops.mesh.primitive_cube_add(location=(1.2, 0.0, 0.5), size=1.0)
    bpy.context.object.hide_viewport = True
    job = precompute.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
    assert any("Cube" in w and "Hidden in the viewport" in w for w in job.warnings)
    assert "Cube" not in [o.name for o in job.objects]


def test_removing_or_hiding_a_traced_object_reports_stale_shadows():
    _ball_scene()
    bpy.ops.prt.precompute()
    assert not [w for w in _sync().warnings if "stale" in w]
    sphere = bpy.data.objects["Sphere"]
    sphere.hide_render = True
    assert any("removed or hidden" in w for w in _sync().warnings)
    sphere.hide_render = False
    bpy.data.objects.remove(sphere)
    assert any("removed or hidden" in w for w in _sync().warnings)


def test_curves_and_text_are_drawn_not_listed_as_instances():
    """Curves and text come as their object plus a mesh instance of themselves."""
    _ball_scene()
    bpy.ops.curve.primitive_bezier_circle_add(location=(-1.5, 1.0, 0.3))
    bpy.context.object.data.extrude = 0.2
    bpy.ops.object.text_add(location=(1.0, 1.5, 0.0))
    bpy.ops.prt.precompute()
    state = _sync()
    assert {"BézierCircle", "Text"} <= {st.name for st in state.objects}
    assert not any("#" in st.name for st in state.objects)     # no instance of themselves
    assert not any("Instanced" in w for w in state.warnings), state.warnings
    assert all(st.status == "ok" for st in state.objects)


def test_renaming_an_object_changes_nothing():
    _ball_scene()
    bpy.ops.prt.precompute()
    bpy.data.objects["Sphere"].name = "Ball"
    state = _sync()
    assert all(st.status == "ok" for st in state.objects)
    assert not any("changed" in w.lower() or "stale" in w.lower() for w in state.warnings), \
        state.warnings


def test_a_new_file_clears_the_previous_files_messages():
    _ball_scene()
    bpy.context.scene.world = None
    assert _sync().error and runtime.LAST_MESSAGES
    bpy.ops.wm.read_homefile(use_empty=True)
    assert runtime.LAST_MESSAGES == []


def test_clear_removes_what_deleted_objects_stored():
    _ball_scene()
    bpy.context.scene.prt.method = "SSDF_SG"
    bpy.ops.prt.precompute()
    sphere = bpy.data.objects["Sphere"]
    assert storage.has(sphere, "ssdf_sg")
    bpy.data.objects.remove(sphere)
    bpy.ops.prt.clear()
    assert not [img.name for img in bpy.data.images if img.name.startswith("PRT")]
    assert not [k for ob in bpy.data.objects for k in ob.keys() if k.startswith("prt_")]


def test_report_refuses_an_unknown_method():
    _ball_scene()
    with pytest.raises(RuntimeError, match="NOPE"):
        bpy.ops.prt.report(methods="NOPE", stability=False)


def test_negative_light_is_warned_and_never_drawn(tmp_path):
    """A 1-pixel 1e6 sun makes SH/WAVELET/RSL ring below zero, and a negative Strength
    makes all light negative: the render result stays >= 0, and the Strength is warned."""
    cam = _ball_scene()
    sun = scenes.sun_image(256, 128, (0.4, -0.5, 0.75), radiance=1e6)
    sun += 0.05
    img = scenes.float_image("sun", sun)
    bpy.context.scene.world.node_tree.nodes["Environment Texture"].image = img
    cam.data.type = "PERSP"
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    for method in ("SH", "WAVELET", "RSL", "REFERENCE"):
        scene.prt.method = method
        frame = scenes.render_exr(tmp_path / f"{method}.exr")
        assert np.isfinite(frame).all() and frame.min() >= 0.0, method
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = -1.0
    assert any("negative" in w for w in _sync().warnings)
    scene.prt.method = "REFERENCE"
    scene.render.film_transparent = False
    frame = scenes.render_exr(tmp_path / "negative.exr", transparent=False)
    assert frame.min() >= 0.0


def test_a_tiny_bright_sun_keeps_the_balls_shadow_with_ssdf_sg(tmp_path):
    """Under a 1-pixel 1e6 sun SSDF_SG drew 17.5 in the ball's shadow on the ground where
    REFERENCE had 0.28; the sun is now drawn per pixel with its own shadow map for every
    method, so the shadow is there for SSDF_SG as for REFERENCE."""
    cam = _ball_scene()
    img = np.full((128, 256, 3), 0.05, np.float32)
    img += scenes.sun_image(256, 128, (0.6, 0.0, 0.8), radiance=1e6)
    bpy.context.scene.world.node_tree.nodes["Environment Texture"].image = \
        scenes.float_image("sun", img)
    cam.location, cam.rotation_euler = (0.0, 0.0, 6.0), (0.0, 0.0, 0.0)   # 0.09 m a pixel
    bpy.ops.prt.precompute()
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        frame = scenes.render_exr(tmp_path / f"{method}.exr")
        # the ground at x = -1.2: outside the ball's silhouette, inside its shadow (the sun
        # is toward +x); and at x = +1.6: in the sun
        shadow, lit = frame[16, 10, :3], frame[16, 41, :3]
        assert shadow.max() < 0.05 * lit.max(), (method, shadow, lit)
