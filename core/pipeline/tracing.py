"""The precompute's run, between gather and commit (addon/blender/precompute.py): per shading
point one ray per cubemap texel of its hemisphere, streamed into each object's compressed
visibility blob, the shadow fields of moving objects, the tessellation check and the
method's derived data; any thread, cancellable, no bpy."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..common import codec
from ..methods.reference import shading as reference
from ..scene import mesh as core_mesh
from ..scene import occluder_fields, rigid, shadow_fields, visibility
from ..sphere import directions
from ..store import layouts
from ..transport import clusters, transfer


@dataclass
class ObjectJob:
    name: str
    #: its world-space arrays (an instance's: core.scene.mesh.PlacedArrays)
    arrays: core_mesh.MeshArrays
    points: core_mesh.ShadingPoints
    fingerprint: str
    #: the visibility as stored (storage.visibility_blob), made in run()
    blob: bytes | None = None
    coarse_warning: str = ""
    #: what its notes are grouped under: an instance's source, None for an object
    #: (core.pipeline.frame_status.grouped_notes)
    group: str | None = None
    #: the traced bits, kept when the job's method derives from them
    kept: np.ndarray | None = field(default=None, repr=False)
    #: a dynamic object (shadow fields): its own triangles, the box it reaches over the
    #: animation, and its field's blob (made in run())
    dynamic: bool = False
    own: np.ndarray | None = field(default=None, repr=False)
    #: its world matrix at the precompute (4x4; an instance's placed by its instancer)
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
        return layouts.visibility_of_blob(self.blob)

    @bits.setter
    def bits(self, value):
        self.kept = value


@dataclass
class PrecomputeJob:
    resolution: int
    offset: float
    objects: list
    #: the static occluders (core.scene.mesh.Occluders, or (T, 3, 3) corners)
    occluders: object
    warnings: list = field(default_factory=list)
    method: str = "REFERENCE"
    #: scene.prt values of every method's settings at gather time
    settings: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    #: method data from Shading.derive (stored by Shading.store in the commit)
    derived: object = None
    progress_done: int = 0
    progress_total: int = 0
    cancel_requested: bool = False
    #: what run() is doing now (shown with the progress)
    stage: str = ""
    #: AUTO's choice is left to the caller (the modal operator runs it in steps)
    defer_choice: bool = False
    #: the dynamic objects' field detail (core.scene.shadow_fields.DETAIL)
    field_detail: str = "HIGH"
    #: the method's ``derive(job)`` run after the trace (it reads the traced bits), or None
    derive: object = field(default=None, repr=False)
    #: what the progress calls that step ("deriving <label>")
    derive_label: str = ""
    #: diffuse bounces of the scene's light paths: > 0 stores each static object's bounce
    #: transfer (core.transport), traced from the same rays as the visibility
    bounces: int = 0
    #: MiB the receivers' bounce rows may take; past it rows keep fewer entries
    #: (core.transport.transfer.row_width)
    bounce_rows_mib: float = transfer.ROW_BUDGET_MIB
    #: bytes of the instanced sources' object-space arrays, shared by their instances
    #: (each instance holds transformed copies of the positions and normals only)
    shared_bytes: int = 0

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
        # each object's points become views of the rows traced (one copy held, not two)
        for o, a, b in zip(self.objects, starts[:-1], starts[1:]):
            o.points = replace(o.points, positions=pts[a:b], normals=nrm[a:b])
        self.progress_done, self.progress_total = 0, total
        self.stage = "tracing"

        def progress(done, count):
            self.progress_done = done

        keep = self.derive is not None     # it reads the bits
        kept = np.empty((total, cube.size // 8), np.uint8) if keep else None
        writers = [layouts.visibility_writer(o.points.count, self.resolution)
                   for o in self.objects]
        sky = np.empty(total, np.float32)       # the tessellation check's, per point
        stream = InOrder(lambda a, b, rows: [
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
        rows = self._transfer_rows(cube, starts) if self.bounces > 0 else None
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
                consume=lambda a, b, bits, lo=lo: consume(lo + a, lo + b, bits),
                hits=None if rows is None or tris is not self.occluders else (
                    lambda a, b, blocked, prim, lo=lo: rows.add(
                        lo + a, lo + b, nrm[lo + a:lo + b], blocked, prim)))
            stats["rays"] += got["rays"]
            if rows is not None and tris is self.occluders:
                self._trace_samples(scene, rows, threads)
            del scene
        stream.drain()
        t2 = time.perf_counter()
        self._shadow_fields(cube, threads)
        t1 += bvh
        t_fields = time.perf_counter()
        self.stage = "checking the tessellation"
        if rows is not None:
            self._store_transfer(rows, starts)
        for i, o in enumerate(self.objects):
            o.blob = writers[i].finish()
            o.kept = None if kept is None else kept[starts[i]:starts[i + 1]]
            o.coarse_warning = coarse_receiver_warning(o, cube, sky[starts[i]:starts[i + 1]])
            self.progress_done = int(starts[i + 1])
        t3 = time.perf_counter()
        self.timings.update(build_bvh=bvh, rays=t2 - t1, ray_count=stats["rays"],
                            rays_per_second=stats["rays"] / max(t2 - t1, 1e-9),
                            tessellation_check=t3 - t_fields, encode=stream.seconds)
        if self.derive is not None:
            self.stage = f"deriving {self.derive_label}"
            self.progress_done = 0
            self.derived = self.derive(self)
        self.timings["derive"] = time.perf_counter() - t3
        self.stage = "writing"

    def _transfer_rows(self, cube, starts):
        """The receivers' bounce rows over gather clusters of the static objects' triangle
        sides (:mod:`..transport`), filled as the static group's rays are traced."""
        static = [o for o in self.objects if not o.dynamic]
        count = sum(o.points.count for o in static)
        if count == 0:
            return None
        width, note = transfer.row_width(count, self.bounce_rows_mib)
        if note:
            self.warnings.append(note)
        meshes = [o.arrays for o in static]
        patches = transfer.Patches.of_meshes(meshes)
        cluster_of, k, cell = clusters.cluster_patches(
            patches.centroids, patches.normals, patches.areas,
            max(1, count // clusters.POINTS_PER_CLUSTER))
        patch, owner, weight = clusters.sample_sets(cluster_of, patches.centroids,
                                                    patches.areas, k, cell)
        samples = (patch, owner, weight, patches.centroids[patch], patches.normals[patch])
        # the sides' own arrays end here: tens of millions of them for a scatter of instances
        patches = patches.offsets_only()
        hits = transfer.HitMap.of_meshes(meshes, patches, cluster_of, self.occluders)
        inner = np.concatenate([core_mesh.point_interiors(o.arrays, o.points).astype(np.float32)
                                for o in static])
        rows = transfer.TransferRows(count, k, hits, cube, width=width, inner=inner,
                                     keep_sum=False)
        rows.patches, rows.cluster_of, rows.picked = patches, cluster_of, samples
        return rows

    def _trace_samples(self, scene, rows, threads):
        """The clusters' samples (:func:`..transport.clusters.sample_sets`): their
        visibility at the sample cubemap (the frame's direct light there) and each
        cluster's row, the weighted mean of its samples' (further bounces)."""
        patch, owner, weight, pos, nrm = rows.picked
        cube = directions.cubemap(layouts.BOUNCE_SAMPLE_RESOLUTION)
        own = transfer.TransferRows(len(patch), rows.clusters, rows.hits, cube)
        bits = visibility.trace_visibility(
            scene, pos, nrm, cube, self.offset, threads=threads,
            cancel=lambda: self.cancel_requested,
            hits=lambda a, b, blocked, prim: own.add(a, b, nrm[a:b], blocked, prim))
        k_cols, k_w = transfer.cluster_rows(owner, weight, own.columns, own.weights,
                                            rows.clusters)
        rows.samples = (patch, owner, weight, pos, nrm, bits, k_cols, k_w)

    def _store_transfer(self, rows, starts):
        """Each static object's rows, its triangle sides' clusters, the samples lying on it
        and the rows of the clusters whose first sample does, as its ``bounce`` blob
        (core.store.layouts)."""
        patch, owner, weight, pos, nrm, bits, k_cols, k_w = rows.samples
        cluster_of = np.asarray(rows.cluster_of, np.int64)
        first = np.full(rows.clusters, -1, np.int64)
        first[owner[::-1]] = patch[::-1]             # the first sample of each cluster
        j = 0
        for i, o in enumerate(self.objects):
            if o.dynamic:
                continue
            a, b = int(starts[i]), int(starts[i + 1])
            front, back = rows.patches.of_mesh(j, o.arrays)
            lo, hi = int(rows.patches.offsets[j]), int(rows.patches.offsets[j + 1])
            mine = (patch >= lo) & (patch < hi)
            held = np.nonzero((first >= lo) & (first < hi))[0]
            o.extra[layouts.BOUNCE] = layouts.bounce_blob(
                rows.columns[a:b], rows.weights[a:b], rows.rest[a:b], cluster_of[front],
                None if back is None else cluster_of[back],
                dict(cluster=owner[mine], weight=weight[mine], position=pos[mine],
                     normal=nrm[mine], bits=bits[mine]),
                dict(ids=held, columns=k_cols[held], weights=k_w[held]), rows.clusters)
            j += 1

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
            field = occluder_fields.build_occluder_field(o.own, layout, threads, cancel)
            static = None
            if len(self.occluders):
                lo, hi = o.reach
                static = shadow_fields.build_static_field(
                    core_mesh.triangle_soup(self.occluders), lo, hi, cube, samples, threads,
                    cancel)
            data = shadow_fields.DynamicData(
                field=field, static=static, matrix=o.matrix,
                rotation=rigid.rotation_part(o.matrix),
                probe=rigid.local_probe(o.arrays.positions, o.matrix), offset=self.offset)
            o.extra[layouts.SHADOW_FIELD] = codec.pack(*shadow_fields.dynamic_arrays(data))
            o.field_note = (f"{o.name}: field {field.nbytes / 2**20:.1f} MiB (PCA error "
                            f"{field.error:.1%})" + (f", static field {static.nbytes / 2**20:.1f}"
                                                     " MiB" if static is not None else ""))
        self.timings["shadow_fields"] = time.perf_counter() - t0


def trace_origins(objects, scene, offset):
    """``(origins, moved)`` of the shading points of ``objects`` (one trace group, in row
    order) against ``scene``: stepped off along the normal, or out of a surface they touch
    (core.scene.visibility.contact_origins).  One object at a time: a point's origin
    depends on its own faces only, and the faces' temporaries of a thousand instances at
    once were the precompute's peak."""
    got = [visibility.contact_origins(
        scene, o.points.positions, o.points.normals, o.arrays.triangle_positions,
        o.points.point_of_corner[o.arrays.triangles], offset) for o in objects]
    if not got:
        return np.zeros((0, 3), np.float32), np.zeros(0, bool)
    return (np.concatenate([g[0] for g in got]), np.concatenate([g[1] for g in got]))


class InOrder:
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
    over a quarter (:func:`core.methods.reference.shading.coarse_edge_share`; ``sky`` per point when
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
