"""addon.frame.engine in headless Blender: the viewport's draw path (a fake region and view)
draws the same frame as F12, turning the world redraws without a recompute, and the
viewport shades view-dependent materials off the main thread."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes

from ... import viewport
from ...cases.small import small_scene, stored


pytestmark = pytest.mark.usefixtures("registered_addon")


def _world_mapping():
    """A Mapping node between the World's texture coordinates and its Environment Texture
    (its Rotation turns the HDRI)."""
    nt = bpy.context.scene.world.node_tree
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], nt.nodes["Environment Texture"].inputs["Vector"])
    return mapping


def _camera_view(w, h):
    """(depsgraph, view, window) of the scene camera at w x h, after one Workbench render
    (it gives the gpu module a context in -b)."""
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    return depsgraph, cam.matrix_world.inverted(), cam.calc_matrix_camera(depsgraph, x=w, y=h)


def test_world_rotation_redraws_without_recompute(tmp_path):
    small_scene()
    bpy.ops.prt.precompute()
    a = scenes.render_exr(tmp_path / "a.exr")
    images = stored()
    _world_mapping().inputs["Rotation"].default_value[2] = 2.0
    b = scenes.render_exr(tmp_path / "b.exr")
    assert stored() == images
    assert np.abs(a - b)[..., :3].mean() > 0.01 * a[..., :3].mean()


@pytest.mark.parametrize("method", ["REFERENCE", "SSDF_SG"])
def test_view_draw_path_draws_the_same_frame_as_f12(method):
    """The viewport's drawing code (everything but Blender's display shader) runs
    headless: a fake region/view from the scene camera gives the F12 pixels.  SSDF_SG
    draws per pixel, and runs its ground's pair pass (an offscreen of its own) inside the
    viewport's bound framebuffer."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.methods.ssdf_sg import gpu as ssdf_sg_gpu

    small_scene()
    bpy.context.scene.prt.method = method
    bpy.ops.prt.precompute()
    ssdf_sg_gpu.PAIR_TABLES.clear()
    scene = bpy.context.scene
    w, h = 64, 48
    depsgraph, view, window = _camera_view(w, h)
    engine, shown = viewport.view_draw(depsgraph, view, window, w, h)
    assert engine.bound == 0 and engine._view_texture is not None
    assert engine.stats is not None
    direct = render_pixels(engine._state, view, window, w, h,
                           scene.render.film_transparent, True)
    # the same pixels up to float rounding: F12 sums only the points its camera may see
    # (REFERENCE), the viewport every point, and a dense sum's rows take BLAS's blocking
    np.testing.assert_allclose(shown, direct, rtol=1e-6, atol=1e-7)
    assert np.isfinite(shown).all() and shown[..., :3].max() > 0.05
    assert bool(ssdf_sg_gpu.PAIR_TABLES) == (method == "SSDF_SG")


def test_viewport_shades_view_dependent_materials_off_the_main_thread():
    """REFERENCE with a glossy layer: after a camera move the viewport redraws at once
    with the previous radiance and a worker computes the new one; the next draw shows
    exactly what F12 computes for that view."""
    from prt_relight.addon.frame.engine import render_pixels

    small_scene()                               # no materials: Principled, view dependent
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    w, h = 48, 36
    window = cam.calc_matrix_camera(depsgraph, x=w, y=h)

    def draw(view):
        return viewport.view_draw(depsgraph, view, window, w, h, engine=engine)[1]

    engine = viewport.FakeViewEngine()
    view_a = cam.matrix_world.inverted()
    first = draw(view_a)
    assert engine._state.view_dependent and not engine.workers     # first frame: synchronous
    from mathutils import Matrix
    view_b = view_a @ Matrix.Rotation(0.15, 4, "Z")
    interim = draw(view_b)
    assert len(engine.workers) == 1                                 # shading went to a worker
    engine.workers[0].join(60)
    final = draw(view_b)
    expected = render_pixels(engine._state, view_b, window, w, h,
                             scene.render.film_transparent, True)
    # the worker sums the glossy part in numpy, F12 on the main thread on the GPU (the same
    # sums in float32, in another order)
    np.testing.assert_allclose(final, expected, rtol=1e-4, atol=1e-6)
    assert not np.allclose(interim, final, rtol=1e-3)               # highlights caught up


def test_viewport_shades_at_once_where_the_glossy_sums_run_on_a_hardware_gpu(monkeypatch):
    """REFERENCE with its GPU pass on a hardware GPU (taken as one here): a moved camera is
    shaded on the main thread at once (no worker, no stale frame)."""
    from prt_relight.addon.gpu import drawing
    small_scene()
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    monkeypatch.setattr(drawing, "software_gpu", lambda: False)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    w, h = 48, 36
    window = cam.calc_matrix_camera(depsgraph, x=w, y=h)
    engine = viewport.FakeViewEngine()
    view_a = cam.matrix_world.inverted()
    first = viewport.view_draw(depsgraph, view_a, window, w, h, engine=engine)[1]
    from mathutils import Matrix
    moved = viewport.view_draw(depsgraph, view_a @ Matrix.Rotation(0.15, 4, "Z"), window, w, h,
                               engine=engine)[1]
    assert engine._state.view_dependent and not engine.workers
    assert not np.allclose(first, moved, rtol=1e-3)


def _viewport_update(engine, change):
    """``change()``, then the engine's ``view_update`` with the depsgraph's updates, as
    Blender calls it after an edit (from the update handler, where ``updates`` is filled)."""
    import types
    calls = []

    def handler(scene, depsgraph):
        engine.view_update(types.SimpleNamespace(region_data=None), depsgraph)
        calls.append(depsgraph)

    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        change()
        bpy.context.view_layer.update()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    assert calls


def test_viewport_hdri_turn_keeps_the_objects_and_draws_a_full_syncs_frame():
    """Turning the HDRI (the World's Mapping) in the viewport reads the World again and
    keeps the synced objects (no mesh exported again); the frame is the one a full sync of
    the turned scene draws.  Moving an object syncs everything again."""
    small_scene()
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH":
            scenes.add_bsdf_material(ob, f"{ob.name} diffuse", "ShaderNodeBsdfDiffuse")
    bpy.context.scene.prt.method = "REFERENCE"
    bpy.ops.prt.precompute()
    mapping = _world_mapping()
    w, h = 48, 36
    depsgraph, view, window = _camera_view(w, h)
    engine = viewport.FakeViewEngine()
    before = viewport.view_draw(depsgraph, view, window, w, h, engine=engine)[1]
    first = engine._state

    def turn():
        mapping.inputs["Rotation"].default_value[2] += 1.3
    _viewport_update(engine, turn)
    turned = engine._state
    assert turned is not first
    assert all(a is b for a, b in zip(turned.objects, first.objects))
    assert len(turned.objects) == len(first.objects) == 2
    assert not np.allclose(turned.world.rotation, first.world.rotation)
    shown = viewport.view_draw(depsgraph, view, window, w, h, engine=engine)[1]
    fresh = viewport.view_draw(bpy.context.evaluated_depsgraph_get(), view, window, w, h)[1]
    np.testing.assert_allclose(shown, fresh, rtol=1e-4, atol=1e-6)
    assert np.abs(shown - before)[..., :3].mean() > 0.01 * before[..., :3].mean()

    def move():
        bpy.data.objects["Suzanne"].location.x += 0.2
    _viewport_update(engine, move)
    assert not any(a is b for a, b in zip(engine._state.objects, turned.objects))
