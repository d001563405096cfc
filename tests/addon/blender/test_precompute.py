"""addon.blender.precompute in headless Blender: gather, run and commit -- the stored
visibility renders the same pixels after a save and reopen and is really used, an edited
mesh is stale not broken, bad input is a clear error that leaves the scene as it was (no
world, an environment without or with a missing image, non-finite pixels, empty meshes),
ESC commits nothing, a new precompute replaces the old bits, the trace streams each
object's blob."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import precompute, storage
from prt_relight.addon.frame import state as runtime
from prt_relight.core.common.parallel import Cancelled
from prt_relight.core.pipeline import tracing
from prt_relight.core.store import layouts
from prt_relight.bench import scenes
from ...cases.small import has_data, small_scene, stored


pytestmark = pytest.mark.usefixtures("registered_addon")


def _frame_warnings():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def test_precompute_render_save_reopen_same_pixels(tmp_path):
    small_scene()
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    suzanne = bpy.data.objects["Suzanne"]
    assert has_data(suzanne)
    before = scenes.render_exr(tmp_path / "a.exr")
    assert np.isfinite(before).all()
    assert before[..., 3].max() == 1.0 and before[..., :3].max() > 0.05
    blend = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    scenes.reset()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    state = _frame_warnings()
    assert all(o.status == "ok" for o in state.objects), [(o.name, o.status) for o in state.objects]
    after = scenes.render_exr(tmp_path / "b.exr")
    np.testing.assert_array_equal(before, after)


def test_shadows_differ_from_unshadowed(tmp_path):
    """Stored visibility is really used: clearing it brightens the contact region."""
    small_scene()
    bpy.ops.prt.precompute()
    shadowed = scenes.render_exr(tmp_path / "s.exr")
    bpy.ops.prt.clear()
    assert stored() == []
    state = _frame_warnings()
    assert any("Not precomputed" in w for w in state.warnings)
    open_sky = scenes.render_exr(tmp_path / "o.exr")
    assert open_sky[..., :3].mean() > shadowed[..., :3].mean() * 1.02


def test_mesh_edited_after_precompute_is_stale_not_broken(tmp_path):
    small_scene()
    bpy.ops.prt.precompute()
    suzanne = bpy.data.objects["Suzanne"]
    suzanne.data.vertices[0].co.z += 0.3                 # same topology: stale
    suzanne.data.update()
    state = _frame_warnings()
    assert any("stale" in w for w in state.warnings)
    assert np.isfinite(scenes.render_exr(tmp_path / "a.exr")).all()
    ground = bpy.data.objects["Ground"]
    ground.modifiers.new("more", "SUBSURF").levels = 1     # new topology: point count differs
    state = _frame_warnings()
    statuses = {o.name: o.status for o in state.objects}
    assert statuses["Ground"] == "stale"
    img = scenes.render_exr(tmp_path / "b.exr")
    assert np.isfinite(img).all() and img[..., :3].max() > 0


def _assert_precompute_error(match):
    images = stored()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.prt.precompute()
    assert stored() == images
    assert not any(has_data(o) for o in bpy.data.objects)


def test_no_world_is_a_clear_error():
    small_scene()
    bpy.context.scene.world = None
    _assert_precompute_error("no World")


def test_environment_without_image_is_a_clear_error():
    small_scene()
    bpy.context.scene.world.node_tree.nodes["Environment Texture"].image = None
    _assert_precompute_error("has no image")


def test_missing_image_file_is_a_clear_error(tmp_path):
    small_scene()
    env = bpy.context.scene.world.node_tree.nodes["Environment Texture"]
    env.image = bpy.data.images.load(str(scenes.hdri_path("forest")))
    env.image.filepath = str(tmp_path / "gone.exr")
    _assert_precompute_error("missing")


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_environment_pixels_are_a_clear_error(tmp_path, bad):
    small_scene()
    px = np.full((16, 32, 3), 0.5, dtype=np.float32)
    px[3, 7, 1] = bad
    env = bpy.context.scene.world.node_tree.nodes["Environment Texture"]
    env.image = scenes.float_image("bad", px)
    _assert_precompute_error("NaN/Inf")
    # The engine reports the same error for F12 instead of drawing garbage.
    state = _frame_warnings()
    assert state.error and "NaN/Inf" in state.error
    with pytest.raises(RuntimeError, match="NaN/Inf"):
        scenes.render_exr(tmp_path / "x.exr")


def test_zero_area_faces_warn_and_stay_finite(tmp_path):
    small_scene()
    mesh = bpy.data.meshes.new("degenerate")
    verts = [(0, 0, 2.5), (1, 0, 2.5), (2, 0, 2.5), (0, 1, 2.5), (1, 1, 2.5)]
    mesh.from_pydata(verts, [], [(0, 1, 2), (0, 3, 4)])    # first face has zero area
    ob = bpy.data.objects.new("Degenerate", mesh)
    bpy.context.scene.collection.objects.link(ob)
    bpy.ops.prt.precompute()
    state = _frame_warnings()
    assert state.objects and all(o.status == "ok" for o in state.objects)
    img = scenes.render_exr(tmp_path / "a.exr")
    assert np.isfinite(img).all()


def test_empty_mesh_is_skipped_and_only_empty_is_an_error():
    small_scene()
    ob = bpy.data.objects.new("Empty Mesh", bpy.data.meshes.new("nothing"))
    bpy.context.scene.collection.objects.link(ob)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert not has_data(ob)
    scenes.reset()
    scenes.add_world("forest")
    ob = bpy.data.objects.new("Empty Mesh", bpy.data.meshes.new("nothing"))
    bpy.context.scene.collection.objects.link(ob)
    _assert_precompute_error("Nothing to precompute")


def test_cancel_leaves_scene_unchanged():
    """ESC sets ``cancel_requested``; the worker stops and nothing is committed."""
    small_scene()
    job = precompute.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
    job.cancel_requested = True
    with pytest.raises(Cancelled):
        job.run()
    assert stored() == []
    assert not any(has_data(o) for o in bpy.data.objects)


def test_precompute_again_replaces_cached_visibility(tmp_path):
    """Re-precomputing after removing an occluder must not reuse the old decoded bits
    (the ground's own geometry and image name are unchanged)."""
    small_scene()
    bpy.ops.prt.precompute()
    with_occluder = scenes.render_exr(tmp_path / "a.exr")
    bpy.data.objects.remove(bpy.data.objects["Suzanne"])
    state = _frame_warnings()
    assert any("removed or hidden" in w for w in state.warnings)
    bpy.ops.prt.precompute()
    state = _frame_warnings()
    assert not any("changed" in w.lower() for w in state.warnings), state.warnings
    without = scenes.render_exr(tmp_path / "b.exr")
    assert np.isfinite(without).all() and not np.array_equal(with_occluder, without)
    # The ground where Suzanne stood is now lit as open sky: no dark contact shadow left.
    grid = [o for o in state.objects if o.name == "Ground"][0]
    open_bits = runtime.open_visibility(grid.points.normals,
                                        runtime.directions.cubemap(state.resolution))
    np.testing.assert_array_equal(grid.bits, open_bits)


def test_text_objects_and_instances_are_traced_and_drawn(tmp_path):
    """A text object is traced as its own mesh; a collection instance is traced in place
    and stored on its instancer under its persistent id (addon.blender.surfaces)."""
    small_scene()
    bpy.ops.object.text_add(location=(1.5, -1.0, 0.01))
    coll = bpy.data.collections.new("inst")
    bpy.data.objects["Suzanne"].users_collection[0].objects.unlink(bpy.data.objects["Suzanne"])
    coll.objects.link(bpy.data.objects["Suzanne"])
    empty = bpy.data.objects.new("Instancer", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = coll
    bpy.context.scene.collection.objects.link(empty)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert has_data(bpy.data.objects["Text"])
    assert storage.has(storage.owner("Instancer#0"), storage.VISIBILITY)
    state = _frame_warnings()
    assert not any("Suzanne" in w or "Instancer" in w for w in state.warnings), state.warnings
    drawn = {st.name: st for st in state.objects}
    assert drawn["Instancer#0"].status == "ok" and "Suzanne" not in drawn
    assert np.isfinite(scenes.render_exr(tmp_path / "a.exr")).all()


def _scene(subdiv=0, cuts=8):
    scenes.reset()
    scenes.add_world("sunset")
    scenes.add_ground(size=6.0, cuts=cuts)
    scenes.add_suzanne(subdiv=subdiv, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 24)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.prt.resolution = "32"
    return scene


def test_precompute_streams_the_visibility_and_keeps_it_only_for_a_derive():
    """The trace's chunks go straight into each object's blob (the blob pack makes of the
    whole array); the bits are kept only for a method that derives from them, else read
    back from the blob."""
    from prt_relight.core.sphere import directions
    from prt_relight.core.scene import visibility
    scene = _scene()
    scene.prt.method = "REFERENCE"
    job = precompute.gather(bpy.context.evaluated_depsgraph_get(), scene.prt)
    job.run(threads=4)
    assert all(o.kept is None and o.blob for o in job.objects)
    pts = np.concatenate([o.points.positions for o in job.objects])
    nrm = np.concatenate([o.points.normals for o in job.objects])
    occluders = visibility.build_occluder_scene(job.occluders)
    origins, _ = tracing.trace_origins(job.objects, occluders, job.offset)
    whole = visibility.trace_visibility(occluders, pts, nrm, directions.cubemap(job.resolution),
                                        job.offset, origins=origins)
    start = 0
    for o in job.objects:
        rows = whole[start:start + o.points.count]
        start += o.points.count
        np.testing.assert_array_equal(o.bits, rows)
        assert o.blob == layouts.visibility_blob(rows, job.resolution)
    assert "rays" in job.timings and job.stage == "writing"
    scene.prt.method = "BLOCKS"
    kept = precompute.gather(bpy.context.evaluated_depsgraph_get(), scene.prt)
    kept.run()
    for o, p in zip(kept.objects, job.objects):
        assert o.kept is not None and o.blob == p.blob
        np.testing.assert_array_equal(o.bits, p.bits)
