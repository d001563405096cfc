"""Operators: ``prt.precompute`` (modal with progress/ESC in the UI, synchronous in -b),
``prt.clear``, ``prt.bake`` (addon/frame/baking.py) and ``prt.auto_choose`` (AUTO's stored choice made again; modal with
progress/ESC in the UI, synchronous in -b).

A modal operator never blocks the UI for long: the trace runs in a worker thread; what
must run on the main thread (writing the results, AUTO's measurements, which draw with
the GPU) runs one short step per timer event (``precompute.commit_steps``,
``AutoMethod.choice_steps``), so the viewport stays interactive and ESC is seen."""

from __future__ import annotations

import threading
import time
import types

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

from ...core.scene import visibility
from ...core.common.parallel import Cancelled
from .. import methods
from ...core.pipeline import frame_status
from ..blender import precompute, scene_export, storage
from ..frame import baking

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
    _finished(context, op, job)


def _finished(context, op, job):
    coarse = [(o.coarse_warning, o.group) for o in job.objects if o.coarse_warning]
    for w in job.warnings + frame_status.grouped_notes(coarse):
        op.report({"WARNING"}, w)
    t = job.timings
    op.report({"INFO"}, f"PRT precompute: {context.scene.prt.last_report}; export "
                        f"{t.get('export', 0):.2f} s, storage {t.get('storage', 0):.2f} s")
    _redraw(context)


def _redraw(context):
    for area in getattr(context.screen, "areas", None) or []:
        area.tag_redraw()


def _chose(op, record):
    where = (f"camera '{record['camera']}'" if record["camera"] else "the probe views")
    op.report({"INFO"}, f"PRT AUTO chose for {where}: " + ", ".join(
        f"{c['object']} → {c['choice']}" for c in record["objects"]))


def _finish_steps(context, job):
    """The main thread's part after the trace, in steps of ``(text, fraction)``: the
    commit one object at a time, then AUTO's choice one measured candidate at a time
    (when the method is AUTO).  Returns the AUTO record or None."""
    job.defer_choice = True
    for fraction in precompute.commit_steps(context.scene, job):
        yield "writing the results", fraction
    if job.method != "AUTO":
        return None
    auto = methods.REGISTRY["AUTO"].shading
    steps = auto.choice_steps(context.scene, bpy.context.evaluated_depsgraph_get())
    while True:
        try:
            fraction = next(steps)
        except StopIteration as stop:
            auto_module().write_choice(context.scene, stop.value)
            return stop.value
        yield "AUTO choosing per object", fraction


def auto_module():
    from ..methods.auto import shading as auto
    return auto


def types_timer():
    """A stand-in timer event (the step after the trace runs at once)."""
    return types.SimpleNamespace(type="TIMER")


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
            self.report({"WARNING"}, "A PRT precompute or AUTO choice is already running")
            return {"CANCELLED"}
        job = _gather(context, self)
        if job is None:
            return {"CANCELLED"}
        self._job = job
        self._error = None
        self._steps = None

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

    def modal(self, context, event):
        job = self._job
        steps = getattr(self, "_steps", None)
        if steps is not None:
            return _precompute_step(self, context, event, steps)
        if event.type == "ESC":
            job.cancel_requested = True
        if event.type != "TIMER" and not job.cancel_requested:
            return {"PASS_THROUGH"}
        total = max(job.progress_total, 1)
        context.window_manager.progress_update(int(100 * job.progress_done / total))
        stage = getattr(job, "stage", "") or "tracing"
        context.workspace.status_text_set(
            f"PRT precompute: {stage}, {job.progress_done}/{job.progress_total} points "
            "(ESC to cancel)")
        if self._thread.is_alive():
            return {"RUNNING_MODAL"}
        if isinstance(self._error, Cancelled) or job.cancel_requested:
            self._end(context)
            self.report({"WARNING"}, "PRT precompute cancelled; nothing was changed")
            return {"CANCELLED"}
        if self._error is not None:
            self._end(context)
            self.report({"ERROR"}, f"PRT precompute failed: {self._error}")
            return {"CANCELLED"}
        # the trace is done: write (and choose for AUTO) one step per timer event, the
        # events now as often as the UI allows
        wm = context.window_manager
        if self._timer is not None and hasattr(wm, "event_timer_add"):
            wm.event_timer_remove(self._timer)
            self._timer = wm.event_timer_add(0.01, window=context.window)
        self._steps = _finish_steps(context, job)
        self._committed = False
        return _precompute_step(self, context, types_timer(), self._steps)

    def _end(self, context):
        end_modal(self, context)
        RUNNING.discard(id(self))


def _precompute_step(op, context, event, steps):
    """One step of the precompute's main-thread part (``op``: the operator); ESC
    stops AUTO's choice (the results are written by then: the precompute stands,
    without a new choice)."""
    if event.type == "ESC" and getattr(op, "_committed", False):
        steps.close()
        op._end(context)
        _finished(context, op, op._job)
        op.report({"WARNING"}, "PRT AUTO choice cancelled (the precompute is stored): "
                                 "press Choose to choose")
        return {"FINISHED"}
    if event.type != "TIMER":
        return {"PASS_THROUGH"}
    try:
        text, fraction = next(steps)
    except StopIteration as stop:
        op._end(context)
        _finished(context, op, op._job)
        if stop.value is not None:
            _chose(op, stop.value)
        return {"FINISHED"}
    except RuntimeError as exc:
        op._end(context)
        if getattr(op, "_committed", False):          # AUTO could not choose
            _finished(context, op, op._job)
            op.report({"WARNING"}, f"AUTO could not choose: {exc}")
            return {"FINISHED"}
        op.report({"ERROR"}, f"PRT precompute failed: {exc}")
        return {"CANCELLED"}
    op._committed = text != "writing the results" or fraction >= 1.0
    context.window_manager.progress_update(int(100 * fraction))
    context.workspace.status_text_set(
        f"PRT precompute: {text}, {fraction:.0%}"
        + (" (ESC stops the choice)" if op._committed else ""))
    return {"RUNNING_MODAL"}


