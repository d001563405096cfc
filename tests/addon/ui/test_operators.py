"""addon.ui.operators: the modal precompute driven headless with fake events -- ESC cancels
with nothing changed, otherwise timer events finish it."""

from __future__ import annotations

import bpy
import pytest

from prt_relight.addon.blender import precompute
from ...cases.small import has_data, small_scene, stored


pytestmark = pytest.mark.usefixtures("registered_addon")


def test_modal_precompute_esc_cancels_and_timer_finishes():
    """The UI path (modal operator) driven headless with fake events: ESC cancels with
    nothing changed; otherwise TIMER events run it to completion and commit."""
    import threading
    import types

    from prt_relight.addon.ui import operators

    class Recorder:
        def __init__(self):
            self.reports = []
            self._timer = None
            self._error = None

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    small_scene()
    wm = types.SimpleNamespace(progress_update=lambda v: None, progress_end=lambda: None,
                               event_timer_remove=lambda t: None)
    ctx = types.SimpleNamespace(window_manager=wm, scene=bpy.context.scene, screen=None,
                                workspace=types.SimpleNamespace(status_text_set=lambda t: None))

    def start(op):
        op._job = precompute.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
        op._end = lambda c: operators.PRT_OT_precompute._end(op, c)
        op._job.cancel_requested = False
        gate = threading.Event()
        job = op._job

        def work():
            gate.wait(5)
            try:
                job.run()
            except BaseException as exc:
                op._error = exc

        op._thread = threading.Thread(target=work)
        op._thread.start()
        return gate

    def drive(op, first_event):
        result = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type=first_event))
        while result == {"RUNNING_MODAL"}:
            op._thread.join(0.05)
            result = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type="TIMER"))
        return result

    op = Recorder()
    gate = start(op)
    assert operators.PRT_OT_precompute.modal(
        op, ctx, types.SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}
    op._job.cancel_requested = False
    result_esc = operators.PRT_OT_precompute.modal(op, ctx, types.SimpleNamespace(type="ESC"))
    gate.set()                                    # the worker starts only after ESC
    if result_esc == {"RUNNING_MODAL"}:
        result_esc = drive(op, "TIMER")
    assert result_esc == {"CANCELLED"}
    assert any("cancelled" in m for _, m in op.reports)
    assert stored() == [] and not any(has_data(o) for o in bpy.data.objects)

    op = Recorder()
    start(op).set()
    assert drive(op, "TIMER") == {"FINISHED"}
    assert has_data(bpy.data.objects["Suzanne"])
    assert not operators.RUNNING
