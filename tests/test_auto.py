"""AUTO: per-object choice meets the error target against REFERENCE, falls back to
REFERENCE when nothing does, is cached (only what changed is selected again), sizes
integer budgets (RSL light count) between the listed values, and is stored with the scene
(a reopened .blend draws the same frame)."""

from __future__ import annotations

import json
import subprocess
import sys
import types

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
from prt_relight.addon.methods import REGISTRY
from prt_relight.addon.methods.auto import shading as auto
from prt_relight.addon.methods.auto import assign as auto_assign, measure as auto_measure
from prt_relight.addon.methods.auto import measure
from prt_relight.addon.methods.auto import store as auto_store

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")


def _sky(width=64, height=32):
    """A small environment: a sky gradient and a soft bright lobe (cheap to resample,
    so relit timings in the selection stay fast)."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta, phi = np.meshgrid(np.pi * v, 2 * np.pi * (0.5 - u), indexing="ij")
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    lobe = np.exp((d @ np.array([0.48, -0.36, 0.8]) - 1.0) / 0.05)
    sky = 0.2 + 0.4 * np.clip(d[..., 2], 0, 1)
    rgb = sky[..., None] * np.array([0.6, 0.8, 1.0]) + 8.0 * lobe[..., None]
    return rgb.astype(np.float32)


def _scene(method="REFERENCE", rotation_z=0.0):
    """Ground and Suzanne under :func:`_sky`, precomputed with ``method``."""
    bs.reset()
    bs.add_world(image=bs.float_image("sky", _sky()), rotation_z=rotation_z)
    bs.add_ground(size=6.0, cuts=8)
    bs.add_suzanne(subdiv=0)
    diffuse = bs.bsdf_material("Diffuse", "ShaderNodeBsdfDiffuse", Color=(0.7, 0.6, 0.5, 1.0))
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.append(diffuse)
    bs.add_camera()
    bs.set_resolution(64, 48)
    bpy.context.scene.prt.method = method
    assert bpy.ops.prt.precompute() == {"FINISHED"}


def _state(method, **settings):
    scene = bpy.context.scene
    scene.prt.method = method
    for k, v in settings.items():
        setattr(scene.prt, k, v)
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def _rel(a, b, weights=None):
    """rel-L2 of per-corner radiance; ``weights`` per corner (surface area) or equal."""
    a, b = np.concatenate(a).astype(np.float64), np.concatenate(b).astype(np.float64)
    w = np.ones(len(a)) if weights is None else np.concatenate(weights)
    return float(np.sqrt(np.sum(w[:, None] * (a - b) ** 2) / np.sum(w[:, None] * b ** 2)))


def _area(objects):
    """Surface area per corner, computed here independently of AUTO's helper."""
    out = []
    for st in objects:
        p = st.arrays.positions[st.arrays.corner_verts]
        w = np.zeros(len(p))
        for t in st.arrays.triangles:
            area = 0.5 * np.linalg.norm(np.cross(p[t[1]] - p[t[0]], p[t[2]] - p[t[0]]))
            w[t] += area / 3.0
        out.append(w)
    return out


def _fewer_candidates(monkeypatch):
    """SH and WAVELET budgets only: the selection logic is the same, the test faster."""
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in ("SH", "WAVELET")])


