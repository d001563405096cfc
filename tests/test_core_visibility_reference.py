# SPDX-License-Identifier: GPL-3.0-or-later
"""Checks of core/scene/visibility.py, core/methods/reference/shading.py and core/scene/mesh.py.

Visibility is checked against analytic occluders (ground plane, half-space
wall, closed box) and a brute-force numpy ray/triangle test; the reference
triple product against explicit python loops over texels.  No bpy.
"""

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.common import parallel
from prt_relight.core.methods.reference import shading as reference


N = 32
OFFSET = 1e-4


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def trace(tris, points, normals, n=N, offset=OFFSET, **kw):
    cube = directions.cubemap(n)
    scene = visibility.build_occluder_scene(np.asarray(tris, dtype=np.float64))
    bits = visibility.trace_visibility(scene, points, normals, cube, offset, **kw)
    assert bits.shape == (len(points), (cube.size + 7) // 8) and bits.dtype == np.uint8
    return bits, visibility.unpack_visibility(bits, cube.size)


def wall_triangles(x=0.01, size=1e3):
    a, b, c, d = ([x, -size, -size], [x, size, -size], [x, size, size], [x, -size, size])
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def box_triangles(lo=-1.0, hi=1.0):
    v = np.array([[x, y, z] for x in (lo, hi) for y in (lo, hi) for z in (lo, hi)], float)
    # index = 4*ix + 2*iy + iz
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [[v[a], v[b], v[c]], [v[a], v[c], v[d]]]
    return np.array(tris)


def white_world(n=N):
    return envmap.WorldLighting(None, color=(1.0, 1.0, 1.0)).to_cubemap(n)


LAMBERT = materials.Material(diffuse_albedo=(0.8, 0.5, 0.2))


def shade(bits, pts, nrm, lighting, material, n=N, eye=(0.0, 0.0, 10.0)):
    cube = directions.cubemap(n)
    return reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [material],
                                  np.asarray(eye, float), cube, lighting)


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


def test_grid_geometric_normals_point_up():
    g = mesh.grid(size=3.0, cuts=4, z=0.5)
    tp = g.triangle_positions
    gn = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
    assert np.all(gn[:, 2] > 0)
    np.testing.assert_allclose(tp[..., 2], 0.5)
    np.testing.assert_allclose(mesh.triangle_areas(tp).sum(), 9.0)


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


def test_shade_lambert_uniform_white():
    cube = directions.cubemap(N)
    light = white_world()
    pts = np.zeros((2, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    bits_open, vis_open = trace(np.zeros((0, 3, 3)), pts, nrm)
    np.testing.assert_array_equal(vis_open[0], cube.directions[:, 2] > 0)
    out = shade(bits_open, pts, nrm, light, LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (2, 1)), atol=1e-3)
    irr = reference.diffuse_irradiance(bits_open, nrm, cube, light)
    np.testing.assert_allclose(irr, np.pi, rtol=1e-4)
    bits_wall, _ = trace(wall_triangles(), pts, nrm)
    out = shade(bits_wall, pts, nrm, light, LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (2, 1)) / 2, atol=5e-3)


def test_shade_lambert_uniform_white_random_normals():
    # Unoccluded, arbitrary normal: albedo to the horizon-straddling error (< 2e-3 * albedo/pi)
    rng = np.random.default_rng(4)
    nrm = unit(rng.normal(size=(20, 3)))
    pts = rng.normal(size=(20, 3))
    bits, _ = trace(np.zeros((0, 3, 3)), pts, nrm)
    out = shade(bits, pts, nrm, white_world(), LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (20, 1)), atol=1e-3)


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
    # the points off the ground keep the plain step along the normal
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
# reference vs brute force
# --------------------------------------------------------------------------- #

