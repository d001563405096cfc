"""``prt.report``: every registered method over a sweep of its budget, timed and measured
against REFERENCE (and Cycles when asked), written as an HTML report; and the stability
table of hard cases × methods (:func:`stability_table`, also run by the tests; the
cases' scenes are built by :mod:`.report_cases`).

The numerics and the HTML live in :mod:`..core.report.metrics`; this module drives Blender:
precompute, per-method derive/store, offscreen drawing through the engine's
:func:`.engine.render_pixels`, Cycles, and putting the scene back as it was.

Per-frame time: the full ``render_pixels`` call (shade + draw + synchronous read-back,
so the GPU has finished) at the camera resolution without supersampling, median of
``repeats`` after one warm-up frame.  Every timed frame is *relit*: the environment is
turned to an angle not drawn before, so per-lighting caches (REFERENCE's diffuse sums,
resampled cubemaps, wavelet lighting) are rebuilt as they would be while relighting,
while per-geometry data (transfer vectors) stays warm.  The images and errors use the
F12 path (the scene's supersampling) at the scene's own lighting.
"""

from __future__ import annotations

import pathlib

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty

from .. import methods
from ..ui.operators import RUNNING, end_modal
from .measuring import default_output_dir
from .sweep import ReportRun


# ---------------------------------------------------------------------------- report


# ---------------------------------------------------------------------------- stability


# ---------------------------------------------------------------------------- operator


class PRT_OT_report(bpy.types.Operator):
    """Run every method over its budgets on this scene; write an HTML report of speed
    against error (images, error maps, plot, numbers)"""

    bl_idname = "prt.report"
    bl_label = "Speed/Error Report"
    bl_options = {"REGISTER"}

    directory: StringProperty(name="Output Folder", subtype="DIR_PATH", default="",
                              description="Where index.html and its images go (empty: "
                                          "//prt_report next to the .blend, or a temp folder)")
    repeats: IntProperty(name="Repeats", default=5, min=1, max=100,
                         description="Frames timed per method and budget (median)")
    include_cycles: BoolProperty(name="Compare with Cycles", default=False,
                                 description="Also render the camera with Cycles (direct "
                                             "light) and measure every method against it")
    cycles_samples: IntProperty(name="Cycles Samples", default=64, min=1, max=65536)
    stability: BoolProperty(name="Stability Table", default=True,
                            description="Run the hard cases through every method")
    methods: StringProperty(name="Methods", default="",
                            description="Comma-separated method ids to include (empty: "
                                        "every registered method)")

    _timer = None
    _gen = None
    _run = None

    @classmethod
    def poll(cls, context):
        if RUNNING:
            cls.poll_message_set("A precompute is running")
            return False
        return True

    def _make_run(self, context):
        out = pathlib.Path(bpy.path.abspath(self.directory)) if self.directory \
            else default_output_dir()
        ids = {x.strip() for x in self.methods.split(",") if x.strip()} or None
        if ids is not None:
            ids.add("REFERENCE")                 # the yardstick is always measured
        return ReportRun(context.scene, out, repeats=self.repeats,
                         include_cycles=self.include_cycles,
                         cycles_samples=self.cycles_samples, stability=self.stability,
                         method_ids=ids)

    def _unknown_methods(self) -> list:
        ids = [x.strip() for x in self.methods.split(",") if x.strip()]
        return [x for x in ids if x not in methods.REGISTRY]

    def _refuse_unknown(self) -> bool:
        unknown = self._unknown_methods()
        if unknown:
            self.report({"ERROR"}, "PRT report: unknown method(s) " + ", ".join(unknown)
                        + "; known: " + ", ".join(methods.REGISTRY))
        return bool(unknown)

    def execute(self, context):
        if self._refuse_unknown():
            return {"CANCELLED"}
        run = self._make_run(context)
        try:
            index = run.run()
        except Exception as exc:
            self.report({"ERROR"}, f"PRT report failed: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"PRT report written to {index}")
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if self._refuse_unknown():
            return {"CANCELLED"}
        self._run = self._make_run(context)
        self._gen = self._run.steps()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.05, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _end(self, context):
        end_modal(self, context)

    def modal(self, context, event):
        if event.type == "ESC":
            self._gen.close()                   # staging removed, scene restored
            self._end(context)
            self.report({"WARNING"}, "PRT report cancelled; nothing was written")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        run = self._run
        try:
            step = next(self._gen)
        except StopIteration:
            self._end(context)
            self.report({"INFO"}, f"PRT report written to {run.index}")
            return {"FINISHED"}
        except Exception as exc:
            self._end(context)
            self.report({"ERROR"}, f"PRT report failed: {exc}")
            return {"CANCELLED"}
        total = max(run.steps_total, 1)
        context.window_manager.progress_update(int(100 * run.steps_done / total))
        context.workspace.status_text_set(
            f"PRT report {run.steps_done}/{total}: {step} (ESC to cancel)")
        return {"RUNNING_MODAL"}


CLASSES = (PRT_OT_report,)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