def test_auto_meets_the_target_per_object_and_is_cached(monkeypatch):
    _fewer_candidates(monkeypatch)
    _scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    truth = _state("REFERENCE").shade(eye)
    auto.CHOICE_CACHE.clear()
    state = _state("AUTO", auto_error_target=0.02)
    before = measure.SELECTIONS[0]
    got = state.shade(eye)
    assert measure.SELECTIONS[0] - before == len(state.objects) == 2
    choices = auto.LAST_CHOICES
    assert [c["object"] for c in choices] == [st.name for st in state.objects]
    areas = _area(state.objects)
    for st, c, a, b, w in zip(state.objects, choices, got, truth, areas):
        assert np.isfinite(a).all()
        assert c["method"] in REGISTRY
        # the measured per-object error is the drawn one (diffuse: view independent)
        assert c["error"] == pytest.approx(_rel([a], [b], [w]), rel=1e-3, abs=1e-6), c
    # the frame's surface-weighted error meets the target (with the diffuse margin)
    assert _rel(got, truth, areas) <= 0.9 * 0.02
    assert any("AUTO:" in w for w in state.warnings)
    # same lighting, same objects, same target: nothing is selected again
    state.shade(eye + 0.1)
    assert measure.SELECTIONS[0] - before == 2
    # a looser target: selected again, and never a slower choice than REFERENCE for all
    loose = _state("AUTO", auto_error_target=0.5)
    loose_out = loose.shade(eye)
    assert measure.SELECTIONS[0] - before == 4
    assert all(c["method"] in ("SH", "WAVELET") for c in auto.LAST_CHOICES), auto.LAST_CHOICES
    assert _rel(loose_out, truth, areas) <= 0.9 * 0.5


def test_auto_falls_back_to_reference_when_nothing_meets_the_target(monkeypatch):
    _fewer_candidates(monkeypatch)
    _scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    truth = _state("REFERENCE").shade(eye)
    state = _state("AUTO", auto_error_target=0.0)
    got = state.shade(eye)
    assert all(c["method"] == "REFERENCE" for c in auto.LAST_CHOICES)
    for a, b in zip(got, truth):
        np.testing.assert_array_equal(a, b)


def test_budget_between_hooks():
    """RSL bisects light counts, WAVELET term counts (geometric); SH orders are
    consecutive and the default has nothing between."""
    rsl, wav, sh = REGISTRY["RSL"], REGISTRY["WAVELET"], REGISTRY["SH"]
    assert rsl.bench.budget_between(10, 30) == 20
    assert rsl.bench.budget_between(20, 30) == 25
    assert rsl.bench.budget_between(29, 30) is None
    assert wav.bench.budget_between(32, 128) == 64
    assert wav.bench.budget_between(128, 512) == 256
    assert wav.bench.budget_between(32, 33) is None
    assert sh.bench.budget_between(2, 3) is None
    for m in REGISTRY.values():
        prop_values = m.bench.budget[1] if m.bench.budget else []
        for lo, hi in zip(prop_values, prop_values[1:]):
            mid = m.bench.budget_between(lo, hi)
            assert mid is None or lo < mid < hi, (m.id, lo, hi, mid)


def _virtual_clock(monkeypatch, costs):
    """AUTO's timings from a cost model (seconds per shaded point, per method, from the
    settings) instead of the wall clock: the choice then does not hang on timing noise."""
    clock = [0.0]
    monkeypatch.setattr(auto_measure, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))
    for mid, cost in costs.items():
        cls = type(REGISTRY[mid].shading)
        real = cls.shade

        def shade(self, state, eye, view_dir, real=real, cost=cost):
            clock[0] += cost(state.settings) * sum(st.points.count for st in state.objects)
            return real(self, state, eye, view_dir)
        monkeypatch.setattr(cls, "shade", shade)


def test_auto_sizes_the_light_count_between_the_listed_values(monkeypatch):
    """RSL only, its per-frame cost linear in the light count, on the ground alone
    (shadowed by Suzanne): AUTO bisects between the last listed count missing the target
    and the first meeting it, and takes a count that is not one of the listed ones, cheaper
    than the cheapest listed count that meets the target, and still meeting it."""
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id == "RSL"])
    _virtual_clock(monkeypatch, {"REFERENCE": lambda s: 1e-2,
                                 "RSL": lambda s: 1e-5 * s["rsl_lights"]})
    _scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    target, listed = 0.03, REGISTRY["RSL"].bench.budget[1]

    def ground(state):
        state.objects = [st for st in state.objects if st.name == "Grid"]
        return state

    truth = ground(_state("REFERENCE")).shade(eye)
    auto.CHOICE_CACHE.clear()
    state = ground(_state("AUTO", auto_error_target=target))
    got = state.shade(eye)
    (choice,) = auto.LAST_CHOICES
    area = _area(state.objects)
    error = _rel(got, truth, area)
    assert choice["method"] == "RSL" and choice["value"] not in listed, choice
    assert choice["error"] == pytest.approx(error, rel=1e-3, abs=1e-6), choice
    assert error <= 0.9 * target
    # the listed counts that meet the target are all dearer than the one taken
    meeting = [k for k in listed
               if _rel(ground(_state("RSL", rsl_lights=k)).shade(eye), truth, area)
               <= 0.9 * target]
    assert meeting and choice["value"] < min(meeting), (choice, meeting)