def brute_visible(tris, origin_base, offset, dirs):
    """Möller-Trumbore in float64 for each direction; also returns ambiguity margin."""
    tris = np.asarray(tris, float)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    vis = np.ones(len(dirs), bool)
    margin = np.full(len(dirs), np.inf)
    for k, d in enumerate(dirs):
        o = origin_base + offset * d
        pvec = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = o - v0
        u = np.einsum("ij,ij->i", tvec, pvec) * inv
        q = np.cross(tvec, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        m = np.minimum(np.minimum(u, v), 1.0 - u - v)
        front = ok & (t > 0)
        hit = front & (m >= 0)
        vis[k] = not hit.any()
        if front.any():
            margin[k] = np.abs(m[front]).min()
    return vis, margin


def test_reference_matches_brute_force_loops():
    n = 16
    cube = directions.cubemap(n)
    rng = np.random.default_rng(12)
    # a few triangles above a ground point at the origin
    tris = rng.uniform(-0.8, 0.8, size=(5, 3, 3)) + [0, 0, 1.0]
    tris[:, :, 2] = np.abs(tris[:, :, 2]) + 0.2
    pts = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [-0.3, 0.25, 0.0]])
    nrm = unit(np.array([[0.0, 0.0, 1.0], [0.2, 0.1, 1.0], [-0.3, 0.0, 1.0]]))
    offset = 1e-4
    bits, vis = trace(tris, pts, nrm, n=n, offset=offset)

    # visibility vs float64 brute force, ignoring texels grazing a triangle edge or the horizon
    for p in range(len(pts)):
        bv, margin = brute_visible(tris, pts[p] + offset * nrm[p], offset, cube.directions)
        bv &= (cube.directions @ nrm[p]) > 0
        # the hemisphere test is float32 (visibility.hemisphere_mask): skip the horizon
        sure = (margin > 1e-4) & (np.abs(cube.directions @ nrm[p]) > 1e-6)
        np.testing.assert_array_equal(vis[p][sure], bv[sure])
        assert sure.sum() > 0.98 * cube.size
    assert 0 < vis.sum() < (nrm @ cube.directions.T > 0).sum()   # some texels are blocked

    # random coloured environment
    img = rng.uniform(0.0, 3.0, size=(32, 64, 3)).astype(np.float32)
    img[5, 20] = 500.0                                              # a bright spot
    light = envmap.WorldLighting(img, strength=0.8).to_cubemap(n)
    mat = materials.Material(diffuse_albedo=(0.6, 0.3, 0.1), specular_color=(0.9, 0.7, 0.5),
                        roughness=0.3, distribution="BECKMANN")
    spec_only = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=mat.specular_color,
                              roughness=0.3, distribution="BECKMANN")
    eye = np.array([1.5, -2.0, 3.0])
    got = reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [mat], eye, cube,
                                 light)
    unit_dirs = light.unit_directions
    for p in range(len(pts)):
        view = unit(eye - pts[p])
        acc = np.zeros(3)
        for k in range(cube.size):
            if not vis[p, k]:
                continue
            L = light.radiance[k].astype(np.float64)
            cos_mean = max(0.0, float(nrm[p] @ light.directions[k]))
            diffuse = np.array(mat.diffuse_albedo) / np.pi * cos_mean
            spec = brdf.reflectance_cosine(spec_only, nrm[p][None], view[None],
                                           unit_dirs[k][None])[0, 0].astype(np.float64)
            acc += L * (diffuse + spec) * cube.solid_angles[k]
        np.testing.assert_allclose(got[p], acc, rtol=1e-4)
    assert np.all(got > 0)

    # diffuse-only material: shade = albedo/pi * diffuse_irradiance
    irr = reference.diffuse_irradiance(bits, nrm, cube, light)
    lam = reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [LAMBERT], eye,
                                 cube, light)
    np.testing.assert_allclose(lam, irr * np.array(LAMBERT.diffuse_albedo) / np.pi, rtol=1e-5)


def test_reference_material_slots_and_view_dirs():
    cube = directions.cubemap(N)
    pts = np.zeros((4, 3))
    nrm = np.tile([0, 0, 1.0], (4, 1))
    bits, _ = trace(np.zeros((0, 3, 3)), pts, nrm)
    light = white_world()
    m0 = materials.Material(diffuse_albedo=(0.2, 0.2, 0.2))
    m1 = materials.Material(diffuse_albedo=(0.9, 0.1, 0.4))
    out = reference.shade_points(bits, pts, nrm, np.array([0, 1, 0, 7]), [m0, m1],
                                 np.array([0, 0, 5.0]), cube, light)
    np.testing.assert_allclose(out[0], m0.diffuse_albedo, atol=1e-3)
    np.testing.assert_allclose(out[1], m1.diffuse_albedo, atol=1e-3)
    # a slot past the table is the last one (Cycles clamps the material index)
    np.testing.assert_allclose(out[3], m1.diffuse_albedo, atol=1e-3)
    # view_dirs overrides eye
    glossy = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=0.5)
    vd = np.tile([0.0, 0.0, 1.0], (4, 1))
    a = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [glossy],
                               np.array([100.0, 0, 0.01]), cube, light, view_dirs=vd)
    b = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [glossy],
                               np.array([0, 0, 5.0]), cube, light)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    # white furnace: the cubemap sum equals the lobe's directional albedo computed
    # with a fine equal-area hemisphere quadrature (independent directions)
    hd, hw = directions.hemisphere_uniform(512)
    for rough, view in [(0.5, [0.0, 0.0, 1.0]), (0.7, [0.6, 0.0, 0.8]), (0.7, [0.0, -0.96, 0.28])]:
        g = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=rough)
        albedo = (brdf.specular_cosine(g, nrm[:1], np.array([view]), hd)[0].astype(np.float64)
                  * hw).sum()
        got = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [g], None, cube,
                                     light, view_dirs=np.tile(view, (4, 1)))
        np.testing.assert_allclose(got, albedo, rtol=2e-3)


