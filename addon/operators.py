"""Operators: ``prt.precompute`` (modal with progress/ESC in the UI, synchronous in -b),
``prt.clear`` and ``prt.auto_choose`` (AUTO's stored choice made again)."""

from __future__ import annotations

import threading
import time

import bpy

from ..core import visibility
from ..core.visibility import Cancelled
from . import methods, precompute, scene_export, storage

#: Modal precomputes in progress (kept out of the .blend, unlike a scene property).
RUNNING: set = set()


def _gather(context, op):
    if not visibility.have_embree():
        op.report({"ERROR"}, "PRT precompute needs embreex, which ships as a wheel with this "
                             "extension: reinstall it for this platform")
        return None
    depsgraph = context.evaluated_depsgraph_get()
    t0 = time.perf_counter()
    try:
        job = precompute.gather(depsgraph, context.scene.prt)
    except scene_export.ExportError as exc:
        op.report({"ERROR"}, str(exc))
        return None
    job.timings["export"] = time.perf_counter() - t0
    return job


def _finish(context, op, job):
    precompute.commit(context.scene, job)
    for w in job.warnings + [o.coarse_warning for o in job.objects if o.coarse_warning]:
        op.report({"WARNING"}, w)
    t = job.timings
    op.report({"INFO"}, f"PRT precompute: {context.scene.prt.last_report}; export "
                        f"{t.get('export', 0):.2f} s, storage {t.get('storage', 0):.2f} s")
    for area in getattr(context.screen, "areas", []):
        area.tag_redraw()


def end_modal(op, context):
    """Stop a modal operator's timer, progress bar and status text (``op._timer``)."""
    wm = context.window_manager
    if op._timer is not None:
        wm.event_timer_remove(op._timer)
        op._timer = None
    wm.progress_end()
    context.workspace.status_text_set(None)


class PRT_OT_precompute(bpy.types.Operator):
    """Trace visibility for every visible mesh and store it in the .blend"""

    bl_idname = "prt.precompute"
    bl_label = "Precompute"
    # an undo step: Ctrl+Z brings back the data stored before (it lives on the objects)
    bl_options = {"REGISTER", "UNDO"}

    _timer = None
    _thread = None
    _job = None
    _error = None

    def execute(self, context):
        job = _gather(context, self)
        if job is None:
            return {"CANCELLED"}
        try:
            job.run()
        except Cancelled:
            self.report({"WARNING"}, "PRT precompute cancelled; nothing was changed")
            return {"CANCELLED"}
        _finish(context, self, job)
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if RUNNING:
            self.report({"WARNING"}, "A PRT precompute is already running")
            return {"CANCELLED"}
        job = _gather(context, self)
        if job is None:
            return {"CANCELLED"}
        self._job = job
        self._error = None

        def work():
            try:
                job.run()
            except BaseException as exc:  # handed back to the main thread
                self._error = exc

        self._thread = threading.Thread(target=work, name="prt-precompute", daemon=True)
        self._thread.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        RUNNING.add(id(self))
        return {"RUNNING_MODAL"}

    def _end(self, context):
        end_modal(self, context)
        RUNNING.discard(id(self))

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel_requested = True
        if event.type != "TIMER" and not job.cancel_requested:
            return {"PASS_THROUGH"}
        total = max(job.progress_total, 1)
        context.window_manager.progress_update(int(100 * job.progress_done / total))
        context.workspace.status_text_set(
            f"PRT precompute: {job.progress_done}/{job.progress_total} points (ESC to cancel)")
        if self._thread.is_alive():
            return {"RUNNING_MODAL"}
        self._end(context)
        if isinstance(self._error, Cancelled) or job.cancel_requested:
            self.report({"WARNING"}, "PRT precompute cancelled; nothing was changed")
            return {"CANCELLED"}
        if self._error is not None:
            self.report({"ERROR"}, f"PRT precompute failed: {self._error}")
            return {"CANCELLED"}
        _finish(context, self, job)
        return {"FINISHED"}


class PRT_OT_clear(bpy.types.Operator):
    """Remove the stored PRT data from every object"""

    bl_idname = "prt.clear"
    bl_label = "Clear Precomputed Data"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        count = storage.clear_all()
        self.report({"INFO"}, f"Cleared PRT data of {count} object(s)")
        return {"FINISHED"}


class PRT_OT_auto_choose(bpy.types.Operator):
    """Choose AUTO's method and budget per object again for the scene as it is now, weighed
    by the scene camera's image, and store the choice with the scene"""

    bl_idname = "prt.auto_choose"
    bl_label = "Choose"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return not RUNNING            # a running precompute replaces what it measures

    def execute(self, context):
        try:
            record = methods.REGISTRY["AUTO"].choose(context.scene,
                                                     context.evaluated_depsgraph_get())
        except RuntimeError as exc:
            self.report({"ERROR"}, f"PRT AUTO: {exc}")
            return {"CANCELLED"}
        where = (f"camera '{record['camera']}'" if record["camera"] else "the probe views")
        self.report({"INFO"}, f"PRT AUTO chose for {where}: " + ", ".join(
            f"{c['object']} → {c['choice']}" for c in record["objects"]))
        for area in getattr(context.screen, "areas", []):
            area.tag_redraw()
        return {"FINISHED"}


CLASSES = (PRT_OT_precompute, PRT_OT_clear, PRT_OT_auto_choose)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
