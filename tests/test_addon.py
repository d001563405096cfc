"""The add-on in headless Blender: precompute, F12, storage in the .blend, bad input."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import precompute, storage
from prt_relight.addon.frame import state as runtime
from prt_relight.core.common.parallel import Cancelled

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")


def _stored():
    """(object, blob key) of every object's stored visibility: equal lists, same data."""
    return sorted((o.name, storage.key(o, storage.VISIBILITY)) for o in bpy.data.objects
                  if storage.has(o, storage.VISIBILITY))


def _has_data(ob):
    return storage.has(ob, storage.VISIBILITY)


def _small_scene(hdri="sunset", cuts=16, subdiv=1):
    bs.reset()
    bs.add_world(path=bs.hdri_path(hdri))
    bs.add_ground(size=6.0, cuts=cuts)
    bs.add_suzanne(subdiv=subdiv)
    bs.add_camera()
    bs.set_resolution(64, 48)
    bpy.context.scene.prt.supersampling = 2


def _frame_warnings():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def test_precompute_render_save_reopen_same_pixels(tmp_path):
    _small_scene()
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    suzanne = bpy.data.objects["Suzanne"]
    assert _has_data(suzanne)
    before = bs.render_exr(tmp_path / "a.exr")
    assert np.isfinite(before).all()
    assert before[..., 3].max() == 1.0 and before[..., :3].max() > 0.05
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bs.reset()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    state = _frame_warnings()
    assert all(o.status == "ok" for o in state.objects), [(o.name, o.status) for o in state.objects]
    after = bs.render_exr(tmp_path / "b.exr")
    np.testing.assert_array_equal(before, after)


def test_shadows_differ_from_unshadowed(tmp_path):
    """Stored visibility is really used: clearing it brightens the contact region."""
    _small_scene()
    bpy.ops.prt.precompute()
    shadowed = bs.render_exr(tmp_path / "s.exr")
    bpy.ops.prt.clear()
    assert _stored() == []
    state = _frame_warnings()
    assert any("Not precomputed" in w for w in state.warnings)
    open_sky = bs.render_exr(tmp_path / "o.exr")
    assert open_sky[..., :3].mean() > shadowed[..., :3].mean() * 1.02


def test_mesh_edited_after_precompute_is_stale_not_broken(tmp_path):
    _small_scene()
    bpy.ops.prt.precompute()
    suzanne = bpy.data.objects["Suzanne"]
    suzanne.data.vertices[0].co.z += 0.3                 # same topology: stale
    suzanne.data.update()
    state = _frame_warnings()
    assert any("stale" in w for w in state.warnings)
    assert np.isfinite(bs.render_exr(tmp_path / "a.exr")).all()
    ground = bpy.data.objects["Grid"]
    ground.modifiers.new("more", "SUBSURF").levels = 1     # new topology: point count differs
    state = _frame_warnings()
    statuses = {o.name: o.status for o in state.objects}
    assert statuses["Grid"] == "stale"
    img = bs.render_exr(tmp_path / "b.exr")
    assert np.isfinite(img).all() and img[..., :3].max() > 0


def _assert_precompute_error(match):
    images = _stored()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.prt.precompute()
    assert _stored() == images
    assert not any(_has_data(o) for o in bpy.data.objects)


def test_no_world_is_a_clear_error():
    _small_scene()
    bpy.context.scene.world = None
    _assert_precompute_error("no World")


def test_environment_without_image_is_a_clear_error():
    _small_scene()
    bpy.context.scene.world.node_tree.nodes["Environment Texture"].image = None
    _assert_precompute_error("has no image")


