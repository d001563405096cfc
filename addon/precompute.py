"""Precompute in three steps: gather (main thread, reads bpy), run (pure core, any
thread, cancellable), commit (main thread, writes bpy).  Nothing in the scene
changes before commit, so an error or ESC leaves it as it was.

Memory (issue 20): the trace hands each chunk of visibility rows on as it is traced;
they are compressed into each object's stored blob in order (``storage.visibility_writer``)
and their sky visibility (the tessellation check) is taken on the way, so no copy of the
whole scene's visibility is held -- unless the method derives data from it (then the
bits are kept for ``Method.derive``; else ``ObjectJob.bits`` decodes the blob when read).
Every step reports ``stage`` and progress; ``commit_steps`` writes one object per step."""

from __future__ import annotations

import threading
import time
import uuid
from dataclasses import dataclass, field

import numpy as np

from ..core import directions, mesh as core_mesh, reference, rigid, shadow_fields, visibility
from . import dynamic, methods, scene_export, storage


@dataclass
class ObjectJob:
    name: str
    arrays: core_mesh.MeshArrays
    points: core_mesh.ShadingPoints
    fingerprint: str
    #: the visibility as stored (storage.visibility_blob), made in run()
    blob: bytes | None = None
    coarse_warning: str = ""
    #: the traced bits, kept when the job's method derives from them
    kept: np.ndarray | None = field(default=None, repr=False)
    #: a dynamic object (shadow fields): its own triangles, its world matrix now, the box
    #: it reaches over the animation, and its field's blob (made in run())
    dynamic: bool = False
    own: np.ndarray | None = field(default=None, repr=False)
    matrix: np.ndarray | None = None
    reach: tuple | None = None
    extra: dict = field(default_factory=dict, repr=False)
    field_note: str = ""

    @property
    def bits(self) -> np.ndarray | None:
        """The traced visibility (P, 6N^2/8): kept, else decoded from the blob each time
        it is read (nothing is held)."""
        if self.kept is not None or self.blob is None:
            return self.kept
        return storage.visibility_of_blob(self.blob)

    @bits.setter
    def bits(self, value):
        self.kept = value


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
    #: what run() is doing now (shown with the progress)
    stage: str = ""
    #: AUTO's choice is left to the caller (the modal operator runs it in steps)
    defer_choice: bool = False
    #: the dynamic objects' field detail (core.shadow_fields.DETAIL)
    field_detail: str = "HIGH"

    @property
    def point_count(self):
        return sum(o.points.count for o in self.objects)

    # -------------------------------------------------------------- run (no bpy)
    def run(self, threads=None):
        cube = directions.cubemap(self.resolution)
        pts = np.concatenate([o.points.positions for o in self.objects])
        nrm = np.concatenate([o.points.normals for o in self.objects])
        total = len(pts)
        starts = np.cumsum([0] + [o.points.count for o in self.objects])
        self.progress_done, self.progress_total = 0, total
        self.stage = "tracing"

        def progress(done, count):
            self.progress_done = done

        method = methods.get(self.method)
        keep = type(method).derive is not methods.Method.derive     # it reads the bits
        kept = np.empty((total, cube.size // 8), np.uint8) if keep else None
        writers = [storage.visibility_writer(o.points.count, self.resolution)
                   for o in self.objects]
        sky = np.empty(total, np.float32)       # the tessellation check's, per point
        stream = _InOrder(lambda a, b, rows: [
            w.write(rows[max(a, lo) - a:min(b, hi) - a])
            for w, lo, hi in zip(writers, starts[:-1], starts[1:]) if max(a, lo) < min(b, hi)])

        def consume(start, stop, bits):
            """A traced chunk (worker thread): its sky visibility, then on to the blobs."""
            sky[start:stop] = reference.sky_visibility(bits, nrm[start:stop], cube)
            if kept is not None:
                kept[start:stop] = bits
            stream.put(start, stop, bits)

        # static objects against the static occluders; a dynamic object against itself
        # only (what other objects cast on it comes from the fields at its current pose)
        groups = [(self.occluders, 0, int(sum(o.points.count for o in self.objects
                                                if not o.dynamic)))]
        groups += [(o.own, int(starts[i]), int(starts[i + 1]))
                   for i, o in enumerate(self.objects) if o.dynamic]
        stats = {"rays": 0}
        bvh = 0.0
        t1 = time.perf_counter()
        for tris, lo, hi in groups:
            if hi <= lo:
                continue
            self.stage = "building the BVH"
            tb = time.perf_counter()
            scene = visibility.build_occluder_scene(tris)
            bvh += time.perf_counter() - tb
            self.stage = "tracing"
            got = {}
            origins, moved = trace_origins(
                [o for i, o in enumerate(self.objects)
                 if lo <= starts[i] and starts[i + 1] <= hi], scene, self.offset)
            self.timings["contact_points"] = (self.timings.get("contact_points", 0)
                                              + int(moved.sum()))
            visibility.trace_visibility(
                scene, pts[lo:hi], nrm[lo:hi], cube, self.offset, threads=threads, origins=origins,
                progress=lambda done, count, lo=lo: progress(lo + done, total),
                cancel=lambda: self.cancel_requested, stats=got,
                consume=lambda a, b, bits, lo=lo: consume(lo + a, lo + b, bits))
            stats["rays"] += got["rays"]
            del scene
        stream.drain()
        t2 = time.perf_counter()
        self._shadow_fields(cube, threads)
        t1 += bvh
        t_fields = time.perf_counter()
        self.stage = "checking the tessellation"
        for i, o in enumerate(self.objects):
            o.blob = writers[i].finish()
            o.kept = None if kept is None else kept[starts[i]:starts[i + 1]]
            o.coarse_warning = coarse_receiver_warning(o, cube, sky[starts[i]:starts[i + 1]])
            self.progress_done = int(starts[i + 1])
        t3 = time.perf_counter()
        self.timings.update(build_bvh=bvh, rays=t2 - t1, ray_count=stats["rays"],
                            rays_per_second=stats["rays"] / max(t2 - t1, 1e-9),
                            tessellation_check=t3 - t_fields, encode=stream.seconds)
        self.stage = f"deriving {method.label}"
        self.progress_done = 0
        self.derived = method.derive(self)
        self.timings["derive"] = time.perf_counter() - t3
        self.stage = "writing"

    def _shadow_fields(self, cube, threads):
        """Each dynamic object's occluder field (its own frame: the world at this pose)
        and the static scene's field over where it goes (Zhou et al. 2005)."""
        dyn = [o for o in self.objects if o.dynamic]
        if not dyn:
            return
        t0 = time.perf_counter()
        layout, samples = shadow_fields.DETAIL[self.field_detail]
        for k, o in enumerate(dyn):
            self.stage = f"shadow field of '{o.name}' ({k + 1}/{len(dyn)})"
            cancel = lambda: self.cancel_requested     # noqa: E731
            field = shadow_fields.build_occluder_field(o.own, layout, threads, cancel)
            static = None
            if len(self.occluders):
                lo, hi = o.reach
                static = shadow_fields.build_static_field(self.occluders, lo, hi, cube, samples,
                                                          threads, cancel)
            data = shadow_fields.DynamicData(
                field=field, static=static, matrix=o.matrix,
                rotation=rigid.rotation_part(o.matrix),
                probe=rigid.local_probe(o.arrays.positions, o.matrix), offset=self.offset)
            o.extra[dynamic.FIELD] = storage.pack(*shadow_fields.dynamic_arrays(data))
            o.field_note = (f"{o.name}: field {field.nbytes / 2**20:.1f} MiB (PCA error "
                            f"{field.error:.1%})" + (f", static field {static.nbytes / 2**20:.1f}"
                                                     " MiB" if static is not None else ""))
        self.timings["shadow_fields"] = time.perf_counter() - t0


def trace_origins(objects, scene, offset):
    """``(origins, moved)`` of the shading points of ``objects`` (one trace group, in row
    order) against ``scene``: stepped off along the normal, or out of a surface they touch
    (core.visibility.contact_origins)."""
    starts = np.cumsum([0] + [o.points.count for o in objects])
    return visibility.contact_origins(
        scene, np.concatenate([o.points.positions for o in objects]),
        np.concatenate([o.points.normals for o in objects]),
        np.concatenate([o.arrays.triangle_positions for o in objects]),
        np.concatenate([o.points.point_of_corner[o.arrays.triangles] + s
                        for o, s in zip(objects, starts[:-1])]), offset)


class _InOrder:
    """Rows handed on in order: ``put(start, stop, rows)`` from any thread (chunks come
    out of order); one thread at a time passes the next ones to ``write(start, stop,
    rows)`` while the others go back to tracing; ``drain()`` at the end passes the rest.
    Holds only the chunks that wait for an earlier one."""

    def __init__(self, write):
        self.write = write
        self.at = 0
        self.pending: dict = {}
        self.lock = threading.Lock()
        self.writing = threading.Lock()
        self.seconds = 0.0          # spent writing (compressing)

    def put(self, start, stop, rows):
        with self.lock:
            self.pending[start] = (stop, rows)
        if self.writing.acquire(blocking=False):
            try:
                self._write()
            finally:
                self.writing.release()

    def _write(self):
        while True:
            with self.lock:
                got = self.pending.pop(self.at, None)
            if got is None:
                return
            t0 = time.perf_counter()
            self.write(self.at, got[0], got[1])
            self.seconds += time.perf_counter() - t0
            self.at = got[0]

    def drain(self):
        with self.writing:
            self._write()
        if self.pending:
            raise RuntimeError("visibility rows missing from the trace")


def coarse_receiver_warning(job: ObjectJob, cube, sky=None) -> str:
    """A note when shadows change faster than the tessellation can show.

    When more than 5 % of the mesh's edges join points whose sky visibility differs by
    over a quarter (:func:`core.reference.coarse_edge_share`; ``sky`` per point when
    the trace took it already: the bits are then not decoded), per-vertex shading blurs
    or aliases the shadows.
    """
    bits = job.bits if sky is None else None
    frac = reference.coarse_edge_share(bits, job.points.normals, job.points.point_of_corner,
                                       job.arrays.triangles, cube, sky=sky)
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
    tri_blocks, all_tris = [], []
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
        job = ObjectJob(ob.original.name, arrays, points, core_mesh.fingerprint(arrays))
        if ob.original.prt.dynamic:
            job.dynamic, job.own = True, occluders
            job.matrix = np.array(ob.matrix_world, dtype=np.float64)
        else:
            tri_blocks.append(occluders)
        all_tris.append(occluders)
        objects.append(job)
    if empty:
        warnings.append("Skipped mesh(es) without faces: " + ", ".join(empty))
    warnings += scene_export.instance_warning(skipped)
    if not objects:
        raise scene_export.ExportError("Nothing to precompute: no visible mesh object has faces")
    occluders = np.concatenate(tri_blocks) if tri_blocks else np.zeros((0, 3, 3))
    diag = core_mesh.bounding_diagonal(np.concatenate(all_tris).reshape(-1, 3))
    offset = float(settings.ray_offset) * max(diag, 1e-6)
    # static objects first: each trace group is one run of rows
    objects.sort(key=lambda o: o.dynamic)
    dynamic.set_reach(scene, [o for o in objects if o.dynamic], occluders)
    return PrecomputeJob(int(settings.resolution), offset, objects, occluders, warnings,
                         method=settings.method, settings={
                             name: getattr(settings, name)
                             for name in methods.scene_properties()},
                         field_detail=settings.field_detail)


def commit(scene, job: PrecomputeJob):
    """Store the job's results in the .blend (main thread)."""
    for _ in commit_steps(scene, job):
        pass


def commit_steps(scene, job: PrecomputeJob):
    """:func:`commit` in steps (a generator of progress fractions, one object per step:
    the modal operator runs one per timer event, so the UI stays responsive)."""
    import bpy

    t0 = time.perf_counter()
    # Objects deleted while a modal precompute ran are dropped.
    job.objects = [o for o in job.objects if o.name in bpy.data.objects]
    # Every blob was made in run(): from here on only assignments change the scene.
    if any(o.blob is None for o in job.objects):
        raise RuntimeError("precompute commit without run(): nothing was traced")
    run_id = uuid.uuid4().hex
    steps = len(job.objects) + 1
    for i, o in enumerate(job.objects):
        ob = bpy.data.objects[o.name]
        ob.prt.resolution = job.resolution
        ob.prt.point_count = o.points.count
        ob.prt.fingerprint = o.fingerprint
        ob.prt.precompute_id = run_id
        ob.prt.coarse_warning = o.coarse_warning
        # what earlier runs stored (other methods' data too) is dropped with them
        storage.replace_all(ob, {storage.VISIBILITY: o.blob, **o.extra})
        yield (i + 1) / steps
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
    yield 1.0
