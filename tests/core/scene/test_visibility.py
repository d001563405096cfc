# SPDX-License-Identifier: GPL-3.0-or-later
"""core.scene.visibility against analytic occluders (ground plane, half-space wall, closed
box and room, a scene far from the origin), contact origins, the float24 packing, and the
trace's threads, chunks, streaming, cancellation and progress.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.common import parallel
from .geometry import LAMBERT, N, OFFSET, box_triangles, flat_cube, shade, trace, unit, wall_triangles, white_world


# --------------------------------------------------------------------------- #
# visibility: analytic occluders
# --------------------------------------------------------------------------- #

def test_ground_grid_sees_upper_hemisphere():
    g = mesh.grid(size=2.0, cuts=8)
    sp = mesh.shading_points(g)
    assert sp.count == 81
    np.testing.assert_allclose(sp.normals, np.tile([0, 0, 1.0], (81, 1)))
    offset = 1e-4 * mesh.bounding_diagonal(g.positions)
    _, vis = trace(g.triangle_positions, sp.positions, sp.normals, offset=offset)
    cube = directions.cubemap(N)
    expected = (sp.normals @ cube.directions.T) > 0
    np.testing.assert_array_equal(vis, expected)
    assert vis.sum() == 81 * cube.size // 2


def test_half_space_wall_blocks_exactly_positive_x():
    cube = directions.cubemap(N)
    pts = np.zeros((3, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (3, 1))
    _, vis = trace(wall_triangles(), pts, nrm)
    up = cube.directions[:, 2] > 0
    expected = up & (cube.directions[:, 0] < 0)
    for p in range(3):
        np.testing.assert_array_equal(vis[p], expected)
    # other normals: the wall still blocks every traced texel with w.x > 0
    nrm2 = unit(np.array([[1.0, 0, 0], [-1.0, 0, 0], [0.3, -0.5, 0.8], [0.0, 1.0, 0.0]]))
    _, vis2 = trace(wall_triangles(), np.zeros((4, 3)), nrm2)
    cos = nrm2 @ cube.directions.T
    np.testing.assert_array_equal(vis2, (cos > 0) & (cube.directions[:, 0] < 0)[None, :])


def test_enclosed_point_is_fully_blocked():
    rng = np.random.default_rng(8)
    nrm = np.vstack([[0, 0, 1.0], [0, 0, -1.0], unit(rng.normal(size=(6, 3)))])
    pts = rng.uniform(-0.5, 0.5, size=(len(nrm), 3))
    bits, vis = trace(box_triangles(), pts, nrm)
    assert not vis.any()
    assert not bits.any()
    glossy = materials.Material(diffuse_albedo=(0.5, 0.5, 0.5), specular_color=(1, 1, 1), roughness=0.3)
    for mat in (LAMBERT, glossy):
        out = shade(bits, pts, nrm, white_world(), mat)
        np.testing.assert_array_equal(out, 0.0)


def test_point_outside_box_sees_past_it():
    # A point on the box top (+Z normal) sees its whole upper hemisphere.
    pts = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 1.0]])
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    cube = directions.cubemap(N)
    _, vis = trace(box_triangles(), pts, nrm, offset=1e-4 * np.sqrt(12))
    np.testing.assert_array_equal(vis, np.tile(cube.directions[:, 2] > 0, (2, 1)))


def test_closed_room_corner_points_fully_blocked():
    room = flat_cube()
    room.corner_normals *= -1.0                          # normals point into the room
    room.triangles = room.triangles[:, [0, 2, 1]].copy()
    sp = mesh.shading_points(room)
    assert sp.count == 24
    offset = 1e-4 * mesh.bounding_diagonal(room.positions)
    _, vis = trace(room.triangle_positions, sp.positions, sp.normals, offset=offset)
    assert vis.sum() == 0


def test_closed_room_interior_points_fully_blocked():
    # Points strictly inside the room faces (not at edges/corners) are dark.
    room = box_triangles()
    rng = np.random.default_rng(3)
    xy = rng.uniform(-0.9, 0.9, size=(10, 2))
    pts = np.column_stack([xy, np.full(10, -1.0)])      # on the floor
    nrm = np.tile([0, 0, 1.0], (10, 1))
    _, vis = trace(room, pts, nrm, offset=1e-4 * np.sqrt(12))
    assert vis.sum() == 0


def test_small_scene_far_from_origin_not_self_occluded():
    g = mesh.grid(size=0.2, cuts=8, z=1000.0)
    sp = mesh.shading_points(g)
    offset = 1e-4 * mesh.bounding_diagonal(g.positions)   # what the add-on passes
    _, vis = trace(g.triangle_positions, sp.positions, sp.normals, offset=offset)
    cube = directions.cubemap(N)
    np.testing.assert_array_equal(vis, (sp.normals @ cube.directions.T) > 0)


def test_small_scene_moderately_far_from_origin():
    g = mesh.grid(size=0.2, cuts=8, z=300.0)
    sp = mesh.shading_points(g)
    _, vis = trace(g.triangle_positions, sp.positions, sp.normals,
                   offset=1e-4 * mesh.bounding_diagonal(g.positions))
    cube = directions.cubemap(N)
    np.testing.assert_array_equal(vis, (sp.normals @ cube.directions.T) > 0)


def _box_on_ground(lift=0.0):
    """A smooth-shaded unit box (corner normals (±1, ±1, ±1)/sqrt 3) standing ``lift``
    above a ground plane at z = 0: its triangles, corner point indices, points, normals."""
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (0.0, 1.0)])
    v[:, 2] += lift
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    corners = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    normals = unit(np.sign(v - [0.0, 0.0, 0.5 + lift]))
    ground = np.array([[[-50, -50, 0], [50, -50, 0], [50, 50, 0]],
                       [[-50, -50, 0], [50, 50, 0], [-50, 50, 0]]], float)
    return np.concatenate([v[corners], ground]), corners, v, normals


def test_contact_origins_lift_a_smooth_rim_off_the_ground_it_rests_on():
    """A bottom corner's normal points 35 degrees into the ground: stepped along it the
    rays start under the ground, blind upward and seeing the world below the floor.
    Its two side faces (180 degrees of corner angle) outvote the bottom face lying on
    the ground (90): traced from just inside a side face it sees every upward direction
    of its hemisphere but those grazing the other side face (the sample sits 2 % into
    its face) and none below the ground."""
    tris, corners, pts, nrm = _box_on_ground()
    cube = directions.cubemap(N)
    scene = visibility.build_occluder_scene(tris)
    offset = 1e-4 * mesh.bounding_diagonal(tris.reshape(-1, 3))
    origins, moved = visibility.contact_origins(scene, pts, nrm, tris[:12], corners, offset)
    bottom = pts[:, 2] == 0.0
    np.testing.assert_array_equal(moved, bottom)
    # the points off the ground keep the plain step along the normal (and the nudge into
    # their own faces)
    np.testing.assert_array_equal(origins[~bottom],
                                  visibility.ray_origins(pts, nrm, offset)[~bottom])
    hemi = visibility.hemisphere_mask(nrm, cube)
    up, down = cube.directions[:, 2] > 0.0, cube.directions[:, 2] < 0.0
    for given, seen_up, seen_down in ((None, (0.0, 0.0), 1.0), (origins, (0.95, 1.0), 0.0)):
        bits = visibility.trace_visibility(scene, pts, nrm, cube, offset, origins=given)
        vis = visibility.unpack_visibility(bits, cube.size)
        for k in np.flatnonzero(bottom):
            assert seen_up[0] <= vis[k][hemi[k] & up].mean() <= seen_up[1]
            assert vis[k][hemi[k] & down].mean() == seen_down


def test_flat_points_on_a_concave_crease_start_inside_their_own_face():
    """The inside corner of an open box (floor and two walls, flat shaded, normals in):
    stepped along its normal alone a floor corner's origin lies in both walls' planes; it
    moves into its own face (by CONTACT_SHARE of the way to its faces' centroid), so its
    rays into the walls hit them a little way off and those into the box are free."""
    floor = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    wall_x = floor[:, :, [2, 0, 1]]                  # the plane x = 0, normal +x
    wall_y = floor[:, :, [1, 2, 0]]                  # the plane y = 0, normal +y
    tris = np.concatenate([floor, wall_x, wall_y])
    pts = np.zeros((3, 3))                          # the corner, once per face (flat)
    nrm = np.eye(3)[[2, 0, 1]]
    corners = np.array([[0, 3, 3], [0, 3, 3], [1, 3, 3], [1, 3, 3], [2, 3, 3], [2, 3, 3]])
    pts = np.vstack([pts, [[0.5, 0.5, 0.5]]])       # a point of no triangle (index 3)
    nrm = np.vstack([nrm, [[0.0, 0.0, 1.0]]])
    scene = visibility.build_occluder_scene(tris)
    origins, moved = visibility.contact_origins(scene, pts, nrm, tris, corners, 1e-4)
    plain = visibility.ray_origins(pts, nrm, 1e-4)
    np.testing.assert_array_equal(origins[3], plain[3])
    shift = origins[:3] - plain[:3]
    assert np.all(np.abs(np.einsum("ij,ij->i", shift, nrm[:3])) < 1e-7)   # in the face
    assert np.all(np.linalg.norm(shift, axis=1) > 0.005) and np.all(origins[:3] > 0.0)
    cube = directions.cubemap(N)
    vis = visibility.unpack_visibility(visibility.trace_visibility(
        scene, pts[:3], nrm[:3], cube, 1e-4, origins=origins[:3]), cube.size)
    inside = np.all(cube.directions > 0.0, axis=1)  # into the box: nothing blocks them
    for k in range(3):
        hemi = visibility.hemisphere_mask(nrm[k:k + 1], cube)[0]
        assert vis[k][inside].all()
        # through the other faces: blocked (the walls of a box are not windows)
        through = hemi & np.any(cube.directions[:, [0, 1, 2]] < 0.0, axis=1)
        assert not vis[k][through].any()


def test_contact_origins_leave_points_off_the_ground_alone():
    tris, corners, pts, nrm = _box_on_ground(lift=0.05)
    scene = visibility.build_occluder_scene(tris)
    origins, moved = visibility.contact_origins(scene, pts, nrm, tris[:12], corners, 1e-3)
    assert not moved.any()
    np.testing.assert_array_equal(origins, visibility.ray_origins(pts, nrm, 1e-3))


# --------------------------------------------------------------------------- #
# visibility: packing, threads, callbacks
# --------------------------------------------------------------------------- #

def test_float24_roundtrip_exact():
    rng = np.random.default_rng(1)
    bits = rng.integers(0, 256, size=(17, 3 * N * N // 4), dtype=np.uint8)
    bits[0] = 255
    bits[1] = 0
    f = visibility.bytes_to_float24(bits)
    assert f.dtype == np.float32 and f.shape == (17, N * N // 4)
    assert f.max() <= 2 ** 24 - 1 and f[0].min() == 2 ** 24 - 1
    back = visibility.float24_to_bytes(f)
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, bits)
    # independent value check: first triple as a big-endian integer
    b = bits[2, :3].astype(np.int64)
    assert f[2, 0] == (b[0] << 16) + (b[1] << 8) + b[2]
    with pytest.raises(ValueError):
        visibility.bytes_to_float24(bits[:, :5])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0, 0.5, 12345.25, float(2 ** 24)])
def test_float24_rejects_corrupt(bad):
    v = np.zeros((2, 4), np.float32)
    v[1, 2] = bad
    with pytest.raises(ValueError):
        visibility.float24_to_bytes(v)


def _random_scene(rng, count=40):
    centres = rng.uniform(-1, 1, size=(count, 1, 3)) + [0, 0, 0.8]
    return centres + rng.normal(scale=0.3, size=(count, 3, 3))


def test_trace_independent_of_threads_and_chunks():
    rng = np.random.default_rng(21)
    tris = _random_scene(rng)
    pts = np.column_stack([rng.uniform(-1, 1, 150), rng.uniform(-1, 1, 150), np.zeros(150)])
    nrm = unit(rng.normal(size=(150, 3)) * [0.3, 0.3, 1.0] + [0, 0, 1.5])
    ref, vis = trace(tris, pts, nrm, threads=1, chunk_points=64)
    assert vis.any() and not vis.all()
    for threads, chunk in [(1, 7), (2, 7), (2, 64), (2, 1000)]:
        bits, _ = trace(tris, pts, nrm, threads=threads, chunk_points=chunk)
        np.testing.assert_array_equal(bits, ref)


def test_trace_hands_on_every_chunk_and_keeps_none():
    """With ``consume`` the rows come chunk by chunk (from worker threads, in any order),
    together exactly the bits kept without it, and nothing is returned."""
    rng = np.random.default_rng(22)
    tris = _random_scene(rng)
    pts = np.column_stack([rng.uniform(-1, 1, 150), rng.uniform(-1, 1, 150), np.zeros(150)])
    nrm = unit(rng.normal(size=(150, 3)) * [0.3, 0.3, 1.0] + [0, 0, 1.5])
    ref, _ = trace(tris, pts, nrm, threads=1, chunk_points=64)
    cube = directions.cubemap(N)
    scene = visibility.build_occluder_scene(tris)
    for threads in (1, 4):
        got, chunks = np.zeros_like(ref), []

        def consume(start, stop, rows):
            chunks.append((start, stop))
            got[start:stop] = rows

        out = visibility.trace_visibility(scene, pts, nrm, cube, 1e-4, chunk_points=9,
                                          threads=threads, consume=consume)
        assert out is None
        assert sorted(chunks) == [(a, min(a + 9, 150)) for a in range(0, 150, 9)]
        np.testing.assert_array_equal(got, ref)


def test_trace_caps_the_rays_in_flight_over_the_threads(monkeypatch):
    """The default chunk shrinks with many threads: the hemisphere rays of every thread's
    chunk together stay within RAYS_IN_FLIGHT (temporaries bounded on any core count)."""
    cube = directions.cubemap(N)
    monkeypatch.setattr(visibility, "RAYS_IN_FLIGHT", 20 * cube.size)
    scene = visibility.build_occluder_scene(wall_triangles())
    for threads in (1, 4, 16):
        seen = []
        visibility.trace_visibility(
            scene, np.zeros((3000, 3)), np.tile([0.0, 0.0, 1.0], (3000, 1)), cube, 1e-4,
            threads=threads, consume=lambda a, b, rows: seen.append(b - a))
        chunk = max(seen)
        assert chunk == 8 or threads * chunk * cube.size / 2 <= visibility.RAYS_IN_FLIGHT
        assert chunk == max(8, min(1_000_000 // cube.size, 40 // threads)), (threads, chunk)


def test_trace_empty_points():
    bits, _ = trace(wall_triangles(), np.zeros((0, 3)), np.zeros((0, 3)))
    assert bits.shape == (0, 6 * N * N // 8)


@pytest.mark.parametrize("threads", [1, 2])
def test_cancel_raises(threads):
    cube = directions.cubemap(N)
    scene = visibility.build_occluder_scene(wall_triangles())
    pts = np.zeros((50, 3))
    nrm = np.tile([0, 0, 1.0], (50, 1))
    with pytest.raises(parallel.Cancelled):
        visibility.trace_visibility(scene, pts, nrm, cube, OFFSET, chunk_points=5,
                                    threads=threads, cancel=lambda: True)
    # cancel after the first chunk
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 1

    with pytest.raises(parallel.Cancelled):
        visibility.trace_visibility(scene, pts, nrm, cube, OFFSET, chunk_points=5,
                                    threads=threads, cancel=cancel)


@pytest.mark.parametrize("threads,chunk", [(1, 7), (2, 7), (2, 100)])
def test_progress_reaches_total(threads, chunk):
    cube = directions.cubemap(N)
    scene = visibility.build_occluder_scene(wall_triangles())
    pts = np.zeros((45, 3))
    nrm = np.tile([0, 0, 1.0], (45, 1))
    seen = []
    visibility.trace_visibility(scene, pts, nrm, cube, OFFSET, chunk_points=chunk,
                                threads=threads, progress=lambda d, t: seen.append((d, t)))
    assert len(seen) == -(-45 // chunk)
    assert all(t == 45 for _, t in seen)
    done = [d for d, _ in seen]
    assert done == sorted(done) and done[-1] == 45


def test_degenerate_triangles_dropped_from_scene():
    tris = np.concatenate([wall_triangles(), [[[0, 0, 1], [0, 0, 1], [1, 1, 1]]],
                           [[[np.nan, 0, 0], [0, 1, 0], [1, 0, 0]]]])
    cube = directions.cubemap(N)
    _, vis = trace(tris, np.zeros((1, 3)), [[0, 0, 1.0]])
    np.testing.assert_array_equal(vis[0], (cube.directions[:, 2] > 0) & (cube.directions[:, 0] < 0))


# --------------------------------------------------------------------------- #
# mesh
# --------------------------------------------------------------------------- #



def test_indexed_occluders_trace_as_the_same_triangles_one_by_one():
    """core.scene.mesh.Occluders (shared vertices, what the precompute gives Embree) block
    the rays their corners given one by one block (but for rays grazing an edge); a triangle with a non-finite
    vertex is left out as it is from the triangles one by one."""
    rng = np.random.default_rng(5)
    vertices = (rng.uniform(-1, 1, size=(60, 3)) * [1.0, 1.0, 0.3] + [0, 0, 0.8]).astype(
        np.float32)
    vertices[7] = np.nan
    triangles = rng.integers(0, 60, size=(80, 3)).astype(np.int32)
    occ = mesh.Occluders(vertices, triangles)
    pts = np.column_stack([rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200), np.zeros(200)])
    nrm = unit(rng.normal(size=(200, 3)) * [0.3, 0.3, 1.0] + [0, 0, 1.5])
    cube = directions.cubemap(N)
    bits = [visibility.trace_visibility(visibility.build_occluder_scene(t), pts, nrm, cube,
                                        OFFSET) for t in (occ, occ.positions)]
    vis = visibility.unpack_visibility(bits[0], cube.size)
    assert vis.any() and not vis.all()
    # two BVHs of the same float32 triangles: a ray grazing a shared edge may go either way
    other = visibility.unpack_visibility(bits[1], cube.size)
    assert (vis != other).mean() < 1e-3


def test_occluder_mesh_keeps_the_triangles_occluder_triangles_keeps():
    m = flat_cube()
    m.positions = m.positions.copy()
    m.positions[0] = m.positions[1]              # a zero-area face or two
    soup, ignored = mesh.occluder_triangles(m)
    occ, ignored_too = mesh.occluder_mesh(m)
    assert ignored == ignored_too > 0
    np.testing.assert_array_equal(occ.positions, soup.astype(np.float32))
    both = mesh.Occluders.join([occ, occ])
    np.testing.assert_array_equal(both.positions, np.concatenate([occ.positions] * 2))