def _camera_frame(state, width=96, height=72):
    """Draw ``state`` through the scene camera (the engine's path; it gives AUTO the
    frame's camera): linear RGBA pixels."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.gpu.drawing import ensure_gpu
    from prt_relight.addon.benchmark.measuring import camera_matrices
    scene = bpy.context.scene
    ensure_gpu(scene)
    view, projection, persp = camera_matrices(scene, bpy.context.evaluated_depsgraph_get(),
                                               width, height)
    return render_pixels(state, view, projection, width, height, True, persp, 1)


def test_auto_meets_the_target_in_the_camera_image(monkeypatch):
    """Drawn through a camera, AUTO weighs each point's error by the pixels it covers
    there: the image (not the surface) meets the target, and the reason says so."""
    from prt_relight.core.report import metrics as core_report
    _fewer_candidates(monkeypatch)
    _scene()
    target = 0.02
    truth = _camera_frame(_state("REFERENCE"))
    auto.CHOICE_CACHE.clear()
    state = _state("AUTO", auto_error_target=target)
    image = _camera_frame(state)
    assert np.isfinite(image).all()
    assert all("in the camera's image" in c["reason"] for c in auto.LAST_CHOICES), \
        [(c["choice"], c["reason"]) for c in auto.LAST_CHOICES]
    assert core_report.rel_l2(image, truth) <= target


def test_auto_spends_nothing_on_objects_the_camera_does_not_see(monkeypatch):
    """An object outside the frame weighs nothing in the image: it takes its fastest
    measured option, however far off, while the visible one still meets the target."""
    from prt_relight.addon.frame.engine import frame_camera
    from mathutils import Matrix
    _fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_assign, "UNIFORM_TRIED", 0)      # the mix only: no timing decides
    _scene()
    auto.CHOICE_CACHE.clear()
    state = _state("AUTO", auto_error_target=0.02)
    # a camera above the grid's corner, looking straight down, Suzanne out of frame
    view = Matrix.Translation((-2.2, -2.2, -2.0))
    s = 1.0 / 0.6                                      # orthographic half width 0.6
    projection = Matrix(((s, 0, 0, 0), (0, s, 0, 0), (0, 0, -0.1, 0), (0, 0, 0, 1)))
    state.camera = frame_camera(view, projection, 64, 64, None, np.array([0.0, 0.0, 1.0]))
    eye = np.array([2.2, 2.2, 2.0])
    state.shade(eye)
    chosen = {c["object"]: c for c in auto.LAST_CHOICES}
    measured = {m["object"]: m for m in (v[-1] if isinstance(v, tuple) else v
                                         for v in auto.CHOICE_CACHE.values())}
    hidden = next(n for n in chosen if n != "Grid")
    fastest = min((o for o in measured[hidden]["options"]
                   if np.isfinite(o[1]) and np.isfinite(o[2])), key=lambda o: o[1])
    assert (chosen[hidden]["method"], chosen[hidden]["setting"], chosen[hidden]["value"]) \
        == fastest[0], (chosen[hidden], fastest)
    assert chosen[hidden]["error"] == 0.0           # it shows no pixel
    assert chosen["Grid"]["error"] <= 0.95 * 0.02


# ---------------------------------------------------------------- the stored choice

def _untimed(monkeypatch):
    """AUTO's clock fails the test when read: a frame drawn with the stored choice times
    nothing."""
    def read():
        raise AssertionError("AUTO timed a frame that has a stored choice")
    monkeypatch.setattr(auto_measure, "time", types.SimpleNamespace(perf_counter=read))


def _stored():
    return json.loads(bpy.context.scene.prt.auto_choice)


class _Labels:
    """A layout that keeps the labels and operators an AUTO settings draw puts in it."""

    def __init__(self):
        self.texts = []

    def box(self):
        return self

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties

    def operator(self, idname, **kwargs):
        self.texts.append(idname)

    def label(self, text="", **kwargs):
        self.texts.append(text)


def _panel(scene):
    layout = _Labels()
    REGISTRY["AUTO"].settings.draw(layout, scene.prt)
    return layout.texts


def _drawn_with_stored(state, eye):
    state.shade(eye)
    return any(w.startswith("AUTO (stored choice)") for w in state.warnings)


# Draws a saved .blend's F12 in a new process, the add-on registered as conftest.py does.
# AUTO's clock there reads 1 s for every interval it times: a process whose timings differ
# from the first one's (the live choice then takes REFERENCE everywhere).
_REOPEN = """
import importlib.util, pathlib, sys, types
root = pathlib.Path(sys.argv[1])
spec = importlib.util.spec_from_file_location(
    "prt_relight", root / "__init__.py", submodule_search_locations=[str(root)])
