"""The speed/error report (prt.report, bench/report.py) on whole scenes: the sweep covers
every registered method and budget, measuring restores the scene, ESC leaves no half
report, the operator runs in the background and in modal steps, and the report's REFERENCE
column against Cycles."""

from __future__ import annotations

import re

import bpy
import numpy as np
import pytest

from prt_relight.addon import methods
from prt_relight.addon.benchmark import measuring, sweep
from prt_relight.addon.blender import storage
from prt_relight.core.report import metrics as core_report
from prt_relight.bench import scenes


# ----------------------------------------------------------------------------- core

def _read_png(path) -> np.ndarray:
    """The 8-bit pixels of a PNG, top row first, alpha as stored (OpenImageIO)."""
    import OpenImageIO as oiio
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    try:
        return np.asarray(inp.read_image(oiio.UINT8))
    finally:
        inp.close()


# ----------------------------------------------------------------------------- Blender

def _tiny_scene():
    scenes.reset()
    scenes.add_world("forest")
    scenes.add_ground(size=6.0, cuts=8)
    scenes.add_suzanne(subdiv=0, location=(0.0, 0.0, 1.0))
    diffuse = scenes.bsdf_material("Diffuse", "ShaderNodeBsdfDiffuse",
                               Color=(0.7, 0.6, 0.5, 1.0))
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.append(diffuse)
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(40, 30)
    bpy.context.scene.prt.supersampling = 1


@pytest.mark.usefixtures("registered_addon")
def test_sweep_covers_every_registered_method_and_budget():
    rows = measuring.sweep()
    assert rows[0][0].id == "REFERENCE"
    for m in methods.REGISTRY.values():
        values = [v for mm, _, v in rows if mm is m]
        assert values == (list(m.bench.budget[1]) if m.bench.budget else [None]), m.id


# Methods run in the Blender tests (the full sweep of every method is bench/report.py's
# job; a method's slow derive would otherwise dominate the suite).
FAST = {"REFERENCE", "SH", "WAVELET", "AUTO"}


@pytest.fixture
def fast_auto(monkeypatch):
    from prt_relight.addon.methods.auto import measure as auto_measure
    every = auto_measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in FAST])


@pytest.mark.usefixtures("registered_addon", "fast_auto")
def test_report_measures_each_method_and_restores_the_scene(tmp_path):
    _tiny_scene()
    scene = bpy.context.scene
    scene.prt.method = "SH"
    scene.prt.sh_order = 3
    out = tmp_path / "rep"
    images = sorted(i.name for i in bpy.data.images if i.type != "RENDER_RESULT")
    run = sweep.ReportRun(scene, out, repeats=1, method_ids=FAST)
    index = run.run()
    # nothing any method stored during the sweep is left behind
    assert sorted(i.name for i in bpy.data.images if i.type != "RENDER_RESULT") == images
    assert index == out / "index.html" and index.is_file()
    text = index.read_text()
    chosen = [m for m in methods.REGISTRY.values() if m.id in FAST]
    expected_rows = sum(len(m.bench.budget[1]) if m.bench.budget else 1 for m in chosen)
    assert len(run.rows) == expected_rows
    for m in chosen:
        assert f">{m.id}<" in text                               # in the plot's legend
        assert any(r["method"] == m.id for r in run.rows)
    ref = [r for r in run.rows if r["method"] == "REFERENCE"][0]
    assert ref["error_ref"] == 0.0
    for r in run.rows:
        assert np.isfinite(r["frame_seconds"]) and r["frame_seconds"] > 0, r
        assert r["error_ref"] is not None and np.isfinite(r["error_ref"]), r
        assert (out / r["image"]).is_file() and (out / r["heatmap"]).is_file()
    # AUTO against the fastest fixed method within its target, timed interleaved
    target = scene.prt.auto_error_target
    fixed_rows = [r for r in run.rows if r["method"] != "AUTO"]
    fastest = core_report.fastest_meeting(fixed_rows, target)
    candidates = core_report.fastest_candidates(fixed_rows, target)
    check = run.auto_check
    assert (check is None) == (fastest is None)
    if check is not None:
        assert candidates[0] is fastest and 1 <= len(candidates) <= 3
        assert all(r["frame_seconds"] <= 2.0 * fastest["frame_seconds"] for r in candidates)
        assert check["fixed"] in [f"{r['method']} {r['budget']}".strip() for r in candidates]
        assert len(check["candidates"]) == len(candidates)
        assert check["rounds"] == 3 and check["auto_seconds"] > 0 and check["fixed_seconds"] > 0
        assert check["ratio"] == pytest.approx(check["fixed_seconds"] / check["auto_seconds"])
        assert "interleaved relit frames" in text
    # SH is a truncation of the same transfer: wrong, but not wildly
    sh = {r["label"]: r["error_ref"] for r in run.rows if r["method"] == "SH"}
    assert 0 < sh["5"] < 0.5
    # every image the page names exists
    for name in re.findall(r"src='([^']+)'", text):
        assert (out / name).is_file(), name
    img = _read_png(out / "reference.png")
    assert img.shape == (30, 40, 3) and img.max() > 50
    # the scene is as it was: method, budgets, no stored data (it had none)
    assert scene.prt.method == "SH" and scene.prt.sh_order == 3
    assert not any(storage.has(ob, storage.VISIBILITY) for ob in bpy.data.objects)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.usefixtures("registered_addon")
