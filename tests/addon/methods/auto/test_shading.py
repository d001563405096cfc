"""AUTO (addon/methods/auto/shading.py): the per-object choice meets the error target against
REFERENCE (per object, and in the camera's image), falls back to REFERENCE when nothing
does, is cached, sizes integer budgets between the listed values, and spends nothing on
objects the camera does not see."""

from __future__ import annotations

import types

import bpy
import numpy as np
import pytest

from prt_relight.addon.methods import REGISTRY
from prt_relight.addon.methods.auto import shading as auto
from prt_relight.addon.methods.auto import assign as auto_assign, measure as auto_measure
from prt_relight.addon.methods.auto import measure

from .cases import auto_scene, fewer_candidates, synced_state


pytestmark = pytest.mark.usefixtures("registered_addon")


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


def test_auto_meets_the_target_per_object_and_is_cached(monkeypatch):
    fewer_candidates(monkeypatch)
    auto_scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    truth = synced_state("REFERENCE").shade(eye)
    auto.CHOICE_CACHE.clear()
    state = synced_state("AUTO", auto_error_target=0.02)
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
    loose = synced_state("AUTO", auto_error_target=0.5)
    loose_out = loose.shade(eye)
    assert measure.SELECTIONS[0] - before == 4
    assert all(c["method"] in ("SH", "WAVELET") for c in auto.LAST_CHOICES), auto.LAST_CHOICES
    assert _rel(loose_out, truth, areas) <= 0.9 * 0.5


def test_auto_falls_back_to_reference_when_nothing_meets_the_target(monkeypatch):
    fewer_candidates(monkeypatch)
    auto_scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    truth = synced_state("REFERENCE").shade(eye)
    state = synced_state("AUTO", auto_error_target=0.0)
    got = state.shade(eye)
    assert all(c["method"] == "REFERENCE" for c in auto.LAST_CHOICES)
    for a, b in zip(got, truth):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


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
    auto_scene()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    target, listed = 0.03, REGISTRY["RSL"].bench.budget[1]

    def ground(state):
        state.objects = [st for st in state.objects if st.name == "Ground"]
        return state

    truth = ground(synced_state("REFERENCE")).shade(eye)
    auto.CHOICE_CACHE.clear()
    state = ground(synced_state("AUTO", auto_error_target=target))
    got = state.shade(eye)
    (choice,) = auto.LAST_CHOICES
    area = _area(state.objects)
    error = _rel(got, truth, area)
    assert choice["method"] == "RSL" and choice["value"] not in listed, choice
    assert choice["error"] == pytest.approx(error, rel=1e-3, abs=1e-6), choice
    assert error <= 0.9 * target
    # the listed counts that meet the target are all dearer than the one taken
    meeting = [k for k in listed
               if _rel(ground(synced_state("RSL", rsl_lights=k)).shade(eye), truth, area)
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
    fewer_candidates(monkeypatch)
    auto_scene()
    target = 0.02
    truth = _camera_frame(synced_state("REFERENCE"))
    auto.CHOICE_CACHE.clear()
    state = synced_state("AUTO", auto_error_target=target)
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
    fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_assign, "UNIFORM_TRIED", 0)      # the mix only: no timing decides
    auto_scene()
    auto.CHOICE_CACHE.clear()
    state = synced_state("AUTO", auto_error_target=0.02)
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
    hidden = next(n for n in chosen if n != "Ground")
    fastest = min((o for o in measured[hidden]["options"]
                   if np.isfinite(o[1]) and np.isfinite(o[2])), key=lambda o: o[1])
    assert (chosen[hidden]["method"], chosen[hidden]["setting"], chosen[hidden]["value"]) \
        == fastest[0], (chosen[hidden], fastest)
    assert chosen[hidden]["error"] == 0.0           # it shows no pixel
    assert chosen["Ground"]["error"] <= 0.95 * 0.02
