"""``prt.report``: every registered method over a sweep of its budget, timed and measured
against REFERENCE (and Cycles when asked), written as an HTML report; and the stability
table of hard cases × methods (:func:`stability_table`, also run by the tests; the
cases' scenes are built by :mod:`.report_cases`).

The numerics and the HTML live in :mod:`..core.report`; this module drives Blender:
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

import copy
import math
import pathlib
import shutil
import statistics
import tempfile
import time
import uuid

import bpy
import numpy as np
from bpy.props import BoolProperty, IntProperty, StringProperty

from ..core import report as core_report
from ..core import visibility
from . import methods, precompute, relit, report_cases, scene_export, storage
from .drawing import ensure_gpu
from .operators import RUNNING, end_modal
from .runtime import FrameState

def sweep(method_ids=None, budgets_per_method=None):
    """(method, budget property or None, value or None) for every registered method and
    budget value, REFERENCE first (the yardstick).  ``budgets_per_method``: keep that
    many values of each sweep, evenly spread, first and last included."""
    out = []
    for m in methods.REGISTRY.values():
        if method_ids is not None and m.id not in method_ids:
            continue
        prop, values = m.budget if m.budget else (None, [None])
        values = list(values)
        n = budgets_per_method
        if n is not None and 0 < n < len(values):
            pick = sorted({round(i * (len(values) - 1) / max(n - 1, 1)) for i in range(n)})
            values = [values[i] for i in pick]
        out += [(m, prop, v) for v in values]
    out.sort(key=lambda row: row[0].id != "REFERENCE")
    return out


def has_derive(method) -> bool:
    return type(method).derive is not methods.Method.derive


def data_nbytes(obj) -> int:
    """Bytes of the numpy arrays in ``obj`` (nested lists/tuples/dicts/objects)."""
    seen = set()

    def walk(o):
        if id(o) in seen:
            return 0
        seen.add(id(o))
        if isinstance(o, np.ndarray):
            return o.nbytes
        if isinstance(o, (bytes, bytearray)):
            return len(o)
        if isinstance(o, dict):
            return sum(walk(v) for v in o.values())
        if isinstance(o, (list, tuple, set)):
            return sum(walk(v) for v in o)
        if hasattr(o, "__dict__"):
            return walk(vars(o))
        if hasattr(o, "__slots__"):
            return sum(walk(getattr(o, s, None)) for s in o.__slots__)
        return 0
    return walk(obj)


def _camera_matrices(scene, depsgraph, width, height):
    cam = scene.camera.evaluated_get(depsgraph)
    r = scene.render
    projection = cam.calc_matrix_camera(depsgraph, x=width, y=height,
                                        scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y)
    return cam.matrix_world.normalized().inverted(), projection, cam.data.type != "ORTHO"


def _settings_snapshot(scene):
    prt = scene.prt
    names = ["method"] + list(methods.scene_properties())
    return {n: getattr(prt, n) for n in names if hasattr(prt, n)}


def _restore_settings(scene, saved):
    for name, value in saved.items():
        try:
            setattr(scene.prt, name, value)
        except (TypeError, AttributeError, ValueError):
            pass


def _configure(scene, job, method, prop, value):
    """Make ``method`` (with ``prop = value``) the scene's method; derive and store its
    data when it has any.  Returns (derive seconds, derived bytes)."""
    scene.prt.method = method.id
    if prop is not None:
        setattr(scene.prt, prop, value)
    if not has_derive(method) or job is None:
        return 0.0, 0
    job.method = method.id
    job.settings = {n: getattr(scene.prt, n) for n in methods.scene_properties()}
    t0 = time.perf_counter()
    job.derived = method.derive(job)
    seconds = time.perf_counter() - t0
    precompute.commit(scene, job)
    return seconds, data_nbytes(job.derived)


def _read_exr_pixels(path) -> np.ndarray:
    """(H, W, 4) float32 top row first of an EXR, through Blender's image loader."""
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, 4)[::-1].copy()
    finally:
        bpy.data.images.remove(img)