# --------------------------------------------------------------------------- #
# mesh
# --------------------------------------------------------------------------- #

def flat_cube():
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    # outward-wound quads; index = 4*ix + 2*iy + iz
    quads = [((0, 1, 3, 2), [-1, 0, 0]), ((4, 6, 7, 5), [1, 0, 0]), ((0, 4, 5, 1), [0, -1, 0]),
             ((2, 3, 7, 6), [0, 1, 0]), ((0, 2, 6, 4), [0, 0, -1]), ((1, 5, 7, 3), [0, 0, 1])]
    corner_verts, corner_normals, tris = [], [], []
    for q, nrm in quads:
        base = len(corner_verts)
        corner_verts += list(q)
        corner_normals += [nrm] * 4
        tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return mesh.MeshArrays(v, corner_verts, corner_normals, tris)


def test_flat_cube_shading_points():
    m = flat_cube()
    assert len(m.corner_verts) == 24 and len(m.triangles) == 12
    tp = m.triangle_positions
    gn = unit(np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0]))
    np.testing.assert_allclose(gn, m.corner_normals[m.triangles[:, 0]], atol=1e-12)
    sp = mesh.shading_points(m)
    assert sp.count == 24
    # each cube vertex has three points whose normals are its three face normals
    for vi, pos in enumerate(m.positions):
        sel = np.all(sp.positions == pos, axis=1)
        assert sel.sum() == 3
        np.testing.assert_allclose(np.sort(sp.normals[sel] @ np.sign(pos)), [1, 1, 1])
    # corners map to a point at their own vertex with their own normal
    np.testing.assert_array_equal(sp.positions[sp.point_of_corner], m.positions[m.corner_verts])
    np.testing.assert_allclose(sp.normals[sp.point_of_corner], m.corner_normals)
    # deterministic
    sp2 = mesh.shading_points(flat_cube())
    np.testing.assert_array_equal(sp.point_of_corner, sp2.point_of_corner)
    # materials split points: give the top face slot 1
    mats = np.zeros(24, np.int64)
    mats[20:24] = 1
    m3 = mesh.MeshArrays(m.positions, m.corner_verts, m.corner_normals, m.triangles, mats)
    sp3 = mesh.shading_points(m3)
    assert sp3.count == 24 and (sp3.materials == 1).sum() == 4


