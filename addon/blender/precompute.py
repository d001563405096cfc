"""Precompute in three steps: gather (main thread, reads bpy), run (pure core, any
thread, cancellable), commit (main thread, writes bpy).  Nothing in the scene
changes before commit, so an error or ESC leaves it as it was.

Memory (issue 20): the trace hands each chunk of visibility rows on as it is traced;
they are compressed into each object's stored blob in order (``storage.visibility_writer``)
and their sky visibility (the tessellation check) is taken on the way, so no copy of the
whole scene's visibility is held -- unless the method derives data from it (then the
bits are kept for ``Shading.derive``; else ``ObjectJob.bits`` decodes the blob when read).
Every step reports ``stage`` and progress; ``commit_steps`` writes one object per step."""

from __future__ import annotations

import time
import uuid

import numpy as np

from ...core.scene import mesh as core_mesh, rigid, sides, visibility
from ..frame import dynamic
from .. import methods
from . import attributes, scene_export, storage, surfaces
from ...core.pipeline import frame_status
from ...core.pipeline.tracing import ObjectJob, PrecomputeJob


def gather(depsgraph, settings) -> PrecomputeJob:
    """Read the scene into a job (raises scene_export.ExportError for bad input)."""
    scene = depsgraph.scene
    warnings = []
    scene_export.export_world(scene, warnings)       # validate lighting early
    objects = []
    # the static occluders, indexed in float32 (what Embree holds: the precompute's largest
    # arrays at scale), and each object's box for the scene's size
    tri_blocks, extents = [], []
    empty = []
    hidden = scene_export.hidden_in_viewport(depsgraph.view_layer, depsgraph)
    if hidden:
        warnings.append("Hidden in the viewport but shown in renders, so not traced (their "
                        "shadows are missing; unhide them to precompute): "
                        + frame_status.listing(hidden))
    shared = surfaces.SharedArrays()
    found = surfaces.scene_surfaces(depsgraph)
    # an instancer whose own geometry is empty (points that geometry nodes instance on)
    instancers = {s.owner.instancer.name for s in found if s.instance}
    notes = []                         # (message, group): one line per instanced source
    for s in found:
        arrays = shared.arrays(s)
        if not np.isfinite(arrays.positions).all():
            raise scene_export.ExportError(f"Object '{s.name}' has non-finite vertex positions")
        if len(arrays.triangles) == 0:
            if s.name not in instancers:
                empty.append(s.name)
            continue
        fixed = core_mesh.repair_normals(arrays)
        occluders, degenerate = core_mesh.occluder_mesh(arrays)
        group = surfaces.note_group(s)
        if degenerate:
            notes.append((f"'{s.name}': {degenerate} zero-area face(s) ignored as occluders",
                          group))
        elif fixed:
            notes.append((f"'{s.name}': {fixed} corner normal(s) repaired", group))
        points = shared.shared_points(s, core_mesh.shading_points(arrays))
        job = ObjectJob(s.name, arrays, points, core_mesh.fingerprint(arrays), matrix=s.matrix,
                        group=group)
        if s.owner.prt.dynamic:
            # its shadow field follows the motion M_now M_then^-1: a scale of 0 has no inverse
            if not rigid.invertible(s.matrix):
                raise scene_export.ExportError(
                    f"Object '{s.name}' is marked Dynamic but scaled to 0 along an axis: its "
                    "shadow field needs a transform that can be inverted (give it a non-zero "
                    "scale, or unmark Dynamic in Object Properties)")
            job.dynamic, job.own = True, core_mesh.occluder_triangles(arrays)[0]
        else:
            tri_blocks.append(occluders)
        extents.append(core_mesh.bounding_box(occluders.vertices))
        objects.append(job)
    warnings += frame_status.grouped_notes(notes)
    if empty:
        warnings.append("Skipped mesh(es) without faces: " + frame_status.listing(empty))
    job_bytes = shared.nbytes()
    if not objects:
        raise scene_export.ExportError("Nothing to precompute: no visible mesh object has faces")
    occluders = core_mesh.Occluders.join(tri_blocks)
    del tri_blocks
    diag = core_mesh.bounding_diagonal(np.concatenate(extents))
    offset = float(settings.ray_offset) * max(diag, 1e-6)
    two_sided(objects, occluders, offset, scene.camera)
    # static objects first: each trace group is one run of rows
    objects.sort(key=lambda o: o.dynamic)
    dynamic.set_reach(scene, [o for o in objects if o.dynamic], occluders.vertices)
    method = methods.get(settings.method)
    return PrecomputeJob(int(settings.resolution), offset, objects, occluders, warnings,
                         bounces=scene_export.light_bounces(scene),
                         bounce_rows_mib=settings.bounce_rows_budget,
                         method=settings.method, settings={
                             name: getattr(settings, name)
                             for name in methods.scene_properties()},
                         field_detail=settings.field_detail,
                         derive=method.shading.derive if method.derives else None,
                         derive_label=method.label, shared_bytes=job_bytes)


