"""Every panel's draw() runs for every method and material model, and each property or
operator it shows exists (the UI draws are not exercised by the headless renders)."""

from __future__ import annotations

import types

import bpy
import pytest

from prt_relight.addon import methods
from prt_relight.addon.ui import panels, sg_material
from prt_relight.bench import scenes

from .fakes import FakeContext, FakeLayout


pytestmark = pytest.mark.usefixtures("registered_addon")


def test_settings_panel_draws_for_every_method():
    scenes.reset()
    scenes.add_suzanne(subdiv=0, location=(0.0, 0.0, 1.0))
    scene = bpy.context.scene
    for method_id in methods.REGISTRY:
        scene.prt.method = method_id
        log = []
        panels.draw_settings(FakeLayout(log), FakeContext(scene))
        shown = {name for kind, name in log if kind == "prop"}
        assert "method" in shown
        budget = methods.REGISTRY[method_id].bench.budget
        if budget:
            assert budget[0] in shown, (method_id, shown)
        assert ("operator", "prt.precompute") in log


@pytest.mark.parametrize("model", [m for m, *_ in sg_material.MODEL_ITEMS])
def test_material_panel_draws_every_model(model):
    scenes.reset()
    mat = bpy.data.materials.new("panel")
    mat.prt_sg.use_blender_material = False
    mat.prt_sg.model = model
    log = []
    panel = types.SimpleNamespace(layout=FakeLayout(log))       # stands in for the Panel
    sg_material.PRT_PT_sg_material.draw(panel, FakeContext(bpy.context.scene, mat))
    assert ("prop", "model") in log and len(log) >= 5


def test_settings_panel_lists_the_compact_sources_it_draws():
    import numpy as np

    from prt_relight.addon.frame import state as runtime
    scenes.reset()
    img = np.full((64, 128, 3), 0.05, np.float32)
    img[10, 30] = 2e4
    scenes.add_world(image=scenes.float_image("sun", img))
    scenes.add_suzanne(subdiv=0, location=(0.0, 0.0, 1.0))
    scene = bpy.context.scene
    runtime.FrameState().sync(bpy.context.evaluated_depsgraph_get())
    log = []
    panels.draw_settings(FakeLayout(log), FakeContext(scene))
    shown = {name for kind, name in log if kind == "prop"}
    assert {"light_sources", "light_threshold", "light_min_share"} <= shown
    lines = [text for kind, text in log if kind == "label" and text.startswith("Source 1:")]
    assert len(lines) == 1 and "elevation 60°" in lines[0], lines
