"""RSL in headless Blender (addon/methods/rsl/shading.py): the method renders and follows the
world's rotation, and turning an object turns its self-shadowing without a recompute."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ....core.methods.rsl.scenes import sky_with_sun as _sky_with_sun


bpy = pytest.importorskip("bpy")


@pytest.mark.slow
def test_method_renders_and_follows_world_rotation(registered_addon):
    from prt_relight.addon.frame.state import FrameState
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=4)
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5))
    world = bpy.data.worlds.new("W")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    img = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    px = _sky_with_sun(32, 64, sun=(8, 20), sun_value=2000.0)
    rgba = np.concatenate([px[::-1], np.ones((32, 64, 1), np.float32)], axis=2)
    img.pixels.foreach_set(rgba.reshape(-1))
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    mapping = nt.nodes.new("ShaderNodeMapping")
    coord = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    cam.location = (5, -5, 4)
    cam.rotation_euler = (math.radians(60), 0, math.radians(45))
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.prt.method = "RSL"
    scene.prt.rsl_lights = 30
    # RSL shades the whole world here: the sun is not split off as a compact source drawn
    # per pixel (addon/gpu/lights.py), so turning the world turns RSL's own lights
    scene.prt.light_sources = 0
    bpy.ops.prt.precompute()
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    scene.render.engine = "PRT_RELIGHT"
    bpy.ops.render.render()

    def shaded():
        state = FrameState()
        state.sync(bpy.context.evaluated_depsgraph_get())
        return np.concatenate(state.shade(np.array(cam.location)))

    a = shaded()
    # the precompute stored the CPCA-compressed VDT; sync reconstructs it
    from prt_relight.addon.methods.rsl import shading as method
    state = FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    for st in state.objects:
        stored = st.data["rsl"]
        derived = method.derive_visibility(st.bits, st.points.normals, 32)
        assert stored.shape == derived.shape
        assert stored.dtype == np.float16                  # held in half floats
        err = np.linalg.norm(stored.astype(np.float64) - derived) / np.linalg.norm(derived)
        assert err <= scene.prt.rsl_cpca_error * 1.001 + 1e-3   # + half-float rounding
    scene.prt.method = "REFERENCE"
    ref = shaded()
    scene.prt.method = "RSL"
    assert np.isfinite(a).all()
    assert np.linalg.norm(a - ref) / np.linalg.norm(ref) < 0.1
    decompositions = len(method.LIGHTS)
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, 1.3)
    b = shaded()
    assert len(method.LIGHTS) == decompositions      # no new decomposition
    scene.prt.method = "REFERENCE"
    ref_b = shaded()
    assert np.linalg.norm(b - a) / np.linalg.norm(a) > 0.05
    assert np.linalg.norm(b - ref_b) / np.linalg.norm(ref_b) < 0.1


@pytest.mark.slow
def test_turning_an_object_turns_its_self_shadowing_without_recompute(registered_addon):
    """The VDTs live in vertex frames: after a rigid turn (and move) of the object the
    stored data, read in the object's precompute orientation with the points matched
    to their stored rows, shades like a fresh precompute."""
    from prt_relight.addon.frame.state import FrameState
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.cycles.max_bounces = 0          # direct light: the stale turn draws no bounce
    bpy.ops.mesh.primitive_monkey_add()
    monkey = bpy.context.active_object                  # flat shaded: split normals
    world = bpy.data.worlds.new("W")
    scene.world = world
    nt = world.node_tree
    img = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    px = _sky_with_sun(32, 64, sun=(6, 20), sun_value=800.0)
    rgba = np.concatenate([px[::-1], np.ones((32, 64, 1), np.float32)], axis=2)
    img.pixels.foreach_set(rgba.reshape(-1))
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    scene.prt.method = "RSL"
    scene.prt.rsl_lights = 60
    scene.prt.rsl_gpu = False
    bpy.ops.prt.precompute()
    eye = np.array([0.0, -6.0, 1.0])

    def shaded():
        state = FrameState()
        state.sync(bpy.context.evaluated_depsgraph_get())
        return np.concatenate(state.shade(eye)), state

    before, _ = shaded()
    monkey.rotation_euler = (0.5, 0.2, 1.1)
    monkey.location = (0.3, 0.0, 0.2)
    bpy.context.view_layer.update()
    turned, state = shaded()
    assert state.objects[0].status == "stale" and "rsl_rotation" in state.objects[0].data
    bpy.ops.prt.precompute()
    fresh, state = shaded()
    assert "rsl_rotation" not in state.objects[0].data
    change = np.linalg.norm(fresh - before) / np.linalg.norm(fresh)
    diff = np.linalg.norm(turned - fresh) / np.linalg.norm(fresh)
    # what is left is the resampling of the traced cubemap bits into the vertex frames
    assert change > 0.15 and diff < 0.05 and diff < 0.25 * change, (change, diff)