def render_cycles(scene, path, samples: int) -> np.ndarray:
    """Direct-light Cycles render of the scene camera (film transparent), saved to
    ``path`` (EXR); the scene's render settings are put back afterwards."""
    r = scene.render
    cy = scene.cycles
    saved_r = {k: getattr(r, k) for k in ("engine", "film_transparent")}
    saved_fmt = {k: getattr(r.image_settings, k) for k in ("file_format", "color_depth",
                                                           "color_mode")}
    saved_c = {k: getattr(cy, k) for k in ("device", "samples", "max_bounces", "use_denoising",
                                           "use_adaptive_sampling", "seed")}
    try:
        r.engine = "CYCLES"
        r.film_transparent = True
        cy.device = "CPU"
        cy.samples = int(samples)
        cy.max_bounces = 0
        cy.use_denoising = False
        cy.use_adaptive_sampling = False
        cy.seed = 0
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render()
        r.image_settings.file_format = "OPEN_EXR"
        r.image_settings.color_depth = "32"
        r.image_settings.color_mode = "RGBA"
        bpy.data.images["Render Result"].save_render(str(path), scene=scene)
    finally:
        for k, v in saved_c.items():
            setattr(cy, k, v)
        for k, v in saved_fmt.items():
            setattr(r.image_settings, k, v)
        for k, v in saved_r.items():
            setattr(r, k, v)
    return _read_exr_pixels(path)


def write_png(path, rgb: np.ndarray):
    """An 8-bit PNG of uint8 RGB/RGBA (H, W, 3|4), top row first: ``core.report.write_png``
    (OpenImageIO), or Blender's image API where OpenImageIO is missing (Blender 4.2)."""
    if core_report.have_openimageio():
        core_report.write_png(path, rgb)
        return
    px = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, c = px.shape
    img = bpy.data.images.new("PRT report PNG", w, h, alpha=c == 4)
    try:
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :c] = px / np.float32(255.0)
        img.pixels.foreach_set(rgba[::-1].reshape(-1))       # Blender: bottom row first
        img.filepath_raw = str(path)
        img.file_format = "PNG"
        img.save()
    finally:
        bpy.data.images.remove(img)


def default_output_dir() -> pathlib.Path:
    if bpy.data.filepath:
        return pathlib.Path(bpy.path.abspath("//prt_report"))
    return pathlib.Path(tempfile.gettempdir()) / "prt_report"


# ---------------------------------------------------------------------------- report


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
        from .engine import render_pixels
        state = FrameState()
        state.sync(depsgraph)
        img = render_pixels(state, view, projection, w, h, True, persp, supersampling,
                            filter_width)
        return state, img[::-1].copy()

    def _time_frames(self, state, view, projection, w, h, persp):
        """Relit frames: each one turns the environment to an angle not drawn before,
        so nothing cached per lighting is reused (what PRT is for); the camera stays."""
        return self._relit_times([state], self.repeats, view, projection, w, h, persp)[0]

    def _relit_times(self, states, rounds, view, projection, w, h, persp):
        """Seconds of ``rounds`` relit frames per state (:func:`.relit.relit_times`: a
        warm-up round first; several states interleaved, the AUTO check): the full
        ``render_pixels`` call at the camera's view."""
        from .engine import render_pixels
        return relit.relit_times(
            states, lambda st: render_pixels(st, view, projection, w, h, True, persp, 1),
            rounds)

    def _auto_check(self, auto_state, target, view, projection, w, h, persp):
        """AUTO against the fastest fixed method/budget that meets AUTO's target: the
        sweep's fastest few within 2x of each other (``core.report.fastest_candidates``)
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
            if method.budget and fixed["label"]:
                prop = method.budget[0]
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
        saved = _settings_snapshot(scene)
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
            had_data = all(storage.has(bpy.data.objects[o.name], storage.VISIBILITY)
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
                derive_s, derived_bytes = _configure(scene, job, method, prop, value)
                depsgraph = bpy.context.evaluated_depsgraph_get()
                view, projection, persp = _camera_matrices(scene, depsgraph, w, h)
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
                    self.auto_rows = list(method.last_choices())
                    auto_frame = (state, view, projection, persp)
                pm = per_method.setdefault(method.id, dict(
                    id=method.id, label=method.label, precompute_seconds=trace_seconds,
                    storage_bytes=vis_bytes, derive=[]))
                if has_derive(method):
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
                       ("machine GPU", _gpu_name())],
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
            _restore_settings(scene, saved)
            if job is not None:
                try:
                    if had_data:
                        method = methods.get(saved.get("method", "REFERENCE"))
                        if any(has_derive(m) for m, _, _ in sweep(self.method_ids)):
                            _configure(scene, job, method, None, None)
                            if not has_derive(method):
                                job.method = method.id
                                job.derived = None
                                precompute.commit(scene, job)
                    else:
                        _clear_objects(job)
                    # data other methods stored during the sweep under new names
                    for img in [i for i in bpy.data.images if i.name not in images_before
                                and i.type != "RENDER_RESULT"]:
                        bpy.data.images.remove(img)
                except Exception as exc:      # never hide the report's own outcome
                    print("PRT report: could not restore stored data:", exc)
                _restore_settings(scene, saved)
                scene.prt.last_report = saved_report
            if not finished:
                self.index = None

    def run(self):
        for _ in self.steps():
            pass
        return self.index


def _gpu_name() -> str:
    try:
        import gpu
        return f"{gpu.platform.renderer_get()}"
    except Exception:
        return "unknown"


def _clear_objects(job):
    """Remove the data the report's precompute stored on objects that had none."""
    for o in job.objects:
        ob = bpy.data.objects.get(o.name)
        if ob is not None:
            storage.clear_object(ob)


