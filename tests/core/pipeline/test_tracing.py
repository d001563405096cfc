"""core.pipeline.tracing: the precompute's run without bpy.  A job made from mesh arrays (a
ground and a box on it, the way addon/blender/precompute.py gathers one) is traced with
Embree: each object's blob holds exactly the bits of one whole trace of its points (the
stream's chunks, threads and order do not show), the bits are kept only for a method that
derives from them, ESC stops it with nothing written; the ordered writer and the
tessellation check against edges counted by hand.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.common import parallel
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.pipeline import tracing
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.sphere import directions
from prt_relight.core.store import layouts

from ..scene.geometry import flat_cube, unit

pytestmark = pytest.mark.skipif(not visibility.have_embree(), reason="needs embreex")

RESOLUTION = 8


def _object(name, arrays):
    return tracing.ObjectJob(name, arrays, mesh.shading_points(arrays), mesh.fingerprint(arrays))


def _job(**kw):
    """A 6x6 ground with a 0.6 m box standing on it, as precompute.gather makes the job."""
    ground = mesh.grid(size=2.0, cuts=6)
    box = flat_cube()
    box.positions = box.positions * 0.3 + [0.2, -0.1, 0.3]
    objects = [_object("Grid", ground), _object("Box", box)]
    occluders = np.concatenate([mesh.occluder_triangles(o.arrays)[0] for o in objects])
    offset = 1e-4 * mesh.bounding_diagonal(occluders.reshape(-1, 3))
    return tracing.PrecomputeJob(RESOLUTION, offset, objects, occluders, **kw)


def _whole_trace(job):
    """The bits of one trace of every point at once (no chunks, one thread)."""
    scene = visibility.build_occluder_scene(job.occluders)
    origins, _ = tracing.trace_origins(job.objects, scene, job.offset)
    pts = np.concatenate([o.points.positions for o in job.objects])
    nrm = np.concatenate([o.points.normals for o in job.objects])
    return visibility.trace_visibility(scene, pts, nrm, directions.cubemap(job.resolution),
                                       job.offset, origins=origins, threads=1)


@pytest.mark.parametrize("threads", [1, 3])
def test_each_blob_holds_the_bits_of_one_whole_trace(threads):
    job = _job()
    job.run(threads=threads)
    whole = _whole_trace(job)
    start = 0
    for o in job.objects:
        rows = whole[start:start + o.points.count]
        start += o.points.count
        assert o.kept is None                               # no derive: read from the blob
        np.testing.assert_array_equal(o.bits, rows)
        assert o.blob == layouts.visibility_blob(rows, RESOLUTION)
    assert start == job.point_count == job.progress_done == job.progress_total
    assert job.stage == "writing" and job.derived is None
    assert job.timings["ray_count"] > 0 and job.timings["rays"] >= 0.0
    # the box shadows the ground: some ground texels above the horizon are blocked
    ground = visibility.unpack_visibility(job.objects[0].bits, 6 * RESOLUTION ** 2)
    hemi = visibility.hemisphere_mask(job.objects[0].points.normals, directions.cubemap(RESOLUTION))
    assert (ground <= hemi).all() and (ground < hemi).any()


def test_a_method_that_derives_gets_the_kept_bits_once():
    seen = []

    def derive(job):
        seen.append([o.kept.copy() for o in job.objects])
        return "derived data"

    job = _job(derive=derive, derive_label="TEST")
    job.run(threads=2)
    assert job.derived == "derived data" and len(seen) == 1
    for o, kept in zip(job.objects, seen[0]):
        np.testing.assert_array_equal(o.kept, kept)
        np.testing.assert_array_equal(layouts.visibility_of_blob(o.blob), kept)
    assert "derive" in job.timings


def test_esc_stops_the_trace_and_writes_no_blob():
    job = _job()
    job.cancel_requested = True
    with pytest.raises(parallel.Cancelled):
        job.run(threads=2)
    assert all(o.blob is None for o in job.objects)


def test_trace_origins_step_off_along_the_normal_away_from_contacts():
    """Points that touch no other surface start their rays ``offset`` along the normal,
    moved CONTACT_SHARE of the way into their own faces in their tangent plane (a cube's
    edge point leaves the plane of the face across its edge)."""
    job = _job()
    scene = visibility.build_occluder_scene(job.occluders)
    box = job.objects[1]
    origins, moved = tracing.trace_origins([box], scene, job.offset)
    pts = box.points
    plain = visibility.ray_origins(pts.positions, pts.normals, job.offset)
    inward = mesh.point_interiors(box.arrays, pts) - pts.positions
    inward -= np.einsum("ij,ij->i", inward, pts.normals)[:, None] * pts.normals
    expected = plain + visibility.CONTACT_SHARE * inward
    bottom = pts.positions[:, 2] < 1e-9                     # its bottom rests on the ground
    np.testing.assert_allclose(origins[~moved], expected[~moved], atol=1e-6)
    assert np.all(np.einsum("ij,ij->i", origins - plain, pts.normals)[~moved] < 1e-6)
    assert np.all(np.linalg.norm(inward, axis=1) > 0.0)     # every point is on an edge
    assert not moved[~bottom].any()


def test_trace_origins_one_object_at_a_time_are_those_of_all_at_once():
    job = _job()
    box = job.objects[1].arrays           # smooth-shaded: its bottom rim steps under the ground
    centre = box.positions.mean(axis=0)
    box.corner_normals = unit(box.positions[box.corner_verts] - centre)
    job.objects[1] = _object("Box", box)
    scene = visibility.build_occluder_scene(job.occluders)
    origins, moved = tracing.trace_origins(job.objects, scene, job.offset)
    starts = np.cumsum([0] + [o.points.count for o in job.objects])
    whole = visibility.contact_origins(
        scene, np.concatenate([o.points.positions for o in job.objects]),
        np.concatenate([o.points.normals for o in job.objects]),
        np.concatenate([o.arrays.triangle_positions for o in job.objects]),
        np.concatenate([o.points.point_of_corner[o.arrays.triangles] + s
                        for o, s in zip(job.objects, starts[:-1])]), job.offset)
    assert moved.any()                              # the box's bottom rim touches the ground
    np.testing.assert_allclose(origins, whole[0], rtol=0, atol=1e-6)
    assert (moved != whole[1]).mean() < 0.01


def test_in_order_writer_takes_chunks_in_any_order():
    got = []
    w = tracing.InOrder(lambda a, b, rows: got.append((a, b, rows[0, 0])))
    chunks = [(a, a + 3, np.full((3, 2), a)) for a in range(0, 30, 3)]
    for i in np.random.default_rng(0).permutation(len(chunks)):
        w.put(*chunks[i])
    w.drain()
    assert [g[0] for g in got] == list(range(0, 30, 3)) and [g[2] for g in got] == \
        list(range(0, 30, 3))
    gap = tracing.InOrder(lambda a, b, rows: None)
    gap.put(3, 6, np.zeros((3, 2)))
    with pytest.raises(RuntimeError):
        gap.drain()


def _half_shaded_grid(cuts):
    """A grid whose points at x < 0 see no sky and the others all of it."""
    g = mesh.grid(2.0, cuts)
    job = _object("Half", g)
    cube = directions.cubemap(RESOLUTION)
    open_bits = np.packbits(visibility.hemisphere_mask(job.points.normals, cube), axis=1)
    shaded = job.points.positions[:, 0] < -1e-9
    job.bits = np.where(shaded[:, None], 0, open_bits).astype(np.uint8)
    return job, cube, shaded


@pytest.mark.parametrize("cuts", [4, 40])
def test_coarse_receiver_warning_counts_the_edges_across_a_shadow(cuts):
    """The warning names the object when more than COARSE_SHARE of its edges join a shaded
    and an open point (counted by hand here), with the sky taken from the bits or given."""
    job, cube, shaded = _half_shaded_grid(cuts)
    tri = job.points.point_of_corner[job.arrays.triangles]
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    share = float(np.mean(shaded[edges[:, 0]] != shaded[edges[:, 1]]))
    sky = reference.sky_visibility(job.bits, job.points.normals, cube)
    for given in (None, sky):
        note = tracing.coarse_receiver_warning(job, cube, given)
        if share > reference.COARSE_SHARE:
            assert "'Half' is too coarse" in note and f"{share:.0%}" in note
        else:
            assert note == ""
    assert (share > reference.COARSE_SHARE) == (cuts == 4)
