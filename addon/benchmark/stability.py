"""The stability table of prt.report: every method on every hard case (open sky, full
occlusion, a one-pixel sun, a black world, bad pixels, a mirror, grazing light), each cell's
error against REFERENCE within its method's bound and finite."""

from __future__ import annotations

import bpy
import numpy as np

from ...core.report import metrics as core_report
from ..blender import precompute, scene_export
from ..frame.state import FrameState
from ..gpu.drawing import ensure_gpu
from . import cases as report_cases
from .measuring import configure, flat_radiance, camera_matrices, sweep


def facing_corners(state, eye, count):
    """(C,) bool over the concatenated corners of ``state.objects`` (``flat_radiance``'s order):
    the corners compared.  A closed mesh's corner whose normal turns away from ``eye`` is
    its inner side, drawn black (``core.scene.mesh.closed_side``), so its view-dependent value
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
                    configure(scene, job, m, None, None)
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
                    values = flat_radiance(out)
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
                    facing = facing_corners(state, eye, len(ref))
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
    from ..frame.engine import render_pixels
    ensure_gpu(bpy.context.scene)
    w, h = scene.render.resolution_x, scene.render.resolution_y
    view, projection, persp = camera_matrices(scene, depsgraph, w, h)
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
    see the outer side of (:func:`facing_corners`), or of pixels for per-pixel
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
