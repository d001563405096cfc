"""What a prt.report run does to a scene: the methods and budgets swept, each configured and
derived in turn, the scene's settings saved and restored, Cycles' frame rendered and read,
images written, bytes counted."""

from __future__ import annotations

import pathlib
import tempfile
import time

import bpy
import numpy as np

from ...core.report import metrics as core_report
from .. import methods
from ..blender import precompute, storage


def sweep(method_ids=None, budgets_per_method=None):
    """(method, budget property or None, value or None) for every registered method and
    budget value, REFERENCE first (the yardstick).  ``budgets_per_method``: keep that
    many values of each sweep, evenly spread, first and last included."""
    out = []
    for m in methods.REGISTRY.values():
        if method_ids is not None and m.id not in method_ids:
            continue
        prop, values = m.bench.budget if m.bench.budget else (None, [None])
        values = list(values)
        n = budgets_per_method
        if n is not None and 0 < n < len(values):
            pick = sorted({round(i * (len(values) - 1) / max(n - 1, 1)) for i in range(n)})
            values = [values[i] for i in pick]
        out += [(m, prop, v) for v in values]
    out.sort(key=lambda row: row[0].id != "REFERENCE")
    return out


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


def camera_matrices(scene, depsgraph, width, height):
    cam = scene.camera.evaluated_get(depsgraph)
    r = scene.render
    projection = cam.calc_matrix_camera(depsgraph, x=width, y=height,
                                        scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y)
    return cam.matrix_world.normalized().inverted(), projection, cam.data.type != "ORTHO"


def settings_snapshot(scene):
    prt = scene.prt
    names = ["method"] + list(methods.scene_properties())
    return {n: getattr(prt, n) for n in names if hasattr(prt, n)}


def restore_settings(scene, saved):
    for name, value in saved.items():
        try:
            setattr(scene.prt, name, value)
        except (TypeError, AttributeError, ValueError):
            pass


def configure(scene, job, method, prop, value):
    """Make ``method`` (with ``prop = value``) the scene's method; derive and store its
    data when it has any.  Returns (derive seconds, derived bytes)."""
    scene.prt.method = method.id
    if prop is not None:
        setattr(scene.prt, prop, value)
    if not method.derives or job is None:
        return 0.0, 0
    job.method = method.id
    job.settings = {n: getattr(scene.prt, n) for n in methods.scene_properties()}
    t0 = time.perf_counter()
    job.derived = method.shading.derive(job)
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
    """Cycles render of the scene camera (film transparent) with the scene's own Light Paths
    (0 bounces: direct light), what our frames draw too; saved to ``path`` (EXR); the
    scene's render settings are put back afterwards."""
    r = scene.render
    cy = scene.cycles
    saved_r = {k: getattr(r, k) for k in ("engine", "film_transparent")}
    saved_fmt = {k: getattr(r.image_settings, k) for k in ("file_format", "color_depth",
                                                           "color_mode")}
    saved_c = {k: getattr(cy, k) for k in ("device", "samples", "use_denoising",
                                           "use_adaptive_sampling", "seed")}
    try:
        r.engine = "CYCLES"
        r.film_transparent = True
        cy.device = "CPU"
        cy.samples = int(samples)
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
    """An 8-bit PNG of uint8 RGB/RGBA (H, W, 3|4), top row first: ``core.report.metrics.write_png``
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


def gpu_name() -> str:
    try:
        import gpu
        return f"{gpu.platform.renderer_get()}"
    except Exception:
        return "unknown"


def clear_objects(job):
    """Remove the data the report's precompute stored on objects that had none."""
    for o in job.objects:
        ob = storage.owner(o.name)
        if ob is not None:
            storage.clear_object(ob)


def flat_radiance(radiance_per_object):
    if not radiance_per_object:
        return np.zeros((0, 3), np.float32)
    return np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 3)
                           for r in radiance_per_object])
