"""SH in headless Blender (addon/methods/sh/shading.py): a smooth world is (nearly) inside the
SH span, so order 4 renders near REFERENCE; a sharp HDRI shows SH's low-frequency error."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


pytestmark = pytest.mark.usefixtures("registered_addon")


def test_sh_method_renders_near_reference_for_low_frequency_light(tmp_path):
    """A smooth world is (nearly) inside the SH span: SH order 4 ~ REFERENCE; a sharp
    HDRI shows SH's low-frequency error, shrinking with the order."""
    scenes.reset()
    h, w = 32, 64
    th = (np.arange(h) + 0.5) / h * np.pi
    ph = (0.5 - (np.arange(w) + 0.5) / w) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    z, x = np.cos(T), np.sin(T) * np.cos(P)
    smooth = (1.2 + 0.6 * z + 0.3 * x)[..., None] * np.array([1.0, 0.9, 0.7])
    scenes.add_world(image=scenes.float_image("smooth", smooth.astype(np.float32)))
    scenes.add_ground(size=6.0, cuts=16)
    scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.append(scenes.bsdf_material("diffuse", "ShaderNodeBsdfDiffuse"))
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    ref = scenes.render_exr(tmp_path / "ref.exr")
    assert ref[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    scene.prt.method = "SH"
    scene.prt.sh_order = 4
    ours = scenes.render_exr(tmp_path / "sh.exr")
    assert np.isfinite(ours).all()
    assert rel_l2(ours, ref) < 0.01

    env = scene.world.node_tree.nodes["Environment Texture"]
    env.image = bpy.data.images.load(str(scenes.hdri_path("sunset")))
    scene.prt.method = "REFERENCE"
    ref = scenes.render_exr(tmp_path / "ref2.exr")
    assert ref[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    errors = []
    for order in (2, 5):
        scene.prt.method = "SH"
        scene.prt.sh_order = order
        errors.append(rel_l2(scenes.render_exr(tmp_path / f"sh{order}.exr"), ref))
    assert errors[1] < errors[0]
    assert errors[1] > 0.01              # the sun's sharp shadows are beyond order 5