def two_sided(objects, occluders, offset, camera):
    """Give the open static meshes whose back side exchanges light or faces the scene
    camera their back side as surfaces of their own (core.scene.sides), so it is traced,
    stored and drawn with its own light (as Cycles shades a back face)."""
    open_static = [o for o in objects if not o.dynamic and core_mesh.closed_side(o.arrays) == 0]
    if not open_static or len(occluders) == 0:
        return
    scene = visibility.build_occluder_scene(occluders)
    eye = None if camera is None else np.array(camera.matrix_world.translation, np.float64)
    for o in open_static:
        if sides.needs_back_side(scene, o.arrays, offset, eye):
            o.arrays = core_mesh.with_back_sides(o.arrays)
            o.points = core_mesh.shading_points(o.arrays)
            o.fingerprint = core_mesh.fingerprint(o.arrays)


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
    job.objects = [o for o in job.objects if storage.owner(o.name) is not None]
    # Every blob was made in run(): from here on only assignments change the scene.
    if any(o.blob is None for o in job.objects):
        raise RuntimeError("precompute commit without run(): nothing was traced")
    run_id = uuid.uuid4().hex
    steps = len(job.objects) + 1
    kept = {}                    # instancer -> keys of its instances in this run
    for i, o in enumerate(job.objects):
        ob = storage.owner(o.name)
        if isinstance(ob, storage.InstanceRecord):
            kept.setdefault(ob.instancer, set()).add(ob.key)
        ob.prt.resolution = job.resolution
        ob.prt.point_count = o.points.count
        ob.prt.fingerprint = o.fingerprint
        ob.prt.precompute_id = run_id
        ob.prt.coarse_warning = o.coarse_warning
        ob.prt.back_sides = o.arrays.two_sided
        # what earlier runs stored (other methods' data too) is dropped with them
        storage.replace_all(ob, {storage.VISIBILITY: o.blob, **o.extra})
        # an instance shares its source's mesh: attributes go on real objects only
        if scene.prt.write_attributes and not isinstance(ob, storage.InstanceRecord):
            attributes.write_precompute(ob, o.arrays, o.points, attributes.precompute_values(
                o.bits, o.points.normals, job.resolution, scene.prt.attribute_sh_order),
                job.warnings.append)
        yield (i + 1) / steps
    for ob in scene.objects:             # instances no longer there lose their records
        storage.keep_instances(ob, kept.get(ob, ()))
    storage.remove_legacy()
    scene.prt.precomputed_resolution = job.resolution
    scene.prt.scene_fingerprint = core_mesh.scene_fingerprint(o.fingerprint for o in job.objects)
    scene.prt.precompute_id = run_id
    scene.prt.precomputed_objects = len(job.objects)
    # last: a method's store sees the committed scene (AUTO draws on it to choose)
    methods.get(job.method).shading.store(scene, job, job.derived)
    job.timings["storage"] = time.perf_counter() - t0
    t = job.timings
    scene.prt.last_report = (f"{job.point_count} points, {t.get('ray_count', 0) / 1e6:.1f} M rays "
                             f"in {t.get('rays', 0):.1f} s "
                             f"({t.get('rays_per_second', 0) / 1e6:.2f} M rays/s)")
    yield 1.0
