"""REFERENCE in headless Blender (addon/methods/reference/shading.py): an F12 frame sums the
diffuse light of the points its camera may see only."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from prt_relight.bench import scenes  # noqa: E402


def test_f12_sums_the_seen_points_as_every_point_and_leaves_the_others(registered_addon):
    """A diffuse Suzanne on a ground the camera sees part of: with the frame's camera the
    seen points' radiance is what the sums over every point give (the same dense sum on
    fewer rows) and the unseen points, which no pixel draws, are left at 0."""
    from prt_relight.addon.frame.engine import frame_camera, render_view
    from prt_relight.addon.frame.state import FrameState
    scenes.reset()
    scenes.add_world("forest")
    for ob in (scenes.add_ground(size=8.0, cuts=24), scenes.add_suzanne(subdiv=1)):
        ob.data.materials.append(scenes.bsdf_material(f"{ob.name} diffuse",
                                                      "ShaderNodeBsdfDiffuse"))
    scenes.add_camera(resolution=(32, 32), distance=4.0)
    scene = bpy.context.scene
    scene.prt.method = "REFERENCE"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = FrameState()
    state.sync(depsgraph)
    view, projection, width, height, persp = render_view(scene, depsgraph)
    assert persp
    eye = np.linalg.inv(np.array(view, dtype=np.float64))[:3, 3]      # the camera's place
    every = state.shade(eye)
    state.camera = frame_camera(view, projection, width, height, eye, None)
    state.visible_only = True
    seen_only = state.shade(eye)
    unseen = 0
    for st, a, b in zip(state.objects, every, seen_only):
        seen = state.seen_points(st)[st.points.point_of_corner]
        unseen += int((~seen).sum())
        assert np.abs(a[seen]).max() > 0.0
        np.testing.assert_allclose(b[seen], a[seen], rtol=1e-5, atol=1e-6 * np.abs(a).max())
        assert not np.asarray(b)[~seen].any()
    assert unseen > 0, "the camera should leave part of the ground out"


def test_the_seen_points_are_found_once_per_object_and_camera(registered_addon, monkeypatch):
    """A frame's passes (each part, the base-colour twins, the diffuse and glossy sums) read
    one set of seen points per object and camera; a new camera finds them again."""
    from prt_relight.addon.frame import state as frame_state
    from prt_relight.addon.frame.engine import frame_camera, render_view
    scenes.reset()
    scenes.add_world("forest")
    scenes.add_ground(size=8.0, cuts=8)
    scenes.add_camera(resolution=(16, 16), distance=4.0)
    scene = bpy.context.scene
    scene.prt.method = "REFERENCE"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = frame_state.FrameState()
    state.sync(depsgraph)
    view, projection, width, height, _persp = render_view(scene, depsgraph)
    eye = np.linalg.inv(np.array(view, dtype=np.float64))[:3, 3]
    calls = []
    real = frame_state.core_mesh.seen_points
    monkeypatch.setattr(frame_state.core_mesh, "seen_points",
                        lambda *a, **k: calls.append(real(*a, **k)) or calls[-1])
    state.visible_only = True
    st = state.objects[0]
    for _camera in range(2):
        state.camera = frame_camera(view, projection, width, height, eye, None)
        first = state.seen_points(st)
        twin = frame_state.copy.copy(st)               # a base-colour twin shares its points
        assert state._part([0]).seen_points(twin) is first
        assert not first.flags.writeable
    assert len(calls) == 2 and first is calls[-1]     # the one set found for this camera
