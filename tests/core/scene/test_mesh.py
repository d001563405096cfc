# SPDX-License-Identifier: GPL-3.0-or-later
"""core.scene.mesh: grids, shading points of flat and smooth meshes, normal repair,
degenerate and occluding triangles, fingerprints, bounding diagonals and the inside of a
closed mesh, each against geometry built by hand.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.scene import mesh, visibility
from .geometry import box_triangles, flat_cube, unit


def test_grid_geometric_normals_point_up():
    g = mesh.grid(size=3.0, cuts=4, z=0.5)
    tp = g.triangle_positions
    gn = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
    assert np.all(gn[:, 2] > 0)
    np.testing.assert_allclose(tp[..., 2], 0.5)
    np.testing.assert_allclose(mesh.triangle_areas(tp).sum(), 9.0)


# --------------------------------------------------------------------------- #
# mesh
# --------------------------------------------------------------------------- #

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


def test_placed_arrays_place_and_repair_their_normals_each_time_they_are_read():
    """core.scene.mesh.PlacedArrays (an instance's arrays): the index arrays its source's,
    the positions and corner normals made when read (the normals repaired as repair_normals
    repairs a held copy, and counted by it); nothing a reader does to a copy it got changes
    the next one."""
    local = flat_cube()
    local.corner_normals[0] = np.nan
    local.corner_normals[7] = [0.0, 0.0, 3.0]
    turn = np.array([[0.0, -2.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # uneven scale
    made = []

    def place():
        made.append(1)
        return unit(local.corner_normals @ np.linalg.inv(turn))
    with np.errstate(invalid="ignore"):
        placed = mesh.PlacedArrays(local, lambda: local.positions @ turn.T, place)
        held = mesh.MeshArrays(placed.positions, local.corner_verts, place(), local.triangles)
    got = placed.positions
    got[:] = 0.0
    np.testing.assert_allclose(placed.positions, held.positions, atol=1e-12)
    assert mesh.repair_normals(held) == 1
    with np.errstate(invalid="ignore"):
        assert mesh.repair_normals(placed) == 1
        first = placed.corner_normals
        first[:] = 0.0
        np.testing.assert_allclose(placed.corner_normals, held.corner_normals, atol=1e-12)
    assert len(made) == 4
    assert placed.triangles is local.triangles and placed.corner_verts is local.corner_verts
    with np.errstate(invalid="ignore"):
        a, b = mesh.shading_points(placed), mesh.shading_points(held)
        assert len(made) == 5                          # read once by shading_points
        assert a.count == b.count
        np.testing.assert_allclose(a.normals, b.normals, atol=1e-12)
        assert len(mesh.fingerprint(placed)) == 40        # it reads the placed normals


def test_bounds_of_several_meshes_are_the_box_of_their_positions_together():
    a, b = flat_cube(), icosphere(1)
    b.positions = b.positions * 3.0 + [5.0, -1.0, 2.0]
    b.positions[0] = np.nan                        # left out, as bounding_box leaves it
    got = mesh.bounds([a, b])
    both = np.concatenate([a.positions, b.positions[1:]])
    np.testing.assert_allclose(got, [both.min(axis=0), both.max(axis=0)])
    assert mesh.bounds([]).shape == (0, 3)


def test_per_point_rows_of_per_corner_values():
    m = icosphere(1)                              # smooth: a point's corners are several
    sp = mesh.shading_points(m)
    rows = np.arange(sp.count * 3, dtype=np.float32).reshape(-1, 3)
    got = mesh.per_point(sp, rows[sp.point_of_corner])
    np.testing.assert_array_equal(got, rows)
    varied = rows[sp.point_of_corner].copy()
    varied[np.nonzero(sp.point_of_corner == sp.point_of_corner[0])[0][-1]] += 1.0
    assert mesh.per_point(sp, varied) is None       # two corners of a point disagree
    assert mesh.per_point(sp, rows) is None         # not per corner


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


# --------------------------------------------------------------------------- #
# mesh.seen_points: what a camera may see
# --------------------------------------------------------------------------- #

def _clip(eye, target, fov=0.8, near=0.1, far=100.0):
    """A GL world-to-clip matrix (perspective @ look-at, Z up)."""
    f = unit(np.asarray(target, float) - eye)
    s = unit(np.cross(f, [0.0, 0.0, 1.0]))
    u = np.cross(s, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = s, u, -f
    view[:3, 3] = -view[:3, :3] @ eye
    t = 1.0 / np.tan(fov / 2)
    proj = np.array([[t, 0, 0, 0], [0, t, 0, 0],
                     [0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)],
                     [0, 0, -1, 0]])
    return proj @ view


def test_seen_points_keep_the_front_of_a_closed_mesh_in_the_frustum():
    cube = flat_cube()
    pts = mesh.shading_points(cube)
    eye = np.array([5.0, 0.0, 0.0])
    clip = _clip(eye, [0.0, 0.0, 0.0])
    side = mesh.closed_side(cube)
    seen = mesh.seen_points(cube, pts, clip, side, eye=eye)
    # the face toward the camera only: its four points, whose normal is +x
    assert seen.sum() == 4 and (pts.normals[seen] @ [1.0, 0.0, 0.0] > 0.99).all()
    # an orthographic camera along +x sees the same face
    ortho = mesh.seen_points(cube, pts, clip, side, view_dir=np.array([1.0, 0.0, 0.0]))
    np.testing.assert_array_equal(ortho, seen)
    # open (side 0): every face in the frustum is kept, both windings
    assert mesh.seen_points(cube, pts, clip, 0, eye=eye).all()
    # behind the camera, or off to the side of the frustum: nothing
    assert not mesh.seen_points(cube, pts, _clip(eye, [10.0, 0.0, 0.0]), 0, eye=eye).any()
    assert not mesh.seen_points(cube, pts, _clip(eye, [5.0, 8.0, 0.0]), 0, eye=eye).any()


def test_seen_points_keep_a_triangle_the_frame_edge_cuts():
    ground = mesh.grid(size=20.0, cuts=4)
    pts = mesh.shading_points(ground)
    eye = np.array([0.0, 0.0, 3.0])
    seen = mesh.seen_points(ground, pts, _clip(eye, [0.0, 0.01, 0.0], fov=0.5), 0, eye=eye)
    # the narrow view meets the middle triangles only, and keeps their corners outside it
    assert 0 < seen.sum() < pts.count
    far = np.linalg.norm(pts.positions[seen, :2], axis=1).max()
    assert far > 3.0 * np.tan(0.25) * 1.5