def test_missing_image_file_is_a_clear_error(tmp_path):
    _small_scene()
    env = bpy.context.scene.world.node_tree.nodes["Environment Texture"]
    env.image = bpy.data.images.load(bs.hdri_path("forest"))
    env.image.filepath = str(tmp_path / "gone.exr")
    _assert_precompute_error("missing")


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_environment_pixels_are_a_clear_error(tmp_path, bad):
    _small_scene()
    px = np.full((16, 32, 3), 0.5, dtype=np.float32)
    px[3, 7, 1] = bad
    env = bpy.context.scene.world.node_tree.nodes["Environment Texture"]
    env.image = bs.float_image("bad", px)
    _assert_precompute_error("NaN/Inf")
    # The engine reports the same error for F12 instead of drawing garbage.
    state = _frame_warnings()
    assert state.error and "NaN/Inf" in state.error
    with pytest.raises(RuntimeError, match="NaN/Inf"):
        bs.render_exr(tmp_path / "x.exr")


def test_zero_area_faces_warn_and_stay_finite(tmp_path):
    _small_scene()
    mesh = bpy.data.meshes.new("degenerate")
    verts = [(0, 0, 2.5), (1, 0, 2.5), (2, 0, 2.5), (0, 1, 2.5), (1, 1, 2.5)]
    mesh.from_pydata(verts, [], [(0, 1, 2), (0, 3, 4)])    # first face has zero area
    ob = bpy.data.objects.new("Degenerate", mesh)
    bpy.context.scene.collection.objects.link(ob)
    bpy.ops.prt.precompute()
    state = _frame_warnings()
    assert state.objects and all(o.status == "ok" for o in state.objects)
    img = bs.render_exr(tmp_path / "a.exr")
    assert np.isfinite(img).all()


def test_empty_mesh_is_skipped_and_only_empty_is_an_error():
    _small_scene()
    ob = bpy.data.objects.new("Empty Mesh", bpy.data.meshes.new("nothing"))
    bpy.context.scene.collection.objects.link(ob)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert not _has_data(ob)
    bs.reset()
    bs.add_world(path=bs.hdri_path("forest"))
    ob = bpy.data.objects.new("Empty Mesh", bpy.data.meshes.new("nothing"))
    bpy.context.scene.collection.objects.link(ob)
    _assert_precompute_error("Nothing to precompute")


def test_cancel_leaves_scene_unchanged():
    """ESC sets ``cancel_requested``; the worker stops and nothing is committed."""
    _small_scene()
    job = precompute.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
    job.cancel_requested = True
    with pytest.raises(Cancelled):
        job.run()
    assert _stored() == []
    assert not any(_has_data(o) for o in bpy.data.objects)


def test_world_rotation_redraws_without_recompute(tmp_path):
    _small_scene()
    bpy.ops.prt.precompute()
    a = bs.render_exr(tmp_path / "a.exr")
    images = _stored()
    world = bpy.context.scene.world
    nt = world.node_tree
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value[2] = 2.0
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], nt.nodes["Environment Texture"].inputs["Vector"])
    b = bs.render_exr(tmp_path / "b.exr")
    assert _stored() == images
    assert np.abs(a - b)[..., :3].mean() > 0.01 * a[..., :3].mean()


