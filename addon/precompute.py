"""Precompute in three steps: gather (main thread, reads bpy), run (pure core, any
thread, cancellable), commit (main thread, writes bpy).  Nothing in the scene
changes before commit, so an error or ESC leaves it as it was."""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field

import numpy as np

from ..core import directions, mesh as core_mesh, reference, visibility
from . import methods, scene_export, storage


@dataclass
class ObjectJob:
    name: str
    arrays: core_mesh.MeshArrays
    points: core_mesh.ShadingPoints
    fingerprint: str
    bits: np.ndarray | None = None
    #: the visibility as stored (storage.visibility_blob), made with the bits
    blob: bytes | None = None
    coarse_warning: str = ""


@dataclass
class PrecomputeJob:
    resolution: int
    offset: float
    objects: list
    occluders: np.ndarray
    warnings: list = field(default_factory=list)
    method: str = "REFERENCE"
    #: scene.prt values of every method's settings at gather time
    settings: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    #: method data from Method.derive (stored by Method.store in the commit)
    derived: object = None
    progress_done: int = 0
    progress_total: int = 0
    cancel_requested: bool = False

    @property
    def point_count(self):
        return sum(o.points.count for o in self.objects)

    # -------------------------------------------------------------- run (no bpy)
    def run(self, threads=None):
        t0 = time.perf_counter()
        scene = visibility.build_occluder_scene(self.occluders)
        t1 = time.perf_counter()
        cube = directions.cubemap(self.resolution)
        pts = np.concatenate([o.points.positions for o in self.objects])
        nrm = np.concatenate([o.points.normals for o in self.objects])
        self.progress_total = len(pts)

        def progress(done, total):
            self.progress_done = done

        stats = {}
        bits = visibility.trace_visibility(scene, pts, nrm, cube, self.offset, threads=threads,
                                           progress=progress, cancel=lambda: self.cancel_requested,
                                           stats=stats)
        t2 = time.perf_counter()
        start = 0
        for o in self.objects:
            o.bits = bits[start:start + o.points.count]
            start += o.points.count
            o.coarse_warning = coarse_receiver_warning(o, cube)
        t3 = time.perf_counter()
        # compressed here, off the main thread: the commit only assigns the blobs
        for o in self.objects:
            o.blob = storage.visibility_blob(o.bits, self.resolution)
        t4 = time.perf_counter()
        self.timings.update(build_bvh=t1 - t0, rays=t2 - t1, ray_count=stats["rays"],
                            rays_per_second=stats["rays"] / max(t2 - t1, 1e-9),
                            tessellation_check=t3 - t2, encode=t4 - t3)
        self.derived = methods.get(self.method).derive(self)
        self.timings["derive"] = time.perf_counter() - t4


def coarse_receiver_warning(job: ObjectJob, cube) -> str:
    """A note when shadows change faster than the tessellation can show.

    When more than 5 % of the mesh's edges join points whose sky visibility differs by
    over a quarter (:func:`core.reference.coarse_edge_share`), per-vertex shading blurs
    or aliases the shadows.
    """
    frac = reference.coarse_edge_share(job.bits, job.points.normals, job.points.point_of_corner,
                                       job.arrays.triangles, cube)
    if frac > reference.COARSE_SHARE:
        return (f"'{job.name}' is too coarse for its shadows ({frac:.0%} of edges jump by more "
                "than a quarter of the sky): subdivide it for sharper per-vertex shadows")
    return ""


def gather(depsgraph, settings) -> PrecomputeJob:
    """Read the scene into a job (raises scene_export.ExportError for bad input)."""
    scene = depsgraph.scene
    warnings = []
    scene_export.export_world(scene, warnings)       # validate lighting early
    objects = []
    tri_blocks = []
    empty = []
    skipped = []
    hidden = scene_export.hidden_in_viewport(depsgraph.view_layer, depsgraph)
    if hidden:
        warnings.append("Hidden in the viewport but shown in renders, so not traced (their "
                        "shadows are missing; unhide them to precompute): " + ", ".join(hidden))
    for ob in scene_export.visible_mesh_objects(depsgraph, skipped):
        arrays = scene_export.mesh_arrays(ob)
        if not np.isfinite(arrays.positions).all():
            raise scene_export.ExportError(f"Object '{ob.name}' has non-finite vertex positions")
        if len(arrays.triangles) == 0:
            empty.append(ob.original.name)
            continue
        fixed = core_mesh.repair_normals(arrays)
        occluders, degenerate = core_mesh.occluder_triangles(arrays)
        if degenerate:
            warnings.append(f"'{ob.original.name}': {degenerate} zero-area face(s) ignored as "
                            "occluders")
        elif fixed:
            warnings.append(f"'{ob.original.name}': {fixed} corner normal(s) repaired")
        points = core_mesh.shading_points(arrays)
        objects.append(ObjectJob(ob.original.name, arrays, points, core_mesh.fingerprint(arrays)))
        tri_blocks.append(occluders)
    if empty:
        warnings.append("Skipped mesh(es) without faces: " + ", ".join(empty))
    warnings += scene_export.instance_warning(skipped)
    if not objects:
        raise scene_export.ExportError("Nothing to precompute: no visible mesh object has faces")
    occluders = np.concatenate(tri_blocks)
    diag = core_mesh.bounding_diagonal(occluders.reshape(-1, 3))
    offset = float(settings.ray_offset) * max(diag, 1e-6)
    return PrecomputeJob(int(settings.resolution), offset, objects, occluders, warnings,
                         method=settings.method, settings={
                             name: getattr(settings, name)
                             for name in methods.scene_properties()})


def commit(scene, job: PrecomputeJob):
    """Store the job's results in the .blend (main thread)."""
    import bpy

    t0 = time.perf_counter()
    # Objects deleted while a modal precompute ran are dropped.
    job.objects = [o for o in job.objects if o.name in bpy.data.objects]
    # Every blob was made in run(): from here on only assignments change the scene.
    if any(o.blob is None for o in job.objects):
        raise RuntimeError("precompute commit without run(): nothing was traced")
    run_id = uuid.uuid4().hex
    for o in job.objects:
        ob = bpy.data.objects[o.name]
        ob.prt.resolution = job.resolution
        ob.prt.point_count = o.points.count
        ob.prt.fingerprint = o.fingerprint
        ob.prt.precompute_id = run_id
        ob.prt.coarse_warning = o.coarse_warning
        # what earlier runs stored (other methods' data too) is dropped with them
        storage.replace_all(ob, {storage.VISIBILITY: o.blob})
    storage.remove_legacy()
    scene.prt.precomputed_resolution = job.resolution
    scene.prt.scene_fingerprint = core_mesh.scene_fingerprint(o.fingerprint for o in job.objects)
    scene.prt.precompute_id = run_id
    scene.prt.precomputed_objects = len(job.objects)
    # last: a method's store sees the committed scene (AUTO draws on it to choose)
    methods.get(job.method).store(scene, job, job.derived)
    job.timings["storage"] = time.perf_counter() - t0
    t = job.timings
    scene.prt.last_report = (f"{job.point_count} points, {t.get('ray_count', 0) / 1e6:.1f} M rays "
                             f"in {t.get('rays', 0):.1f} s "
                             f"({t.get('rays_per_second', 0) / 1e6:.2f} M rays/s)")