def test_report_cancel_leaves_no_half_report(tmp_path):
    _tiny_scene()
    scene = bpy.context.scene
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    images = sorted(i.name for i in bpy.data.images)
    scene.prt.method = "SH"
    scene.prt.sh_order = 2
    out = tmp_path / "rep"
    run = sweep.ReportRun(scene, out, repeats=1, method_ids=FAST)
    steps = run.steps()
    next(steps)
    next(steps)
    next(steps)                             # inside the sweep: REFERENCE then SH measured
    assert scene.prt.method != "SH" or scene.prt.sh_order != 2
    steps.close()                           # what ESC does
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []
    assert scene.prt.method == "SH" and scene.prt.sh_order == 2
    assert sorted(i.name for i in bpy.data.images) == images
    assert all(storage.has(ob, storage.VISIBILITY) for ob in bpy.data.objects
               if ob.type == "MESH")


@pytest.mark.usefixtures("registered_addon")
def test_report_operator_in_background(tmp_path):
    _tiny_scene()
    out = tmp_path / "op"
    result = bpy.ops.prt.report(directory=str(out), repeats=1, stability=False,
                                methods="SH")
    assert result == {"FINISHED"}
    text = (out / "index.html").read_text()
    assert ">SH<" in text and ">REFERENCE<" in text and ">WAVELET<" not in text


@pytest.mark.slow
@pytest.mark.usefixtures("registered_addon")
def test_report_against_cycles(tmp_path):
    _tiny_scene()
    engine = bpy.context.scene.render.engine
    out = tmp_path / "cy"
    run = sweep.ReportRun(bpy.context.scene, out, repeats=1, include_cycles=True,
                           cycles_samples=32, method_ids={"REFERENCE", "SH"})
    run.run()
    assert (out / "cycles.png").is_file() and (out / "cycles.exr").is_file()
    ref = [r for r in run.rows if r["method"] == "REFERENCE"][0]
    # REFERENCE against Cycles: per-vertex shading and 32 spp noise on a coarse
    # Suzanne; the same order as the add-on's Cycles tests
    assert 0 < ref["error_cycles"] < 0.25
    assert "vs Cycles" in (out / "index.html").read_text()
    assert bpy.context.scene.render.engine == engine


@pytest.mark.usefixtures("registered_addon", "fast_auto")
def test_report_modal_steps_and_esc(tmp_path):
    """The UI path driven headless with fake events: TIMER events step it to the end;
    ESC between steps cancels with nothing written and the settings restored."""
    import types

    from prt_relight.addon.benchmark import operator as report

    class Recorder:
        def __init__(self):
            self.reports = []
            self._timer = None

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    _tiny_scene()
    scene = bpy.context.scene
    scene.prt.method = "SH"
    status = []
    wm = types.SimpleNamespace(progress_update=lambda v: None, progress_end=lambda: None,
                               event_timer_remove=lambda t: None)
    ctx = types.SimpleNamespace(window_manager=wm, scene=scene,
                                workspace=types.SimpleNamespace(status_text_set=status.append))

    def start(out):
        op = Recorder()
        op._run = sweep.ReportRun(scene, out, repeats=1, method_ids={"REFERENCE", "SH"})
        op._gen = op._run.steps()
        op._end = lambda c: report.PRT_OT_report._end(op, c)
        return op

    def event(op, kind):
        return report.PRT_OT_report.modal(op, ctx, types.SimpleNamespace(type=kind))

    op = start(tmp_path / "esc")
    assert event(op, "MOUSEMOVE") == {"PASS_THROUGH"}
    assert event(op, "TIMER") == {"RUNNING_MODAL"}
    assert event(op, "TIMER") == {"RUNNING_MODAL"}
    assert any("ESC to cancel" in (s or "") for s in status)
    assert event(op, "ESC") == {"CANCELLED"}
    assert not (tmp_path / "esc").exists() and scene.prt.method == "SH"
    assert [p for p in tmp_path.iterdir()] == []

    op = start(tmp_path / "done")
    result = {"RUNNING_MODAL"}
    steps = 0
    while result == {"RUNNING_MODAL"}:
        result = event(op, "TIMER")
        steps += 1
    # one event per step, the last one finishes; the progress count reaches its total
    assert result == {"FINISHED"} and steps == op._run.steps_total
    assert op._run.steps_done == op._run.steps_total
    assert (tmp_path / "done" / "index.html").is_file()
    assert status[-1] is None and scene.prt.method == "SH"
