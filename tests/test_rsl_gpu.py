"""RSL in Blender: the GLSL per-vertex pass equals the numpy evaluator; the method
renders through F12 and follows a world rotation without recompute."""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.methods.rsl import shading as rsl
from prt_relight.core.scene import distance_tables
from prt_relight.core.methods.rsl import square_lights  # noqa: E402

from .core.methods.rsl.scenes import occluded_grid as _scene, sky_with_sun as _sky_with_sun  # noqa: E402

CUBE = directions.cubemap(32)


def _gpu_context():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 8, 8
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()                    # gives the gpu module a context in -b


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["VDT", "SAT"])
def test_glsl_pass_equals_numpy(registered_addon, kind):
    from prt_relight.addon.methods.rsl import shading as method
    _gpu_context()
    pos, nrm, bits = _scene(8)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    table = distance_tables.visibility_distance_table(maps) if kind == "VDT" else distance_tables.visibility_sat(maps)
    table = table.astype(method.held_dtype(kind))      # as drawn: a VDT in half floats
    lighting = envmap.WorldLighting(image=_sky_with_sun()).to_cubemap(32)
    R = envmap.euler_xyz_matrix(0.1, 0.2, 0.7)
    ev = rsl.Evaluator(square_lights.decompose(lighting, CUBE, 40), R)
    eye = np.array([2.0, -3.0, 2.0])
    views = eye[None, :] - pos
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    from prt_relight.addon.frame.engine import in_render
    sel = np.arange(1, len(nrm), 2)                      # a subset: tables by index
    mats = (materials.Material(), materials.principled_material(metallic=0.3, roughness=0.4),
            materials.Material(specular_color=(0.9, 0.5, 0.2), roughness=0.3,
                          distribution="BECKMANN", fresnel="SCHLICK"))

    def passes(_depsgraph):
        """The GLSL pass of every material, inside a render (the gpu module's context in
        -b: drawing outside one may corrupt it for later passes)."""
        # textures of 7 points each: several batches, a table's texels cross rows
        batches = method.vis_textures(table, batch=7)
        assert len(batches) == -(-len(nrm) // 7)
        out = []
        for mat in mats:
            got = np.zeros((len(sel), 3))
            for a, e, tex in batches:
                part = np.nonzero((sel >= a) & (sel < e))[0]
                i = sel[part]
                got[part] = method.gpu_shade(ev.centres, ev.half[0], ev.energy,
                                             rsl.brdf_tables(mat), nrm[i], views[i],
                                             rsl.point_weights(mat, nrm[i], views[i]),
                                             kind, tex, 32, i - a)
            out.append(got)
        return out

    for mat, got in zip(mats, in_render(bpy.context.scene, passes)):
        tables = rsl.brdf_tables(mat)
        V, C = ev.diffuse_factors(nrm, kind, table, tables)
        want = ev.shade(mat, tables, nrm, views, V, C)
        assert np.isfinite(got).all()
        # float32 textures and arithmetic against float64: SAT differences keep ~1e-4
        np.testing.assert_allclose(got, want[sel], rtol=1e-3, atol=1e-4 * np.abs(want).max())


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
