"""addon.frame.sources: the compact sources split off the World follow its rotation (Mapping
node) without a recompute, as the sources of a rotated image would; the shadow maps' plan
(every lamp's cube faces, the atlases' tiles within their budget, what the messages say)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import sources, state as runtime
from prt_relight.core.sg.lamp_lobes import Lamp
from prt_relight.bench import scenes


pytestmark = pytest.mark.usefixtures("registered_addon")


def test_turning_the_world_moves_its_sources_without_recompute():
    scenes.reset()
    h, w = 64, 128
    img = np.full((h, w, 3), 0.05, np.float32)
    img[20, 40] = 2e4
    scenes.add_world(image=scenes.float_image("sun", img), rotation_z=0.0)
    coord = bpy.context.scene.world.node_tree.nodes.new("ShaderNodeTexCoord")
    mapping = bpy.context.scene.world.node_tree.nodes.new("ShaderNodeMapping")
    nt = bpy.context.scene.world.node_tree
    nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], nt.nodes["Environment Texture"].inputs["Vector"])
    scenes.add_ground(size=4.0, cuts=4)
    bpy.ops.prt.precompute()

    def source_direction():
        state = runtime.FrameState()
        state.sync(bpy.context.evaluated_depsgraph_get())
        assert len(state.sources) == 1
        return state.sources[0].direction, state

    d0, s0 = source_direction()
    mapping.inputs["Rotation"].default_value[2] = 0.7
    d1, s1 = source_direction()
    # the world reads R @ d: a texture-space source appears turned by R^T
    c, s = math.cos(0.7), math.sin(0.7)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(d1, Rz.T @ d0, atol=1e-9)
    assert s1.world.image is s0.world.image              # the same residual, not re-split


# --------------------------------------------------------------------------- shadow plan


def _face_of(v):
    """The cube face lights_frag.glsl reads for direction v (the largest component)."""
    a = np.abs(v)
    k = int(np.argmax(a))
    return 2 * k + (0 if v[k] >= 0 else 1)


def test_a_lamp_draws_the_cube_faces_its_light_can_pass_through():
    """A spot straight down needs the -Z face alone, an area lamp facing down every face
    but +Z, a point lamp all six; for random spots every direction in the cone falls on
    a face the plan draws."""
    down = sources.lamp_sources([Lamp("SPOT", position=(0, 0, 3), spot_size=math.radians(60)),
                                 Lamp("AREA", position=(0, 0, 3), half_x=(0.5, 0, 0),
                                      half_y=(0, 0.5, 0)),
                                 Lamp("POINT", position=(0, 0, 3))])
    assert [sum(sources.lamp_faces(s)) for s in down] == [1, 5, 6]
    assert sources.lamp_faces(down[0])[5] and not sources.lamp_faces(down[1])[4]
    rng = np.random.default_rng(3)
    for _ in range(200):
        axis = rng.normal(size=3)
        size = rng.uniform(0.05, math.pi)
        spot = sources.lamp_sources([Lamp("SPOT", direction=axis, spot_size=size)])[0]
        faces = sources.lamp_faces(spot)
        v = rng.normal(size=(400, 3))
        v /= np.linalg.norm(v, axis=1)[:, None]
        inside = v[v @ spot.spot[0] > math.cos(0.5 * size)]
        assert all(faces[_face_of(d)] for d in inside)


def test_the_shadow_plan_keeps_full_tiles_for_few_lamps_and_says_what_many_change():
    few = sources.lamp_sources([Lamp("SPOT", position=(0, 0, 3)), Lamp("POINT"),
                                Lamp("AREA", half_x=(0.5, 0, 0), half_y=(0, 0.5, 0)),
                                Lamp("SUN")])
    plan = sources.shadow_plan(few)
    assert (plan.face_tile, plan.distant_tile, plan.distant_shadowed) == \
        (sources.CUBE_TILE, sources.SHADOW_TILE, 1)
    assert plan.messages == [] and [sum(f) for f in plan.faces] == [1, 6, 5]
    # 64 spots straight down: 64 faces, past 48 at full size -> every face at 512²
    spots = sources.lamp_sources([Lamp("SPOT", position=(x, 0, 3), name=f"S{x}")
                                  for x in range(64)])
    plan = sources.shadow_plan(spots)
    assert plan.face_tile == 512 and all(sum(f) == 1 for f in plan.faces)
    assert plan.messages == ["Shadow maps: 64 local lamps draw 64 cube faces at 512² texels "
                             "each (1024² up to 48 faces)"]
    # 600 point lamps: the least tile holds 512 of them; the rest are named, unshadowed
    points = sources.lamp_sources([Lamp("POINT", position=(x, 0, 3), name=f"P{x}")
                                   for x in range(600)])
    plan = sources.shadow_plan(points)
    assert plan.face_tile == sources.CUBE_TILE_MIN
    assert sum(any(f) for f in plan.faces) == 512 and not any(plan.faces[-1])
    assert "88 local lamps past the atlas's budget cast no shadow: point lamp 'P512'" \
        in plan.messages[1] and "and 80 more" in plan.messages[1]
    # twelve suns and compact sources: tiles of 1024² (up to 32 in the budget)
    suns = sources.lamp_sources([Lamp("SUN", direction=(0.1 * k, 0, -1)) for k in range(12)])
    plan = sources.shadow_plan(suns)
    assert (plan.distant_tile, plan.distant_shadowed) == (1024, 12)
    assert len(plan.messages) == 1 and "12 distant sources" in plan.messages[0]


def test_atlas_grid_stays_within_the_atlas_side():
    for count, size in ((1, 1024), (48, 1024), (64, 512), (3072, 128), (7, 2048)):
        cols, rows = sources.atlas_grid(count, size)
        assert cols * rows >= count and max(cols, rows) * size <= sources.ATLAS_SIDE