# ---------------------------------------------------------------------------- stability

def _flat(radiance_per_object):
    if not radiance_per_object:
        return np.zeros((0, 3), np.float32)
    return np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 3)
                           for r in radiance_per_object])


def _facing_corners(state, eye, count):
    """(C,) bool over the concatenated corners of ``state.objects`` (``_flat``'s order):
    the corners compared.  A closed mesh's corner whose normal turns away from ``eye`` is
    its inner side, drawn black (``core.mesh.closed_side``), so its view-dependent value
    is left out; an open mesh shows its corners from both sides, so all count.  None when
    the corners do not line up with ``count`` values."""
    eye = np.asarray(eye, dtype=np.float64)
    parts = []
    for st in state.objects:
        a = st.arrays
        if not getattr(st, "closed_side", 0):
            parts.append(np.ones(len(a.corner_verts), bool))
            continue
        p = np.asarray(a.positions, np.float64)[a.corner_verts]
        parts.append(((eye - p) * np.asarray(a.corner_normals, np.float64)).sum(axis=1) > 0.0)
    mask = np.concatenate(parts) if parts else np.zeros(0, bool)
    return mask if len(mask) == count else None


def _new_datablocks(before):
    collections = ("objects", "meshes", "materials", "worlds", "images", "cameras")
    return {c: [d for d in getattr(bpy.data, c) if d not in before[c]] for c in collections}


