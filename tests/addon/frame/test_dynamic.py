"""Dynamic objects (shadow fields, addon/frame/dynamic.py): an object marked dynamic moves,
turns and scales after its precompute and every method draws the shadows of its new pose
(as a precompute at that pose would); beyond its outermost shell it casts nothing; two
dynamic objects shadow each other; AUTO keeps its choice while one moves; RSL's multiple
product follows it."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
from prt_relight.addon.blender import storage
from prt_relight.bench import scenes


pytestmark = pytest.mark.usefixtures("registered_addon")

EYE = np.array([0.0, -6.0, 3.0])


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


def _shade(method="REFERENCE"):
    bpy.context.scene.prt.method = method
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    out = state.shade(EYE)
    return state, {st.name: r for st, r in zip(state.objects, out)}


def _rel(a, b):
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-30))


def _move(ob, location, rotation, scale=1.0):
    ob.location = location
    ob.rotation_euler = rotation
    ob.scale = (scale, scale, scale) if np.isscalar(scale) else scale
    bpy.context.view_layer.update()


def _exact_at_current_pose(cube):
    """The same frame after a full precompute with the cube static where it is now."""
    cube.prt.dynamic = False
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _, exact = _shade()
    cube.prt.dynamic = True
    return exact


def test_moved_and_turned_object_shades_as_a_precompute_at_its_new_pose():
    """The cube's shadow on the ground and the ground's occlusion of the cube follow a
    move and a turn with no new precompute (REFERENCE, per-corner radiance), where the
    data of the old pose are far off."""
    scene, cube = _scene()
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert storage.has(cube, storage.SHADOW_FIELD)
    _move(cube, (0.9, 0.4, 0.75), (0.3, 0.2, 1.3))
    state, moved = _shade()
    assert {st.name: st.status for st in state.objects} == {"Cube": "posed", "Ground": "posed"}
    assert not any("stale" in w for w in state.warnings), state.warnings
    exact = _exact_at_current_pose(cube)
    ground, box = _rel(moved["Ground"], exact["Ground"]), _rel(moved["Cube"], exact["Cube"])
    assert ground < 0.045 and box < 0.02, (ground, box)
    # the precompute of the old pose, drawn at the new one (what a static object shows)
    _move(cube, (0.0, 0.0, 0.9), (0.0, 0.0, 0.0))
    cube.prt.dynamic = False
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _, old = _shade()
    assert _rel(old["Ground"], exact["Ground"]) > 4 * ground


def test_uniform_scale_is_followed_and_non_uniform_scale_is_stale():
    """Uniform scale is a motion the field follows; a squashed object is reported stale."""
    scene, cube = _scene(detail="LOW")
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(cube, (0.3, -0.2, 1.1), (0.0, 0.0, 0.4), scale=1.4)
    state, _ = _shade()
    assert [st.status for st in state.objects] == ["posed", "posed"], state.warnings
    _move(cube, (0.3, -0.2, 1.1), (0.0, 0.0, 0.4), scale=(1.0, 1.0, 0.5))
    state, _ = _shade()
    cube_state = next(st for st in state.objects if st.name == "Cube")
    assert cube_state.status == "stale"
    assert any("non-uniformly" in w for w in state.warnings), state.warnings


def test_an_object_beyond_its_outermost_shell_casts_nothing():
    """Beyond the field's outermost shell the ground keeps exactly its stored
    visibility (status ok: the stored data of every method apply)."""
    scene, cube = _scene(detail="LOW")
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(cube, (0.0, 0.0, 40.0), (0.0, 0.0, 0.0))
    state, _ = _shade()
    ground = next(st for st in state.objects if st.name == "Ground")
    assert ground.status == "ok"
    stored = runtime.stored_visibility(bpy.data.objects["Ground"], ground.points.count,
                                       ground.bits.shape[1])
    np.testing.assert_array_equal(ground.bits, stored())


def test_two_dynamic_objects_shadow_each_other():
    """A dynamic plate above a dynamic cube: the cube's top is shaded by the plate's
    field at their current poses, as a full precompute there."""
    scene, cube = _scene(detail="MEDIUM")
    bpy.ops.mesh.primitive_cylinder_add(radius=0.8, depth=0.1, location=(2.0, 2.0, 2.0))
    plate = bpy.context.object
    plate.prt.dynamic = True
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(plate, (0.2, 0.1, 1.9), (0.2, 0.0, 0.0))
    _move(cube, (0.1, 0.0, 0.8), (0.0, 0.0, 0.5))
    _, moved = _shade()
    plate.prt.dynamic = False
    exact = _exact_at_current_pose(cube)
    err = _rel(moved["Cube"], exact["Cube"])
    assert err < 0.03, err
    plate.prt.dynamic = cube.prt.dynamic = False
    _move(plate, (2.0, 2.0, 2.0), (0.0, 0.0, 0.0))
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(plate, (0.2, 0.1, 1.9), (0.2, 0.0, 0.0))
    _, unshadowed = _shade()       # the cube traced without the plate over it
    assert _rel(unshadowed["Cube"], exact["Cube"]) > 3 * err


@pytest.mark.parametrize("method", ["SH", "WAVELET", "BLOCKS", "RSL", "SSDF_SG", "AUTO"])
def test_every_method_draws_the_moved_shadow(method):
    """Every method shades the posed visibility: the ground under the cube's new place is
    darker than where it stood at the precompute, and every value is finite."""
    scene, cube = _scene(detail="LOW")
    scene.prt.method = method
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(cube, (1.2, 0.0, 0.7), (0.0, 0.0, 0.0))
    state, out = _shade(method)
    ground = next(st for st in state.objects if st.name == "Ground")
    rad = out["Ground"].mean(axis=1)
    corner = ground.arrays.positions[ground.arrays.corner_verts]
    near_new = np.linalg.norm(corner[:, :2] - (1.2, 0.0), axis=1) < 0.3
    near_old = np.linalg.norm(corner[:, :2], axis=1) < 0.3
    assert np.isfinite(out["Ground"]).all() and np.isfinite(out["Cube"]).all()
    assert rad[near_new].mean() < 0.8 * rad[near_old].mean(), method


def test_marking_or_unmarking_dynamic_after_the_precompute_is_stale():
    scene, cube = _scene(detail="LOW")
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    cube.prt.dynamic = False
    state, _ = _shade()
    assert any("unmarked dynamic" in w for w in state.warnings), state.warnings
    assert bpy.ops.prt.clear() == {"FINISHED"}
    assert not storage.has(cube, storage.SHADOW_FIELD)


def test_a_dynamic_object_scaled_to_0_is_refused_by_name():
    """Scene fuzzer seeds 31 and 35: a dynamic object flattened (scale 0 on an axis)
    crashed the precompute inverting its matrix; it is refused with a message that names
    it, nothing stored, and the same object static is traced."""
    scene, cube = _scene(detail="LOW")
    cube.scale = (1.0, 0.0, 1.0)
    with pytest.raises(RuntimeError, match="'Cube' is marked Dynamic but scaled to 0"):
        bpy.ops.prt.precompute()
    assert not storage.has(cube, storage.VISIBILITY) and scene.prt.precompute_id == ""
    cube.prt.dynamic = False
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert storage.has(cube, storage.VISIBILITY)


def test_auto_stored_choice_holds_while_a_dynamic_object_moves():
    """AUTO's stored choice keys on a dynamic object's shape, not its pose: an animation
    is not re-chosen live at every frame."""
    scene, cube = _scene(detail="LOW")
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scene.prt.method = "AUTO"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert scene.prt.auto_choice
    _move(cube, (0.8, 0.3, 0.8), (0.0, 0.0, 0.7))
    state, out = _shade("AUTO")
    assert any("stored choice" in w for w in state.warnings), state.warnings
    assert not any("out of date" in w for w in state.warnings), state.warnings
    assert all(np.isfinite(r).all() for r in out.values())
    cube.scale = (1.0, 1.0, 0.5)        # non-uniform: stale, and the geometry changed
    bpy.context.view_layer.update()
    state, _ = _shade("AUTO")
    assert any("out of date" in w for w in state.warnings), state.warnings


def test_rsl_multi_product_matches_rsl_precomputed_at_the_new_pose():
    """RSL precomputed with a dynamic cube shades the moved scene by Fig. 8's product
    (stored VDTs times the occluder field at each light, no posed bits made) close to RSL
    precomputed from scratch at the new pose; the old pose's data are far off."""
    scene, cube = _scene(detail="MEDIUM")
    scene.prt.method = "RSL"
    scene.prt.rsl_gpu = False
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(cube, (0.9, 0.4, 0.75), (0.3, 0.2, 1.3))
    state, moved = _shade("RSL")
    ground = next(st for st in state.objects if st.name == "Ground")
    assert ground.status == "posed" and ground._pose is not None     # bits never made
    cube.prt.dynamic = False
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _, exact = _shade("RSL")
    err = {n: _rel(moved[n], exact[n]) for n in exact}
    assert err["Ground"] < 0.05 and err["Cube"] < 0.05, err
    _move(cube, (0.0, 0.0, 0.9), (0.0, 0.0, 0.0))
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _move(cube, (0.9, 0.4, 0.75), (0.3, 0.2, 1.3))
    _, stale = _shade("RSL")
    assert _rel(stale["Ground"], exact["Ground"]) > 3 * err["Ground"]


def test_with_bounces_a_dynamic_object_neither_sends_nor_receives_bounced_light():
    """The bounce transfer is the static scene's (addon/frame/bounce.py): with the Light
    Paths' bounces on, the dynamic cube is no receiver and no reflector -- its frame and
    the flat ground's (which only the cube could light) are their direct frames, moved
    or not."""
    scene, cube = _scene()
    scenes.light_paths(4)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    for pose in (((0.0, 0.0, 0.9), (0.0, 0.0, 0.0)), ((0.4, -0.3, 1.1), (0.3, 0.2, 0.5))):
        _move(cube, *pose)
        state, bounced = _shade()
        assert state.bounce is not None
        assert [state.objects[i].name for i, _ in state.bounce.receivers] == ["Ground"]
        scenes.light_paths(0)
        _, direct = _shade()
        scenes.light_paths(4)
        for name in ("Cube", "Ground"):
            np.testing.assert_allclose(bounced[name], direct[name], rtol=1e-5, atol=1e-7)