class PRT_OT_clear(bpy.types.Operator):
    """Remove the stored PRT data from every object"""

    bl_idname = "prt.clear"
    bl_label = "Clear Precomputed Data"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        count = storage.clear_all()
        self.report({"INFO"}, f"Cleared PRT data of {count} object(s)")
        return {"FINISHED"}


class PRT_OT_bake(bpy.types.Operator):
    """Bake the relit irradiance, radiance or ambient occlusion of the selected objects
    into an image texture on a UV map or into a Color Attribute"""

    bl_idname = "prt.bake"
    bl_label = "Bake PRT"
    bl_options = {"REGISTER", "UNDO"}

    quantity: EnumProperty(name="Bake", default="IRRADIANCE", items=[
        ("IRRADIANCE", "Irradiance", "The light arriving (World, lamps, bounces): a lightmap "
                                     "to multiply by the material's colour"),
        ("RADIANCE", "Radiance", "The diffuse light leaving toward the scene camera"),
        ("AO", "Ambient Occlusion", "The cosine-weighted open sky")])
    target: EnumProperty(name="Into", default="IMAGE", items=[
        ("IMAGE", "Image Texture", "A float image per object on its UV map, packed"),
        ("COLOR_ATTRIBUTE", "Color Attribute", "A Face Corner colour attribute of its mesh")])
    uv_map: StringProperty(name="UV Map", default="",
                           description="The UV map the image is laid on (empty: the one "
                                       "rendered)")
    size: IntProperty(name="Size", default=1024, min=16, max=16384,
                      description="Width and height of the image in pixels")
    margin: IntProperty(name="Margin", default=16, min=0, max=256,
                        description="Pixels the islands are dilated by at their seams")
    rotations: StringProperty(name="World Rotations", default="",
                              description="Turns of the World about Z in degrees, added to "
                                          "its rotation, e.g. '0 90 180 270': one result "
                                          "each (empty: the current rotation only)")

    def execute(self, context):
        try:
            made, notes = baking.bake(
                context.scene, context.evaluated_depsgraph_get(),
                [o.name for o in context.selected_objects], self.quantity, self.target,
                self.uv_map, self.size, self.margin, baking.parse_turns(self.rotations))
        except ValueError as exc:
            self.report({"ERROR"}, f"PRT bake: {exc}")
            return {"CANCELLED"}
        for note in notes:
            self.report({"WARNING"}, f"PRT bake: {note}")
        self.report({"INFO"}, "PRT bake: " + ", ".join(made))
        return {"FINISHED"}


class PRT_OT_auto_choose(bpy.types.Operator):
    """Choose AUTO's method and budget per object again for the scene as it is now, weighed
    by the scene camera's image, and store the choice with the scene"""

    bl_idname = "prt.auto_choose"
    bl_label = "Choose"
    bl_options = {"REGISTER", "UNDO"}

    _timer = None
    _steps = None

    @classmethod
    def poll(cls, context):
        return not RUNNING            # a running precompute replaces what it measures

    def execute(self, context):
        try:
            record = methods.REGISTRY["AUTO"].shading.choose(context.scene,
                                                     context.evaluated_depsgraph_get())
        except RuntimeError as exc:
            self.report({"ERROR"}, f"PRT AUTO: {exc}")
            return {"CANCELLED"}
        _chose(self, record)
        _redraw(context)
        return {"FINISHED"}

    def invoke(self, context, event):
        """In the UI: one measured candidate per timer event (progress bar, ESC cancels
        and writes nothing); in ``-b`` (no timers) :meth:`execute`."""
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if RUNNING:
            self.report({"WARNING"}, "A PRT precompute or AUTO choice is already running")
            return {"CANCELLED"}
        self._steps = methods.REGISTRY["AUTO"].shading.choice_steps(
            context.scene, context.evaluated_depsgraph_get())
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        RUNNING.add(id(self))
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        return choice_step(self, context, event)

    def _end(self, context):
        end_modal(self, context)
        RUNNING.discard(id(self))


def choice_step(op, context, event):
    """One event of a modal AUTO choice (``op._steps``: ``AutoMethod.choice_steps``): a
    timer event runs one step, ESC closes the steps with nothing written, the last step
    writes the choice."""
    if event.type == "ESC":
        op._steps.close()
        op._end(context)
        op.report({"WARNING"}, "PRT AUTO choice cancelled; nothing was changed")
        return {"CANCELLED"}
    if event.type != "TIMER":
        return {"PASS_THROUGH"}
    try:
        fraction = next(op._steps)
    except StopIteration as stop:
        op._end(context)
        auto_module().write_choice(context.scene, stop.value)
        _chose(op, stop.value)
        _redraw(context)
        return {"FINISHED"}
    except RuntimeError as exc:
        op._end(context)
        op.report({"ERROR"}, f"PRT AUTO: {exc}")
        return {"CANCELLED"}
    context.window_manager.progress_update(int(100 * fraction))
    context.workspace.status_text_set(
        f"PRT AUTO: measuring the candidates, {fraction:.0%} (ESC to cancel)")
    return {"RUNNING_MODAL"}


CLASSES = (PRT_OT_precompute, PRT_OT_clear, PRT_OT_bake, PRT_OT_auto_choose)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