def _run_case(case, method_list, resolution, progress=None):
    """One case in a temporary scene: precompute, then every method's ``shade`` (or its
    drawn pixels when ``shade`` returns None) against REFERENCE's."""
    collections = ("objects", "meshes", "materials", "worlds", "images", "cameras")
    before = {c: set(getattr(bpy.data, c)) for c in collections}
    scene = bpy.data.scenes.new("PRT Stability")
    cells = {}
    try:
        setup = case["build"](scene)
        eye = setup["eye"]
        view_layer = scene.view_layers[0]
        scene.prt.resolution = "32"
        # the methods' own numerics under the whole world: no source drawn per pixel instead
        scene.prt.light_sources = 0
        with bpy.context.temp_override(scene=scene, view_layer=view_layer):
            depsgraph = bpy.context.evaluated_depsgraph_get()
        message = ""
        job = None
        try:
            settings = _SettingsProxy(scene.prt, resolution=resolution, method="REFERENCE")
            job = precompute.gather(depsgraph, settings)
            job.run()
            precompute.commit(scene, job)
        except scene_export.ExportError as exc:
            message = str(exc)
        ref = None
        ref_pixels = None
        for m in method_list:
            try:
                if job is not None:
                    _configure(scene, job, m, None, None)
                else:
                    scene.prt.method = m.id
                state = FrameState()
                state.sync(depsgraph)
                out = state.shade(eye)
                pixels = None
                if out is None:
                    pixels = _stability_pixels(scene, depsgraph, state)
                    values = pixels[..., :3].reshape(-1, 3).astype(np.float64)
                else:
                    values = _flat(out)
                finite = bool(np.isfinite(values).all()) and (
                    pixels is None or bool(np.isfinite(pixels).all()))
                if m.id == "REFERENCE":
                    ref = values
                    ref_pixels = None
                msg = state.error or message
                refused_ok = None
                if "expect_error" in case:
                    refused_ok = case["expect_error"] in (msg or "")
                    if not refused_ok:
                        msg = f"expected a '{case['expect_error']}' error; got: {msg or 'none'}"
                if pixels is not None:
                    if ref_pixels is None:
                        saved = scene.prt.method
                        scene.prt.method = "REFERENCE"
                        rs = FrameState()
                        rs.sync(depsgraph)
                        ref_pixels = _stability_pixels(scene, depsgraph, rs)
                        scene.prt.method = saved
                    err = core_report.rel_l2(pixels, ref_pixels)
                elif ref is not None:
                    facing = _facing_corners(state, eye, len(ref))
                    if facing is None:
                        facing = np.ones(len(ref), bool)
                    err = core_report.rel_l2(values[:, None, :], ref[:, None, :],
                                             mask=facing[:, None])
                else:
                    err = None
                cells[m.id] = dict(finite=finite, error=err, message=msg, refused_ok=refused_ok,
                                   max=float(np.nanmax(np.abs(values))) if values.size else 0.0)
            except Exception as exc:
                cells[m.id] = dict(finite=False, error=None, message=f"failed: {exc!r}")
            if progress is not None:
                progress(case["name"], m.id)
    finally:
        bpy.data.scenes.remove(scene)
        for c, items in _new_datablocks(before).items():
            coll = getattr(bpy.data, c)
            for d in items:
                try:
                    coll.remove(d)
                except (ReferenceError, RuntimeError):
                    pass
    return cells


def _stability_pixels(scene, depsgraph, state):
    from .engine import render_pixels
    ensure_gpu(bpy.context.scene)
    w, h = scene.render.resolution_x, scene.render.resolution_y
    view, projection, persp = _camera_matrices(scene, depsgraph, w, h)
    return render_pixels(state, view, projection, w, h, True, persp, 1)


class _SettingsProxy:
    """``scene.prt`` with a few values replaced (e.g. a 6×16² cubemap for tiny cases)."""

    def __init__(self, prt, **override):
        self._prt = prt
        self._override = override

    def __getattr__(self, name):
        if name in self._override:
            return self._override[name]
        return getattr(self._prt, name)


def stability_table(resolution=16, method_ids=None, cases=None, progress=None) -> dict:
    """Every hard case × every registered method (REFERENCE first):
    ``{"methods": [ids], "cases": [{"name", "description", "cells": {id: {"finite",
    "error" (rel-L2 vs REFERENCE of the per-corner radiance at the corners the eye can
    see the outer side of (:func:`_facing_corners`), or of pixels for per-pixel
    methods), "message", "max", "bound" (:func:`.report_cases.error_bound`), "within"
    (error <= bound; None without a bound)}}}]}``.  Runs in temporary scenes removed
    afterwards; the open scene is not touched."""
    method_list = [m for m, _, _ in sweep(method_ids)]
    seen = set()
    method_list = [m for m in method_list if not (m.id in seen or seen.add(m.id))]
    table = dict(methods=[m.id for m in method_list], cases=[])
    for case in (cases if cases is not None else report_cases.stability_cases(method_ids)):
        cells = _run_case(case, method_list, resolution, progress)
        for mid, cell in cells.items():
            bound = report_cases.error_bound(case["name"], mid)
            err = cell.get("error")
            cell["bound"] = bound
            cell["within"] = None if bound is None else (
                err is not None and bool(np.isfinite(err)) and err <= bound)
        table["cases"].append(dict(name=case["name"], description=case.get("description", ""),
                                   cells=cells))
    return table


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