def icosphere(subdiv=1):
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
         [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = [list(unit(x)) for x in v]
    for _ in range(subdiv):
        cache, nf = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                cache[key] = len(v)
                v.append(list(unit(np.add(v[a], v[b]) / 2)))
            return cache[key]
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = nf
    v = np.array(v)
    f = np.array(f)
    corner_verts = f.reshape(-1)
    return mesh.MeshArrays(v * 2.0, corner_verts, v[corner_verts],
                           np.arange(len(corner_verts)).reshape(-1, 3))


def test_smooth_sphere_one_point_per_vertex():
    m = icosphere(2)
    assert len(m.positions) == 162
    sp = mesh.shading_points(m)
    assert sp.count == 162
    np.testing.assert_allclose(np.linalg.norm(sp.normals, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(sp.normals, unit(sp.positions), atol=1e-12)
    assert len(np.unique(sp.positions, axis=0)) == 162


def test_repair_normals():
    m = flat_cube()
    m.corner_normals[0] = np.nan            # vertex 0: other corners valid
    m.corner_normals[5] = 0.0
    m.corner_normals[7] = [0.0, 0.0, 3.0]   # not unit but valid
    v0 = m.corner_verts[0]
    expected0 = unit(sum(m.corner_normals[c] for c in range(24)
                         if m.corner_verts[c] == v0 and c != 0))
    count = mesh.repair_normals(m)
    assert count == 2
    assert np.all(np.isfinite(m.corner_normals))
    np.testing.assert_allclose(np.linalg.norm(m.corner_normals, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(m.corner_normals[0], expected0, atol=1e-12)
    np.testing.assert_allclose(m.corner_normals[7], [0, 0, 1], atol=1e-12)
    # a vertex with no valid normal at all gets +Z
    m2 = mesh.MeshArrays(np.eye(3), [0, 1, 2], [[0, 0, 0], [np.nan, 0, 0], [0, 0, 0]],
                         [[0, 1, 2]])
    assert mesh.repair_normals(m2) == 3
    np.testing.assert_allclose(m2.corner_normals, np.tile([0, 0, 1.0], (3, 1)))
    assert mesh.repair_normals(m2) == 0


def test_degenerate_triangles():
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [np.nan, 0, 0]], float)
    tris_v = np.array([[0, 1, 2],      # fine
                       [0, 1, 3],      # collinear -> zero area
                       [1, 1, 2],      # repeated vertex
                       [0, 1, 4],      # NaN vertex
                       [2, 1, 0]])     # fine (other winding)
    cv = tris_v.reshape(-1)
    m = mesh.MeshArrays(pos, cv, np.tile([0, 0, 1.0], (len(cv), 1)),
                        np.arange(len(cv)).reshape(-1, 3))
    np.testing.assert_array_equal(mesh.degenerate_triangles(m), [False, True, True, True, False])
    np.testing.assert_allclose(mesh.triangle_areas(m.triangle_positions)[[0, 4]], 0.5)
    # relative to scale: a tiny (but non-zero) triangle on a huge mesh
    pos2 = np.array([[0, 0, 0], [1e-7, 0, 0], [0, 1e-7, 0], [1e3, 1e3, 0]], float)
    m2 = mesh.MeshArrays(pos2, [0, 1, 2, 0, 3, 1], np.tile([0, 0, 1.0], (6, 1)),
                         [[0, 1, 2], [3, 4, 5]])
    assert mesh.degenerate_triangles(m2).tolist() == [True, False]
    assert mesh.degenerate_triangles(m2, scale=1e-6).tolist() == [False, False]


def test_occluders_are_the_faces_the_warning_keeps():
    """The precompute's warning counts the zero-area faces it ignores; the occluder scene
    holds exactly the others.  A face that is zero-area relative to its mesh but not in
    float32 (a 0.02 x 0.01 triangle on a mesh 1e4 across) is ignored by both: a ray
    through it is not blocked, while a ray through a kept face of the same mesh is."""
    small = [[0.0, 0.0, 1.0], [0.02, 0.0, 1.0], [0.0, 0.01, 1.0]]        # area 1e-4
    big = [[3.0, -1.0, 1.0], [5.0, -1.0, 1.0], [4.0, 1.0, 1.0]]
    far = [[1e4, 0.0, 0.0], [1e4, 1.0, 0.0], [1e4, 0.0, 1.0]]
    collapsed = [[5.0, 5.0, 5.0], [5.0, 5.0, 5.0], [6.0, 5.0, 5.0]]
    tris = np.array([small, big, far, collapsed])
    m = mesh.MeshArrays(tris.reshape(-1, 3), np.arange(12), np.tile([0, 0, 1.0], (12, 1)),
                        np.arange(12).reshape(-1, 3))
    kept, ignored = mesh.occluder_triangles(m)
    assert ignored == int(mesh.degenerate_triangles(m).sum()) == 2
    np.testing.assert_array_equal(kept, tris[[1, 2]])
    up = np.array([[0.0, 0.0, 1.0]], np.float32)
    through_small = np.array([[0.005, 0.0025, 0.0]], np.float32)
    through_big = np.array([[4.0, -0.5, 0.0]], np.float32)
    scene = visibility.build_occluder_scene(kept)
    assert scene.run(through_big, up, query="OCCLUDED")[0] != -1
    assert scene.run(through_small, up, query="OCCLUDED")[0] == -1
    # every face handed to Embree (what its own float32 area test would keep) blocks it
    every = visibility.build_occluder_scene(tris)
    assert every.run(through_small, up, query="OCCLUDED")[0] != -1


def test_fingerprint():
    a, b = flat_cube(), flat_cube()
    assert mesh.fingerprint(a) == mesh.fingerprint(b)
    b.positions[3, 1] += 1e-3
    assert mesh.fingerprint(a) != mesh.fingerprint(b)
    c = flat_cube()
    c.corner_normals[4] = -c.corner_normals[4]
    assert mesh.fingerprint(a) != mesh.fingerprint(c)
    d = flat_cube()
    d.corner_materials[0] = 2
    assert mesh.fingerprint(a) != mesh.fingerprint(d)
    e = flat_cube()
    e.triangles = e.triangles[:, [0, 2, 1]].copy()
    assert mesh.fingerprint(a) != mesh.fingerprint(e)


def test_bounding_diagonal():
    assert mesh.bounding_diagonal(flat_cube().positions) == pytest.approx(2 * np.sqrt(3))
    assert mesh.bounding_diagonal(np.array([[np.nan, 0, 0], [1, 1, 1], [0, 0, 0]])) == \
        pytest.approx(np.sqrt(3))
    assert mesh.bounding_diagonal(np.zeros((0, 3))) == 0.0


# --------------------------------------------------------------------------- #
# mesh.closed_side: which side of a closed mesh is its inside
# --------------------------------------------------------------------------- #

def _box_mesh(sign=1.0, split=False):
    tris = box_triangles() * np.array([1.0, 1.0, sign])
    if split:                                # every triangle its own vertices (an import)
        pos = tris.reshape(-1, 3)
        return mesh.MeshArrays(pos, np.arange(len(pos)), np.tile([0.0, 0.0, 1.0], (len(pos), 1)),
                               np.arange(len(pos)).reshape(-1, 3))
    pos, verts = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
    return mesh.MeshArrays(pos, verts.reshape(-1), np.tile([0.0, 0.0, 1.0], (verts.size, 1)),
                           np.arange(verts.size).reshape(-1, 3))


def test_closed_side_of_open_closed_and_mirrored_meshes():
    outward = _box_mesh()
    tp = outward.triangle_positions
    centre_to_face = tp.mean(axis=1)
    geo = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
    side = 1 if (np.einsum("ij,ij->i", geo, centre_to_face) > 0).all() else -1
    assert mesh.closed_side(outward) == side                 # the winding's own sign
    assert mesh.closed_side(_box_mesh(-1.0)) == -side        # mirrored: winds the other way
    assert mesh.closed_side(_box_mesh(split=True)) == side   # welded by position
    open_box = _box_mesh()
    open_box.triangles = open_box.triangles[2:]              # one face missing
    assert mesh.closed_side(open_box) == 0
    assert mesh.closed_side(mesh.grid()) == 0


def test_coarse_edge_share_counts_edges_across_a_shadow_edge():
    """A 4 x 4 grid whose points at x < 0 see no sky and the others all of it: the edges
    that join the two halves jump by 1, the others by 0; counted by hand."""
    g = mesh.grid(2.0, 4)
    pts = mesh.shading_points(g)
    cube = directions.cubemap(8)
    open_bits = np.packbits(visibility.hemisphere_mask(pts.normals, cube), axis=1)
    bits = np.where((pts.positions[:, 0] < -1e-9)[:, None], 0, open_bits).astype(np.uint8)
    tri_points = pts.point_of_corner[g.triangles]
    shaded = pts.positions[:, 0] < -1e-9
    edges = np.concatenate([tri_points[:, [0, 1]], tri_points[:, [1, 2]], tri_points[:, [2, 0]]])
    want = float(np.mean(shaded[edges[:, 0]] != shaded[edges[:, 1]]))
    assert 0.0 < want < 1.0
    got = reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner, g.triangles, cube)
    assert got == pytest.approx(want)
    # a jump of exactly the whole sky is over any threshold below 1, none at 1
    assert reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner, g.triangles,
                                       cube, jump=1.0) == 0.0
    assert reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner,
                                       np.zeros((0, 3), np.int64), cube) == 0.0


def test_point_views():
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]])
    np.testing.assert_allclose(reference.point_views(pos, eye=np.array([0.0, 0.0, 3.0])),
                               [[0.0, 0.0, 1.0], np.array([-1.0, -2.0, 1.0]) / np.sqrt(6.0)])
    ortho = reference.point_views(pos, eye=None, view_dir=np.array([0.0, 1.0, 0.0]))
    assert ortho.shape == (2, 3) and np.all(ortho == [0.0, 1.0, 0.0])