def test_materials_export():
    from prt_relight.addon.blender import scene_export

    warnings = []
    mat = bs.bsdf_material("glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                           Roughness=0.3)
    nt = mat.node_tree
    glossy = nt.nodes["Glossy BSDF"]
    m = scene_export.export_material(mat, warnings)
    assert m.distribution == "BECKMANN" and m.roughness == pytest.approx(0.3)
    assert m.is_diffuse_only is False and m.diffuse_albedo == (0.0, 0.0, 0.0)
    nt.nodes.remove(glossy)
    emission = nt.nodes.new("ShaderNodeHoldout")
    nt.links.new(emission.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    scene_export.export_material(mat, warnings)
    assert any("not supported" in w for w in warnings)


def test_precompute_again_replaces_cached_visibility(tmp_path):
    """Re-precomputing after removing an occluder must not reuse the old decoded bits
    (the ground's own geometry and image name are unchanged)."""
    _small_scene()
    bpy.ops.prt.precompute()
    with_occluder = bs.render_exr(tmp_path / "a.exr")
    bpy.data.objects.remove(bpy.data.objects["Suzanne"])
    state = _frame_warnings()
    assert any("removed or hidden" in w for w in state.warnings)
    bpy.ops.prt.precompute()
    state = _frame_warnings()
    assert not any("changed" in w.lower() for w in state.warnings), state.warnings
    without = bs.render_exr(tmp_path / "b.exr")
    assert np.isfinite(without).all() and not np.array_equal(with_occluder, without)
    # The ground where Suzanne stood is now lit as open sky: no dark contact shadow left.
    grid = [o for o in state.objects if o.name == "Grid"][0]
    open_bits = runtime.open_visibility(grid.points.normals,
                                        runtime.directions.cubemap(state.resolution))
    np.testing.assert_array_equal(grid.bits, open_bits)


def test_text_objects_render_and_instances_are_reported(tmp_path):
    _small_scene()
    bpy.ops.object.text_add(location=(1.5, -1.0, 0.01))
    coll = bpy.data.collections.new("inst")
    bpy.data.objects["Suzanne"].users_collection[0].objects.unlink(bpy.data.objects["Suzanne"])
    coll.objects.link(bpy.data.objects["Suzanne"])
    empty = bpy.data.objects.new("Instancer", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = coll
    bpy.context.scene.collection.objects.link(empty)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert _has_data(bpy.data.objects["Text"])
    state = _frame_warnings()
    assert any("Instanced objects" in w and "Suzanne" in w for w in state.warnings)
    assert np.isfinite(bs.render_exr(tmp_path / "a.exr")).all()


def test_sh_method_renders_near_reference_for_low_frequency_light(tmp_path):
    """A smooth world is (nearly) inside the SH span: SH order 4 ~ REFERENCE; a sharp
    HDRI shows SH's low-frequency error, shrinking with the order."""
    bs.reset()
    h, w = 32, 64
    th = (np.arange(h) + 0.5) / h * np.pi
    ph = (0.5 - (np.arange(w) + 0.5) / w) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    z, x = np.cos(T), np.sin(T) * np.cos(P)
    smooth = (1.2 + 0.6 * z + 0.3 * x)[..., None] * np.array([1.0, 0.9, 0.7])
    bs.add_world(image=bs.float_image("smooth", smooth.astype(np.float32)))
    bs.add_ground(size=6.0, cuts=16)
    bs.add_suzanne(subdiv=1)
    bs.add_camera()
    bs.set_resolution(64, 48)
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.append(bs.bsdf_material("diffuse", "ShaderNodeBsdfDiffuse"))
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    ref = bs.render_exr(tmp_path / "ref.exr")
    scene.prt.method = "SH"
    scene.prt.sh_order = 4
    ours = bs.render_exr(tmp_path / "sh.exr")
    assert np.isfinite(ours).all()
    assert bs.rel_l2(ours, ref) < 0.01

    env = scene.world.node_tree.nodes["Environment Texture"]
    env.image = bpy.data.images.load(bs.hdri_path("sunset"))
    scene.prt.method = "REFERENCE"
    ref = bs.render_exr(tmp_path / "ref2.exr")
    errors = []
    for order in (2, 5):
        scene.prt.method = "SH"
        scene.prt.sh_order = order
        errors.append(bs.rel_l2(bs.render_exr(tmp_path / f"sh{order}.exr"), ref))
    assert errors[1] < errors[0]
    assert errors[1] > 0.01              # the sun's sharp shadows are beyond order 5


@pytest.mark.parametrize("method", ["REFERENCE", "SSDF_SG"])
def test_view_draw_path_draws_the_same_frame_as_f12(method):
    """The viewport's drawing code (everything but Blender's display shader) runs
    headless: a fake region/view from the scene camera gives the F12 pixels.  SSDF_SG
    draws per pixel, and runs its ground's pair pass (an offscreen of its own) inside the
    viewport's bound framebuffer."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.methods.ssdf_sg import gpu as ssdf_sg_gpu

    _small_scene()
    bpy.context.scene.prt.method = method
    bpy.ops.prt.precompute()
    ssdf_sg_gpu.PAIR_TABLES.clear()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()                      # gives the gpu module a context in -b
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    w, h = 64, 48
    view, window = cam.matrix_world.inverted(), cam.calc_matrix_camera(depsgraph, x=w, y=h)
    engine, shown = bs.view_draw(depsgraph, view, window, w, h)
    assert engine.bound == 0 and engine._view_texture is not None
    assert engine.stats is not None
    direct = render_pixels(engine._state, view, window, w, h,
                           scene.render.film_transparent, True)
    np.testing.assert_array_equal(shown, direct)
    assert np.isfinite(shown).all() and shown[..., :3].max() > 0.05
    assert bool(ssdf_sg_gpu.PAIR_TABLES) == (method == "SSDF_SG")


def test_modal_precompute_esc_cancels_and_timer_finishes():
    """The UI path (modal operator) driven headless with fake events: ESC cancels with
    nothing changed; otherwise TIMER events run it to completion and commit."""
    import threading
    import types

    from prt_relight.addon.ui import operators

    class Recorder:
        def __init__(self):
            self.reports = []
            self._timer = None
            self._error = None

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    _small_scene()
    wm = types.SimpleNamespace(progress_update=lambda v: None, progress_end=lambda: None,
                               event_timer_remove=lambda t: None)
    ctx = types.SimpleNamespace(window_manager=wm, scene=bpy.context.scene, screen=None,
                                workspace=types.SimpleNamespace(status_text_set=lambda t: None))

    def start(op):
        op._job = precompute.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
        op._end = lambda c: operators.PRT_OT_precompute._end(op, c)
        op._job.cancel_requested = False
        gate = threading.Event()
        job = op._job

        def work():
            gate.wait(5)
            try:
                job.run()
            except BaseException as exc:
                op._error = exc

        op._thread = threading.Thread(target=work)
        op._thread.start()
        return gate

    def drive(op, first_event):
        result = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type=first_event))
        while result == {"RUNNING_MODAL"}:
            op._thread.join(0.05)
            result = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type="TIMER"))
        return result

    op = Recorder()
    gate = start(op)
    assert operators.PRT_OT_precompute.modal(
        op, ctx, types.SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}
    op._job.cancel_requested = False
    result_esc = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type="ESC"))
    gate.set()                                    # the worker starts only after ESC
    if result_esc == {"RUNNING_MODAL"}:
        result_esc = drive(op, "TIMER")
    assert result_esc == {"CANCELLED"}
    assert any("cancelled" in m for _, m in op.reports)
    assert _stored() == [] and not any(_has_data(o) for o in bpy.data.objects)

    op = Recorder()
    start(op).set()
    assert drive(op, "TIMER") == {"FINISHED"}
    assert _has_data(bpy.data.objects["Suzanne"])
    assert not operators.RUNNING


def test_viewport_shades_view_dependent_materials_off_the_main_thread():
    """REFERENCE with a glossy layer: after a camera move the viewport redraws at once
    with the previous radiance and a worker computes the new one; the next draw shows
    exactly what F12 computes for that view."""
    from prt_relight.addon.frame.engine import render_pixels

    _small_scene()                               # no materials: Principled, view dependent
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    w, h = 48, 36
    window = cam.calc_matrix_camera(depsgraph, x=w, y=h)

    def draw(view):
        return bs.view_draw(depsgraph, view, window, w, h, engine=engine)[1]

    engine = bs.FakeViewEngine()
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
    np.testing.assert_array_equal(final, expected)
    assert not np.array_equal(interim, final)                       # highlights caught up
