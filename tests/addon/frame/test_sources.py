"""addon.frame.sources: the compact sources split off the World follow its rotation (Mapping
node) without a recompute, as the sources of a rotated image would."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
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
