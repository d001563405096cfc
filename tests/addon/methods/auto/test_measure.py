"""AUTO's measurement (addon/methods/auto/measure.py): the points and probes it shades are
capped, and the sampled errors are within their stated margin of the full ones; the modal
Choose and Precompute steps (progress, ESC)."""

from __future__ import annotations

import types

import bpy
import numpy as np
import pytest

from prt_relight.addon.methods import REGISTRY
from prt_relight.addon.methods.auto import shading as auto
from prt_relight.addon.methods.auto import measure as auto_measure
from prt_relight.addon.methods.auto import measure

from .cases import auto_scene, fewer_candidates, stored_choice, synced_state


pytestmark = pytest.mark.usefixtures("registered_addon")


# ---------------------------------------------------------------- sampling (issue 20)

def _measured():
    return {m["object"]: m for m in (v[-1] for v in auto.CHOICE_CACHE.values())}


def test_the_points_and_probes_measured_are_capped(monkeypatch):
    """Every frame AUTO's measurement shades holds at most SAMPLE_POINTS points (the
    scene has more), at most PROBES probe views; the choice says what it measured."""
    fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 48)
    monkeypatch.setattr(auto_measure, "SLOPE_POINTS", 6)
    auto_scene()
    shaded = []
    for mid in ("REFERENCE", "SH", "WAVELET"):
        cls = type(REGISTRY[mid].shading)
        real = cls.shade

        def shade(self, state, eye, view_dir, real=real, mid=mid):
            shaded.append((mid, [st.points.count for st in state.objects], eye))
            return real(self, state, eye, view_dir)
        monkeypatch.setattr(cls, "shade", shade)
    auto.CHOICE_CACHE.clear()
    state = synced_state("AUTO", auto_error_target=0.02)
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
    fewer_candidates(monkeypatch)
    auto_scene()
    auto.CHOICE_CACHE.clear()
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 10 ** 6)
    auto.AutoShading().choices(synced_state("AUTO", auto_error_target=0.02))
    exact = _measured()
    assert all(m["sample"].exact for m in exact.values())
    auto.CHOICE_CACHE.clear()
    monkeypatch.setattr(auto_measure, "SAMPLE_POINTS", 64)
    monkeypatch.setattr(auto_measure, "SLOPE_POINTS", 8)
    auto.AutoShading().choices(synced_state("AUTO", auto_error_target=0.02))
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
    fewer_candidates(monkeypatch)
    auto_scene()
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
    record = stored_choice()
    assert [c["object"] for c in record["objects"]] == ["Ground", "Suzanne"]
    assert record["sample"]["points"] == measure.SAMPLE_POINTS


def test_modal_precompute_writes_in_steps_and_esc_stops_only_the_choice(monkeypatch):
    """After the trace the modal precompute writes one object per timer event, then runs
    AUTO's choice one candidate per event; ESC then stops the choice only (the precompute
    is stored, no choice is); without ESC the choice is stored."""
    import threading

    from prt_relight.addon.ui import operators
    from prt_relight.addon.blender import precompute
    fewer_candidates(monkeypatch)
    auto_scene()
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
    assert stored_choice()["objects"]