addon = importlib.util.module_from_spec(spec)
sys.modules["prt_relight"] = addon
spec.loader.exec_module(addon)
import bpy
addon.register()
from prt_relight.addon.methods.auto import measure as auto
reads = [0]
def tick():
    reads[0] += 1
    return float(reads[0])
auto.time = types.SimpleNamespace(perf_counter=tick)
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
bpy.ops.render.render()
bpy.data.images["Render Result"].save_render(sys.argv[3])
print("AUTO clock reads:", reads[0], flush=True)
"""


def test_a_reopened_blend_renders_the_same_auto_frame(tmp_path, repo_root):
    """Precompute with AUTO (every candidate), F12, save; the .blend opened in a new
    process renders a bit-identical frame and AUTO reads no clock there."""
    _scene(method="AUTO")
    first = bs.render_exr(tmp_path / "first.exr")
    blend = tmp_path / "auto.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    script = tmp_path / "reopen.py"
    script.write_text(_REOPEN)
    again_path = tmp_path / "again.exr"
    proc = subprocess.run([sys.executable, str(script), str(repo_root), str(blend),
                           str(again_path)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and again_path.exists(), proc.stderr[-3000:]
    again = bs.read_exr(again_path)
    assert np.array_equal(first, again), (
        f"max difference {np.abs(first - again).max()}", proc.stdout[-2000:])
    assert "AUTO clock reads: 0" in proc.stdout, proc.stdout[-2000:]


def test_the_stored_choice_holds_until_the_scene_or_the_target_changes(monkeypatch):
    """Precompute with AUTO stores its choice for the scene camera; frames use it without
    timing while the world turns; a new target, lighting strength or moved object makes it
    out of date (the frame is chosen live and nothing is written) until Choose or
    Precompute chooses again."""
    _fewer_candidates(monkeypatch)
    _scene(method="AUTO", rotation_z=0.3)
    scene = bpy.context.scene
    record = _stored()
    assert record["camera"] == "Camera" and record["size"] == [64, 48]
    assert [c["object"] for c in record["objects"]] == ["Grid", "Suzanne"]
    assert all(c["method"] in ("REFERENCE", "SH", "WAVELET") for c in record["objects"])
    eye = np.array(scene.camera.matrix_world.translation)
    real_time = auto_measure.time
    _untimed(monkeypatch)
    state = _state("AUTO")
    assert _drawn_with_stored(state, eye), state.warnings
    assert [(c["object"], c["choice"]) for c in auto.LAST_CHOICES] == \
        [(c["object"], c["choice"]) for c in record["objects"]]
    assert auto_store.stored_status(scene.prt) == ""
    panel = _panel(scene)
    assert "Stored choice, current" in panel and "prt.auto_choose" in panel
    assert "Chosen for camera 'Camera' at 64×48" in panel
    assert all(any(t.startswith(f"{c['object']}: {c['choice']}") for t in panel)
               for c in record["objects"]), panel
    # the same environment turned keeps the choice
    mapping = next(n for n in scene.world.node_tree.nodes if n.type == "MAPPING")
    mapping.inputs["Rotation"].default_value[2] = 1.4
    assert _drawn_with_stored(_state("AUTO"), eye)
    stored = scene.prt.auto_choice

    monkeypatch.setattr(auto_measure, "time", real_time)
    # a stored choice naming a method no longer registered is out of date
    scene.prt.auto_choice = json.dumps(dict(record, objects=[
        dict(c, method="GONE") for c in record["objects"]]))
    state = _state("AUTO")
    assert not _drawn_with_stored(state, eye)
    assert any("no longer present" in w for w in state.warnings), state.warnings
    scene.prt.auto_choice = stored
    for change, part in ((lambda: setattr(scene.prt, "auto_error_target", 0.05), "target"),
                         (lambda: setattr(scene.world.node_tree.nodes["Background"]
                                          .inputs["Strength"], "default_value", 2.0),
                          "lighting"),
                         (lambda: setattr(bpy.data.objects["Suzanne"].location, "z", 1.3),
                          "geometry")):
        change()
        state = _state("AUTO")
        assert not _drawn_with_stored(state, eye)
        assert any(w.startswith("AUTO choice is out of date (") and part in w
                   for w in state.warnings), state.warnings
        assert any(w.startswith("AUTO:") for w in state.warnings)    # chosen live
        assert scene.prt.auto_choice == stored                         # and not written
        assert part in auto_store.stored_status(scene.prt)
        assert any(t.startswith("AUTO choice is out of date") and part in t
                   for t in _panel(scene))
        if part == "target":
            assert bpy.ops.prt.auto_choose() == {"FINISHED"}
            assert _stored()["key"]["target"] == pytest.approx(0.05)
            assert _drawn_with_stored(_state("AUTO"), eye)
            stored = scene.prt.auto_choice
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert scene.prt.auto_choice != stored
    _untimed(monkeypatch)
    assert _drawn_with_stored(_state("AUTO"), eye)


def test_clear_removes_the_stored_choice(monkeypatch):
    _fewer_candidates(monkeypatch)
    _scene(method="AUTO")
    scene = bpy.context.scene
    assert _stored()["objects"]
    assert bpy.ops.prt.clear() == {"FINISHED"}
    assert scene.prt.auto_choice == ""
    assert "No stored choice: press Choose (or Precompute)" in _panel(scene)
    state = _state("AUTO")
    state.shade(np.array(scene.camera.matrix_world.translation))
    assert any(w.startswith("AUTO has no stored choice") for w in state.warnings)


def test_choose_stores_the_choice_for_the_scene_camera(monkeypatch):
    """Choose weighs errors in the scene camera's image: with Suzanne out of the frame it
    stores Suzanne's fastest measured option (it shows no pixel).  The camera is not part
    of the key: moving it keeps the stored choice until Choose is pressed again."""
    _fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_assign, "UNIFORM_TRIED", 0)      # the mix only: no timing decides
    _scene()
    scene = bpy.context.scene
    scene.prt.method = "AUTO"
    assert scene.prt.auto_choice == ""                  # a REFERENCE precompute chose nothing
    cam = scene.camera                                  # above the grid's corner, looking down
    cam.data.type, cam.data.ortho_scale = "ORTHO", 1.2
    cam.location, cam.rotation_euler = (2.2, 2.2, 2.0), (0.0, 0.0, 0.0)
    bs.set_resolution(64, 64)
    auto.CHOICE_CACHE.clear()
    assert bpy.ops.prt.auto_choose() == {"FINISHED"}
    record = _stored()
    assert record["camera"] == cam.name and record["size"] == [64, 64]
    chosen = {c["object"]: c for c in record["objects"]}
    measured = {m["object"]: m for m in (v[-1] if isinstance(v, tuple) else v
                                         for v in auto.CHOICE_CACHE.values())}
    fastest = min((o for o in measured["Suzanne"]["options"]
                   if np.isfinite(o[1]) and np.isfinite(o[2])), key=lambda o: o[1])
    suzanne = chosen["Suzanne"]
    assert (suzanne["method"], suzanne["setting"], suzanne["value"]) == fastest[0], suzanne
    assert suzanne["error"] == 0.0
    assert chosen["Grid"]["error"] <= 0.95 * 0.02
    _untimed(monkeypatch)
    cam.location = (0.0, -6.0, 3.0)
    cam.data.type = "PERSP"
    assert _drawn_with_stored(_state("AUTO"), np.array(cam.location))


# ---------------------------------------------------------------- sampling (issue 20)

def _measured():
    return {m["object"]: m for m in (v[-1] for v in auto.CHOICE_CACHE.values())}


def test_the_points_and_probes_measured_are_capped(monkeypatch):
    """Every frame AUTO's measurement shades holds at most SAMPLE_POINTS points (the
    scene has more), at most PROBES probe views; the choice says what it measured."""
    _fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 48)
    monkeypatch.setattr(auto_measure, "SLOPE_POINTS", 6)
    _scene()
    shaded = []
    for mid in ("REFERENCE", "SH", "WAVELET"):
        cls = type(REGISTRY[mid].shading)
        real = cls.shade

        def shade(self, state, eye, view_dir, real=real, mid=mid):
            shaded.append((mid, [st.points.count for st in state.objects], eye))
            return real(self, state, eye, view_dir)
        monkeypatch.setattr(cls, "shade", shade)
    auto.CHOICE_CACHE.clear()
    state = _state("AUTO", auto_error_target=0.02)
    counts = {st.name: st.points.count for st in state.objects}
    assert all(n > 48 for n in counts.values()), counts
    choices = auto.AutoShading().choices(state)
    measured = [c for c in shaded]
    assert measured and all(max(n) <= 48 for _, n, _ in measured), measured
    # diffuse-only objects: one probe view per candidate (plus the timing frames' eye)
    eyes = {tuple(np.round(e, 6)) for _, _, e in measured}
    assert len(eyes) <= 2 * measure.PROBES
    for c in choices:
        assert c["points"] == counts[c["object"]] and 0 < c["sampled"] <= 48
        assert f"measured on {c['sampled']} of {c['points']} points" in c["reason"]


def test_the_sampled_errors_are_within_their_stated_margin_of_the_full_ones(monkeypatch):
    """The same selection measured whole (every point: exact) and on 64 draws: each
    option's sampled rel-L2 is within 1.5 x its stated margin (a 2-sigma one) of the
    exact one."""
    _fewer_candidates(monkeypatch)
    _scene()
    auto.CHOICE_CACHE.clear()
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 10 ** 6)
    auto.AutoShading().choices(_state("AUTO", auto_error_target=0.02))
    exact = _measured()
    assert all(m["sample"].exact for m in exact.values())
    auto.CHOICE_CACHE.clear()
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 64)
    monkeypatch.setattr(auto_measure, "SLOPE_POINTS", 8)
    auto.AutoShading().choices(_state("AUTO", auto_error_target=0.02))
    sampled = _measured()
    compared = 0
    for name, s in sampled.items():
        assert not s["sample"].exact
        full = {o[0]: o for o in exact[name]["options"]}
        for key, _, up, err2 in s["options"]:
            if key not in full or not np.isfinite(err2) or not np.isfinite(full[key][3]):
                continue
            truth = measure.rel_error(full[key][3], exact[name]["ref_norm2"])
            est = measure.rel_error(err2, s["ref_norm2"])
            margin = measure.rel_error(up, s["ref_norm2"]) - est
            assert abs(est - truth) <= 1.5 * margin + 1e-9, (name, key, est, truth, margin)
            compared += 1
    assert compared >= 6


def test_modal_choose_reports_progress_and_esc_writes_nothing(monkeypatch):
    """prt.auto_choose's modal steps (what one timer event runs): progress per measured
    candidate, ESC cancels with nothing stored; run to its end it stores the choice."""
    from prt_relight.addon.ui import operators
    _fewer_candidates(monkeypatch)
    _scene()
    scene = bpy.context.scene
    scene.prt.method = "AUTO"
    assert scene.prt.auto_choice == ""
    progress = []
    wm = types.SimpleNamespace(progress_update=progress.append, progress_end=lambda: None,
                               event_timer_remove=lambda t: None)
    ctx = types.SimpleNamespace(window_manager=wm, scene=scene, screen=None,
                                workspace=types.SimpleNamespace(status_text_set=lambda t: None))

    class Op:
        def __init__(self):
            self.reports, self.ended, self._timer = [], 0, None
            self._steps = REGISTRY["AUTO"].shading.choice_steps(
                scene, bpy.context.evaluated_depsgraph_get())

        def report(self, kind, message):
            self.reports.append(message)

        def _end(self, context):
            self.ended += 1

    timer, esc = types.SimpleNamespace(type="TIMER"), types.SimpleNamespace(type="ESC")
    auto.CHOICE_CACHE.clear()
    op = Op()
    assert operators.choice_step(op, ctx, types.SimpleNamespace(type="MOUSEMOVE")) == \
        {"PASS_THROUGH"}
    for _ in range(3):
        assert operators.choice_step(op, ctx, timer) == {"RUNNING_MODAL"}
    assert operators.choice_step(op, ctx, esc) == {"CANCELLED"}
    assert op.ended == 1 and any("cancelled" in r for r in op.reports)
    assert scene.prt.auto_choice == ""
    auto.CHOICE_CACHE.clear()
    progress.clear()
    op = Op()
    steps = 0
    while (result := operators.choice_step(op, ctx, timer)) == {"RUNNING_MODAL"}:
        steps += 1
    assert result == {"FINISHED"} and op.ended == 1
    assert steps >= 2 * len(measure.candidates())     # one candidate per event
    assert progress == sorted(progress) and 0 <= progress[0] and progress[-1] <= 100
    record = _stored()
    assert [c["object"] for c in record["objects"]] == ["Grid", "Suzanne"]
    assert record["sample"]["points"] == measure.SAMPLE_POINTS


def test_modal_precompute_writes_in_steps_and_esc_stops_only_the_choice(monkeypatch):
    """After the trace the modal precompute writes one object per timer event, then runs
    AUTO's choice one candidate per event; ESC then stops the choice only (the precompute
    is stored, no choice is); without ESC the choice is stored."""
    import threading

    from prt_relight.addon.ui import operators
    from prt_relight.addon.blender import precompute
    _fewer_candidates(monkeypatch)
    _scene()
    scene = bpy.context.scene
    scene.prt.method = "AUTO"
    wm = types.SimpleNamespace(progress_update=lambda v: None, progress_end=lambda: None,
                               event_timer_remove=lambda t: None)
    texts = []
    ctx = types.SimpleNamespace(window_manager=wm, scene=scene, screen=None,
                                workspace=types.SimpleNamespace(status_text_set=texts.append))

    class Op:
        def __init__(self):
            self.reports, self._timer, self._error, self._steps = [], None, None, None
            self._job = precompute.gather(bpy.context.evaluated_depsgraph_get(), scene.prt)
            self._job.run()
            self._thread = threading.Thread(target=lambda: None)
            self._thread.start()
            self._thread.join()

        def report(self, kind, message):
            self.reports.append(message)

        def _end(self, context):
            pass

    timer = types.SimpleNamespace(type="TIMER")
    auto.CHOICE_CACHE.clear()
    run_before = scene.prt.precompute_id
    op = Op()
    modal = operators.PRT_OT_precompute.modal
    assert modal(op, ctx, timer) == {"RUNNING_MODAL"}
    assert texts[-1].startswith("PRT precompute: writing the results")
    while not any(t.startswith("PRT precompute: AUTO choosing") for t in texts):
        assert modal(op, ctx, timer) == {"RUNNING_MODAL"}
    assert modal(op, ctx, types.SimpleNamespace(type="ESC")) == {"FINISHED"}
    assert any("AUTO choice cancelled" in r for r in op.reports), op.reports
    assert scene.prt.precompute_id != run_before and scene.prt.auto_choice == ""
    op = Op()
    while (result := modal(op, ctx, timer)) == {"RUNNING_MODAL"}:
        pass
    assert result == {"FINISHED"} and any("PRT AUTO chose" in r for r in op.reports)
    assert _stored()["objects"]
