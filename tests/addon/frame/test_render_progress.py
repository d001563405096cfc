"""F12 reports progress and stops on ESC (issue 20 item 4): the engine's render() run
headless with a stand-in for the RenderEngine Blender passes (its ``test_break`` turns
true after N calls, as ESC would), for REFERENCE (ticks between blocks of points), a
per-object method and AUTO's live choice (ticks between measured candidates)."""

from __future__ import annotations

import types

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame.engine import PRTRenderEngine
from prt_relight.addon.methods.auto import shading as auto
from prt_relight.addon.methods.auto import measure as auto_measure
from prt_relight.addon.methods.auto import measure
from prt_relight.bench import scenes

from ... import viewport


pytestmark = pytest.mark.usefixtures("registered_addon")


class FakeRenderEngine:
    """What render() uses of a RenderEngine: progress, ESC, reports and the result."""

    def __init__(self, break_after=None):
        self.progress = []
        self.breaks = 0
        self.break_after = break_after
        self.reports = []
        self.stats = []
        self.pixels = None
        self.size = None

    def update_progress(self, fraction):
        self.progress.append(fraction)

    def test_break(self):
        self.breaks += 1
        return self.break_after is not None and self.breaks >= self.break_after

    def report(self, kind, message):
        self.reports.append((set(kind), message))

    def update_stats(self, stats, info):
        self.stats.append(info)

    def begin_result(self, x, y, width, height, layer=""):
        self.size = (width, height)
        rect = types.SimpleNamespace(foreach_set=lambda data: setattr(
            self, "pixels", np.array(data, dtype=np.float32)))
        passes = {"Combined": types.SimpleNamespace(rect=rect)}
        return types.SimpleNamespace(layers=[types.SimpleNamespace(passes=passes)])

    def end_result(self, result):
        pass


def _scene(method):
    """Glossy Suzanne (subdivided once: several blocks of points) on a grid, precomputed."""
    from prt_relight.addon.gpu.drawing import ensure_gpu
    scenes.reset()
    scenes.add_world("city")
    scenes.add_ground(size=6.0, cuts=16)
    ob = scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    glossy = scenes.bsdf_material("Glossy", "ShaderNodeBsdfGlossy", Roughness=0.3)
    ob.data.materials.append(glossy)
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(48, 36)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.prt.method = "REFERENCE"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    scene.prt.method = method
    ensure_gpu(scene)                 # the gpu module's context for the drawing (in -b)
    return scene


def _render(engine):
    PRTRenderEngine.render(engine, bpy.context.evaluated_depsgraph_get())
    return engine


def test_f12_reports_progress_monotonically_to_the_end():
    _scene("REFERENCE")
    engine = _render(FakeRenderEngine())
    p = engine.progress
    assert p and all(0.0 < a < b <= 1.0 for a, b in zip(p, p[1:])), p
    assert p[-1] == 1.0
    # REFERENCE ticks per block of points: many steps inside the shading
    assert len([f for f in p if 0.1 < f < 0.95]) >= 5, p
    assert engine.size == (48, 36)
    assert engine.pixels is not None and engine.pixels.size == 48 * 36 * 4
    assert np.isfinite(engine.pixels).all()
    assert engine.breaks > len(p) // 2             # ESC was looked at as often


@pytest.mark.parametrize("method", ["REFERENCE", "SH"])
def test_esc_stops_f12_at_once_and_draws_nothing(method):
    _scene(method)
    full = _render(FakeRenderEngine()).breaks
    assert full > 6
    engine = _render(FakeRenderEngine(break_after=4))
    assert engine.breaks == 4                      # nothing ran after the ESC was seen
    assert engine.pixels is None and engine.size is None
    assert any("stopped" in m for _, m in engine.reports), engine.reports
    assert engine.progress and engine.progress[-1] < 1.0
    assert all(a < b for a, b in zip(engine.progress, engine.progress[1:]))


def test_esc_stops_auto_live_choice_and_keeps_nothing(monkeypatch):
    """AUTO without a stored choice chooses live inside F12: ESC between its measured
    candidates stops the frame; nothing is stored or kept half-measured."""
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in ("SH", "WAVELET")])
    scene = _scene("AUTO")
    assert scene.prt.auto_choice == ""
    auto.CHOICE_CACHE.clear()
    before = measure.SELECTIONS[0]
    engine = _render(FakeRenderEngine(break_after=6))
    assert engine.breaks == 6 and engine.pixels is None
    assert measure.SELECTIONS[0] > before             # it had started measuring
    assert not auto.CHOICE_CACHE                  # an object half-measured is not kept
    assert scene.prt.auto_choice == ""
    # the same frame without ESC chooses live, reports progress to the end and draws
    engine = _render(FakeRenderEngine())
    assert engine.pixels is not None and engine.progress[-1] == 1.0
    assert all(a < b for a, b in zip(engine.progress, engine.progress[1:]))
    assert len(auto.CHOICE_CACHE) == 2


def test_viewport_measures_auto_off_the_main_thread(monkeypatch):
    """The viewport with AUTO and no stored choice: the first draw returns at once (the
    geometry unlit) while a worker measures; the next draw after it shows the frame."""
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in ("SH", "WAVELET")])
    scene = _scene("AUTO")
    auto.CHOICE_CACHE.clear()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    w, h = 32, 24
    window = cam.calc_matrix_camera(depsgraph, x=w, y=h)
    view = cam.matrix_world.inverted()
    engine = viewport.FakeViewEngine()
    _, first = viewport.view_draw(depsgraph, view, window, w, h, engine=engine)
    assert len(engine.workers) == 1 and not auto.CHOICE_CACHE     # measuring meanwhile
    engine.workers[0].join(300)
    assert len(auto.CHOICE_CACHE) == 2
    _, second = viewport.view_draw(depsgraph, view, window, w, h, engine=engine)
    assert len(engine.workers) == 1
    drawn = second[..., 3] > 0.5
    assert drawn.any() and second[drawn][:, :3].max() > 0.05
    assert not np.array_equal(first, second)
