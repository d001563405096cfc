"""The speed/error sweep of prt.report: every method and budget on the scene (precompute, F12
and relit frame times, stored bytes, error against REFERENCE and Cycles), written as an HTML
report."""

from __future__ import annotations

import copy
import math
import pathlib
import shutil
import statistics
import time
import uuid

import bpy
import numpy as np

from ...core.report import metrics as core_report
from ...core.scene import visibility
from .. import methods
from ..blender import precompute, storage
from ..frame import relit
from ..frame.state import FrameState
from ..gpu.drawing import ensure_gpu
from .measuring import (
    clear_objects,
    configure,
    gpu_name,
    restore_settings,
    settings_snapshot,
    camera_matrices,
    render_cycles,
    sweep,
    write_png,
)
from .stability import stability_table


class ReportRun:
    """The report as a generator of progress steps, so the operator can run it from a
    timer in the UI (one step per event, ESC between steps) or drain it in ``-b``.

    Everything is written into a staging folder that replaces ``out_dir``'s report files
    only at the end; closing the generator early (cancel, error) removes the staging
    folder and restores the scene's method, settings and stored data.
    """

    def __init__(self, scene, out_dir, repeats=5, include_cycles=False, cycles_samples=64,
                 stability=False, stability_resolution=16, method_ids=None, title=None,
                 budgets_per_method=None):
        self.scene = scene
        self.out_dir = pathlib.Path(out_dir)
        self.repeats = max(1, int(repeats))
        self.include_cycles = include_cycles
        self.cycles_samples = cycles_samples
        self.stability = stability
        self.stability_resolution = stability_resolution
        self.method_ids = method_ids
        self.budgets_per_method = budgets_per_method
        self.title = title
        self.rows: list = []
        self.method_rows: list = []
        self.auto_rows: list = []
        #: AUTO against the fastest fixed method meeting its target, timed interleaved
        self.auto_check: dict | None = None
        self.warnings: list = []
        self.index: pathlib.Path | None = None
        self._has_auto = any(m.id == "AUTO" for m, _, _ in sweep(method_ids, budgets_per_method))
        self.steps_total = (len(sweep(method_ids, budgets_per_method)) + 3 + int(self._has_auto)
                            + int(include_cycles) + int(stability))
        self.steps_done = 0

    # -------------------------------------------------------------- helpers
    def _frame(self, depsgraph, view, projection, w, h, persp, supersampling, filter_width):
        from ..frame.engine import render_pixels
        state = FrameState()
        state.sync(depsgraph)
        img = render_pixels(state, view, projection, w, h, True, persp, supersampling,
                            filter_width, depsgraph.scene.prt.aa_threshold)
        return state, img[::-1].copy()

    def _time_frames(self, state, view, projection, w, h, persp):
        """Relit frames: each one turns the environment to an angle not drawn before,
        so nothing cached per lighting is reused (what PRT is for); the camera stays."""
        return self._relit_times([state], self.repeats, view, projection, w, h, persp)[0]

    def _relit_times(self, states, rounds, view, projection, w, h, persp):
        """Seconds of ``rounds`` relit frames per state (:func:`.relit.relit_times`: a
        warm-up round first; several states interleaved, the AUTO check): the full
        ``render_pixels`` call at the camera's view."""
        from ..frame.engine import render_pixels
        return relit.relit_times(
            states, lambda st: render_pixels(st, view, projection, w, h, True, persp, 1),
            rounds)

    def _auto_check(self, auto_state, target, view, projection, w, h, persp):
        """AUTO against the fastest fixed method/budget that meets AUTO's target: the
        sweep's fastest few within 2x of each other (``core.report.metrics.fastest_candidates``)
        are timed again interleaved with AUTO (:meth:`_relit_times`) with the stored data
        AUTO set up (a fixed method reads the same stored data, with its budget as the
        setting), and the fastest of them by median is the one compared."""
        candidates = core_report.fastest_candidates(
            [r for r in self.rows if r["method"] != "AUTO"], target)
        auto_row = next((r for r in self.rows if r["method"] == "AUTO"), None)
        if not candidates or auto_row is None:
            return None
        states = []
        for fixed in candidates:
            method = methods.get(fixed["method"])
            other = copy.copy(auto_state)
            other.method = method.id
            other.settings = dict(auto_state.settings)
            if method.bench.budget and fixed["label"]:
                prop = method.bench.budget[0]
                other.settings[prop] = type(getattr(self.scene.prt, prop))(fixed["label"])
            states.append(other)
        times = self._relit_times([auto_state] + states, 3 * self.repeats, view, projection,
                                  w, h, persp)
        a = statistics.median(times[0])
        medians = [statistics.median(t) for t in times[1:]]
        k = int(np.argmin(medians))
        fixed, f = candidates[k], medians[k]
        label = lambda r: f"{r['method']} {r['budget']}".strip()       # noqa: E731
        return dict(target=target, fixed=label(fixed),
                    fixed_error=fixed.get("error_ref"), auto_error=auto_row.get("error_ref"),
                    auto_seconds=a, fixed_seconds=f, ratio=f / a if a > 0 else math.nan,
                    rounds=len(times[0]),
                    candidates=[f"{label(r)} {1e3 * m:.2f} ms" for r, m in zip(candidates, medians)])

    # -------------------------------------------------------------- steps
    def steps(self):
        scene = self.scene
        if scene.camera is None:
            raise RuntimeError("The scene has no camera: the report renders its view")
        if not visibility.have_embree():
            raise RuntimeError("The report needs embreex for the precompute")
        saved = settings_snapshot(scene)
        saved_report = scene.prt.last_report
        images_before = {img.name for img in bpy.data.images}
        staging = self.out_dir.parent / f".{self.out_dir.name}.partial-{uuid.uuid4().hex[:8]}"
        staging.mkdir(parents=True, exist_ok=False)
        job = None
        had_data = False
        finished = False
        try:
            ensure_gpu(scene)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            yield "precompute (visibility)"
            scene.prt.method = "REFERENCE"
            job = precompute.gather(depsgraph, scene.prt)
            had_data = all(storage.has(storage.owner(o.name), storage.VISIBILITY)
                           for o in job.objects)
            t0 = time.perf_counter()
            job.run()
            trace_seconds = time.perf_counter() - t0
            precompute.commit(scene, job)
            vis_bytes = sum(len(o.blob) for o in job.objects)
            self.warnings += job.warnings
            self.steps_done += 1

            r = scene.render
            w = max(1, int(r.resolution_x * r.resolution_percentage / 100))
            h = max(1, int(r.resolution_y * r.resolution_percentage / 100))
            ss = int(scene.prt.supersampling)
            ref_img = None
            images = {}
            per_method = {}
            auto_frame = None
            for method, prop, value in sweep(self.method_ids, self.budgets_per_method):
                label = "" if prop is None else f"{prop}={value}"
                yield f"{method.id} {label}".strip()
                derive_s, derived_bytes = configure(scene, job, method, prop, value)
                depsgraph = bpy.context.evaluated_depsgraph_get()
                view, projection, persp = camera_matrices(scene, depsgraph, w, h)
                notes = ""
                try:
                    state, img = self._frame(depsgraph, view, projection, w, h, persp, ss,
                                             r.filter_size)
                    times = self._time_frames(state, view, projection, w, h, persp)
                    notes = "; ".join(([state.error] if state.error else []) + [
                        x for x in state.warnings if "Not precomputed" not in x])
                except Exception as exc:       # a broken method is reported, not fatal
                    img, times, notes = None, [], f"failed: {exc}"
                row = dict(method=method.id, label=str(value) if prop else "",
                           budget=label, frame_times=times,
                           frame_seconds=statistics.median(times) if times else math.nan,
                           notes=notes)
                if method.id == "REFERENCE" and ref_img is None:
                    ref_img = img
                if img is not None and ref_img is not None:
                    row["error_ref"] = core_report.rel_l2(img, ref_img)
                    row["psnr_ref"] = core_report.psnr(img, ref_img)
                    images[len(self.rows)] = img
                self.rows.append(row)
                if method.id == "AUTO" and img is not None:
                    self.auto_rows = list(method.bench.last_choices())
                    auto_frame = (state, view, projection, persp)
                pm = per_method.setdefault(method.id, dict(
                    id=method.id, label=method.label, precompute_seconds=trace_seconds,
                    storage_bytes=vis_bytes, derive=[]))
                if method.derives:
                    pm["derive"].append((label, derive_s, derived_bytes))
                self.steps_done += 1

            if self._has_auto:
                yield "AUTO against the fastest fixed method (interleaved frames)"
                if auto_frame is not None:
                    st_auto, view, projection, persp = auto_frame
                    self.auto_check = self._auto_check(
                        st_auto, float(scene.prt.auto_error_target), view, projection, w, h,
                        persp)
                self.steps_done += 1

            cycles_img = None
            if self.include_cycles:
                yield "Cycles"
                cycles_img = render_cycles(scene, staging / "cycles.exr", self.cycles_samples)
                for i, img in images.items():
                    self.rows[i]["error_cycles"] = core_report.rel_l2(img, cycles_img)
                    self.rows[i]["psnr_cycles"] = core_report.psnr(img, cycles_img)
                self.steps_done += 1

            stability = None
            if self.stability:
                yield "stability cases"
                stability = stability_table(resolution=self.stability_resolution,
                                            method_ids=self.method_ids)
                self.steps_done += 1

            yield "writing images"
            exposure = core_report.exposure_for(ref_img) if ref_img is not None else 1.0
            heat_max = 0.2
            mask = core_report.coverage_mask(ref_img) if ref_img is not None else None
            ref_name = None
            if ref_img is not None:
                ref_name = "reference.png"
                write_png(staging / ref_name,
                                      core_report.display_rgb(ref_img, exposure))
            cycles_name = None
            if cycles_img is not None:
                cycles_name = "cycles.png"
                write_png(staging / cycles_name,
                                      core_report.display_rgb(cycles_img, exposure))
            for i, img in images.items():
                row = self.rows[i]
                stem = "".join(c if c.isalnum() else "_" for c in
                               f"{row['method']}_{row['label']}".lower()).strip("_")
                row["image"] = f"{stem}.png"
                write_png(staging / row["image"],
                                      core_report.display_rgb(img, exposure))
                row["heatmap"] = f"{stem}_error.png"
                write_png(staging / row["heatmap"], core_report.heatmap_rgb(
                    core_report.error_map(img, ref_img, mask), heat_max, mask))
            for pm in per_method.values():
                derive = pm.pop("derive")
                if derive:
                    pm["precompute_seconds"] += max(d[1] for d in derive)
                    pm["storage_bytes"] += max(d[2] for d in derive)
                    pm["notes"] = "visibility trace + derive (" + ", ".join(
                        f"{lbl or 'default'}: {s:.2f} s" for lbl, s, _ in derive) + ")"
                else:
                    pm["notes"] = "visibility trace only (shares the stored visibility)"
                self.method_rows.append(pm)
            self.steps_done += 1

            points = job.point_count
            report = dict(
                title=self.title or "PRT report: " + (
                    bpy.path.display_name(bpy.data.filepath) or scene.name),
                scene=[("scene", scene.name), ("objects", len(job.objects)),
                       ("shading points", points), ("directions", f"6×{job.resolution}²"),
                       ("camera", f"{w}×{h}"), ("F12 supersampling", ss),
                       ("pixel filter", f"Blackman-Harris {r.filter_size:g} px" if ss > 1
                        and r.filter_size > 0 else "box"),
                       ("timing", f"render_pixels at {w}×{h}, median of {self.repeats}"),
                       ("machine GPU", gpu_name())],
                rows=self.rows, reference_image=ref_name, cycles_image=cycles_name,
                cycles_note=f"{self.cycles_samples} spp, direct light" if cycles_name else "",
                heat_max=heat_max, methods=self.method_rows, auto=self.auto_rows,
                auto_check=self.auto_check,
                stability=stability, warnings=self.warnings)
            core_report.write_html(staging / "index.html", report)
            (staging / "speed_error.svg").write_text(core_report.speed_error_svg(
                self.rows, title="Per-frame time vs rel-L2 error against REFERENCE"),
                encoding="utf-8")
            self.out_dir.mkdir(parents=True, exist_ok=True)
            for f in staging.iterdir():
                shutil.move(str(f), str(self.out_dir / f.name))
            self.index = self.out_dir / "index.html"
            self.report = report
            finished = True
            self.steps_done += 1
        finally:
            shutil.rmtree(staging, ignore_errors=True)
            restore_settings(scene, saved)
            if job is not None:
                try:
                    if had_data:
                        method = methods.get(saved.get("method", "REFERENCE"))
                        if any(m.derives for m, _, _ in sweep(self.method_ids)):
                            configure(scene, job, method, None, None)
                            if not method.derives:
                                job.method = method.id
                                job.derived = None
                                precompute.commit(scene, job)
                    else:
                        clear_objects(job)
                    # data other methods stored during the sweep under new names
                    for img in [i for i in bpy.data.images if i.name not in images_before
                                and i.type != "RENDER_RESULT"]:
                        bpy.data.images.remove(img)
                except Exception as exc:      # never hide the report's own outcome
                    print("PRT report: could not restore stored data:", exc)
                restore_settings(scene, saved)
                scene.prt.last_report = saved_report
            if not finished:
                self.index = None

    def run(self):
        for _ in self.steps():
            pass
        return self.index
