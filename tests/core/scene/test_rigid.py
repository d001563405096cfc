"""core.scene.rigid (no Blender): a stored pose, a rigid motion told from an edit, and the stored
row of every shading point after a turn -- against the motions that made them."""

import numpy as np

from prt_relight.core.sphere import envmap
from prt_relight.core.scene import mesh, rigid


def _matrix(rotation, translation, scale=(1.0, 1.0, 1.0)):
    M = np.eye(4)
    M[:3, :3] = np.asarray(rotation) @ np.diag(scale)
    M[:3, 3] = translation
    return M


def _cube() -> mesh.MeshArrays:
    """A flat-shaded cube: three shading points (normals) per corner vertex."""
    pos = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    corners, normals, tris = [], [], []
    for f in faces:
        p = pos[list(f)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        base = len(corners)
        corners += list(f)
        normals += [n] * 4
        tris += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    mats = np.repeat([0, 1, 0, 1, 0, 1], 4)
    return mesh.MeshArrays(pos, corners, normals, tris, mats)


def _placed(arrays, M):
    """``arrays`` (object space) placed by the 4x4 ``M`` (normals by its rotation)."""
    R = rigid.rotation_part(M)
    return mesh.MeshArrays(arrays.positions @ M[:3, :3].T + M[:3, 3], arrays.corner_verts,
                           arrays.corner_normals @ R.T, arrays.triangles,
                           arrays.corner_materials)


R0 = envmap.euler_xyz_matrix(0.4, -0.3, 0.8)
R1 = envmap.euler_xyz_matrix(-1.2, 0.5, 2.9)


def test_rotation_part():
    M = _matrix(R0, (1.0, 2.0, 3.0), scale=(2.0, 0.5, 3.0))
    np.testing.assert_allclose(rigid.rotation_part(M), R0, atol=1e-12)
    # a reflection (negative scale): the nearest rotation, det +1
    F = rigid.rotation_part(_matrix(R0, (0, 0, 0), scale=(1.0, 1.0, -1.0)))
    np.testing.assert_allclose(F @ F.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(F), 1.0)


def test_local_probe_undoes_the_placement():
    local = np.random.default_rng(0).normal(size=(200, 3))
    M = _matrix(R0, (5.0, -1.0, 2.0), scale=(1.5, 1.5, 0.7))
    probe = rigid.local_probe(local @ M[:3, :3].T + M[:3, 3], M)
    idx = np.linspace(0, 199, 64).astype(np.int64)
    np.testing.assert_allclose(probe, local[idx], atol=1e-12)


def test_rigid_turn_tells_a_motion_from_an_edit():
    local = np.random.default_rng(1).normal(size=(100, 3))
    M0 = _matrix(R0, (1.0, 0.0, 0.5), scale=(2.0, 2.0, 2.0))
    probe = rigid.local_probe(local @ M0[:3, :3].T + M0[:3, 3], M0)
    M1 = _matrix(R1, (-3.0, 4.0, 1.0), scale=(2.0, 2.0, 2.0))
    turn = rigid.rigid_turn(M1, local @ M1[:3, :3].T + M1[:3, 3], rigid.rotation_part(M0), probe)
    np.testing.assert_allclose(turn, R1 @ R0.T, atol=1e-12)
    edited = local.copy()
    edited[0] += 0.01                         # vertex 0 is probed
    assert rigid.rigid_turn(M1, edited @ M1[:3, :3].T + M1[:3, 3], R0, probe) is None
    assert rigid.rigid_turn(M1, local[:50] @ M1[:3, :3].T, R0, probe) is None


def test_a_flattened_object_has_a_probe_and_is_told_moved_from_edited():
    """Scale 0 on an axis (scene fuzzer seeds 82 and 86: RSL's store of a flattened
    object crashed inverting its matrix): a finite probe, the same after a turn; an
    edit within its plane is still seen."""
    local = np.random.default_rng(2).normal(size=(100, 3))
    M0 = _matrix(R0, (1.0, 0.0, 0.5), scale=(2.0, 0.0, 2.0))
    probe = rigid.local_probe(local @ M0[:3, :3].T + M0[:3, 3], M0)
    idx = np.linspace(0, 99, 64).astype(np.int64)
    np.testing.assert_allclose(probe[:, [0, 2]], local[idx][:, [0, 2]], atol=1e-12)
    np.testing.assert_allclose(probe[:, 1], 0.0, atol=1e-12)
    M1 = _matrix(R1, (-3.0, 4.0, 1.0), scale=(2.0, 0.0, 2.0))
    turn = rigid.rigid_turn(M1, local @ M1[:3, :3].T + M1[:3, 3], rigid.rotation_part(M0), probe)
    np.testing.assert_allclose(turn, rigid.rotation_part(M1) @ rigid.rotation_part(M0).T,
                               atol=1e-12)
    edited = local.copy()
    edited[0, 0] += 0.01
    assert rigid.rigid_turn(M1, edited @ M1[:3, :3].T + M1[:3, 3], R0, probe) is None


def test_stored_rows_follow_the_turned_points():
    """Every current shading point of the turned cube maps to the stored point of the
    same vertex, material and (turned back) normal; the map is a permutation."""
    cube = _cube()
    then = _placed(cube, _matrix(R0, (0.0, 0.0, 0.0)))
    now = _placed(cube, _matrix(R1, (2.0, 1.0, 0.0)))
    pts0, pts1 = mesh.shading_points(then), mesh.shading_points(now)
    assert pts0.count == pts1.count == 24
    turn = R1 @ R0.T
    rows = rigid.stored_rows(pts1, now, turn)
    assert sorted(rows) == list(range(24))
    np.testing.assert_allclose(pts0.normals[rows], pts1.normals @ turn, atol=1e-9)
    np.testing.assert_array_equal(pts0.materials[rows], pts1.materials)
    vert0 = np.empty(24, np.int64)
    vert0[pts0.point_of_corner] = then.corner_verts
    vert1 = np.empty(24, np.int64)
    vert1[pts1.point_of_corner] = now.corner_verts
    np.testing.assert_array_equal(vert0[rows], vert1)
    # the order really changed (else the test shows nothing)
    assert not np.array_equal(rows, np.arange(24))


def test_point_keys_pack_normal_and_slot():
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0 + 1e-5], [1.0, 0.0, 0.0]])
    k = mesh.point_keys(n, np.array([0, 1, 0, 0]))
    assert k[0] != k[1] and k[0] == k[2] and k[0] != k[3]
    q = np.round(n[0] * 4096).astype(np.int64) + 4096
    assert k[0] == ((q[0] << 28) | (q[1] << 14) | q[2]) << 20
