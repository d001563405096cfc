"""core.scene.sides: an open surface's back side is traced only where the scene camera
sees it past the rest of the scene."""

import numpy as np

from prt_relight.core.scene import mesh, sides, visibility


def _plane(z: float, size: float = 2.0, flip: bool = False) -> mesh.MeshArrays:
    """A square at height ``z`` facing +z (``flip``: -z, its winding reversed)."""
    h = size / 2
    pos = np.array([(-h, -h, z), (h, -h, z), (h, h, z), (-h, h, z)], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    if flip:
        tris = tris[:, ::-1]
    corners = tris.reshape(-1)
    normal = np.array([0.0, 0.0, -1.0 if flip else 1.0])
    return mesh.MeshArrays(pos, corners, np.tile(normal, (len(corners), 1)),
                           np.arange(len(corners)).reshape(-1, 3))


def test_a_plane_seen_from_below_needs_its_back_side_and_from_above_does_not():
    plane = _plane(1.0)
    scene = visibility.build_occluder_scene(mesh.occluder_triangles(plane)[0])
    assert sides.needs_back_side(scene, plane, 1e-4, eye=(0.3, -2.0, -1.0))
    assert not sides.needs_back_side(scene, plane, 1e-4, eye=(0.3, -2.0, 3.0))
    assert not sides.needs_back_side(scene, plane, 1e-4, eye=None)    # no scene camera


def test_a_flipped_plane_turns_which_side_is_its_back():
    plane = _plane(1.0, flip=True)
    scene = visibility.build_occluder_scene(mesh.occluder_triangles(plane)[0])
    assert sides.needs_back_side(scene, plane, 1e-4, eye=(0.0, 0.5, 4.0))
    assert not sides.needs_back_side(scene, plane, 1e-4, eye=(0.0, 0.5, -4.0))


def test_a_back_hidden_behind_another_surface_is_not_traced():
    """A camera below a plane whose view of it is blocked by a wider plane under it."""
    plane, cover = _plane(1.0), _plane(0.5, size=40.0)
    tris = np.concatenate([mesh.occluder_triangles(m)[0] for m in (plane, cover)])
    scene = visibility.build_occluder_scene(tris)
    assert sides.camera_sees_back(plane, (0.0, 0.0, -1.0))            # without the scene
    assert not sides.needs_back_side(scene, plane, 1e-4, eye=(0.0, 0.0, -1.0))


def test_two_sided_meshes_copy_their_corners_with_flipped_normals():
    plane = _plane(0.0)
    both = mesh.with_back_sides(plane)
    assert both.two_sided and mesh.closed_side(both) == 2
    assert len(both.triangles) == 2 * len(plane.triangles)
    np.testing.assert_array_equal(mesh.corner_source(both), np.tile(np.arange(6), 2))
    np.testing.assert_allclose(both.corner_normals[6:], -plane.corner_normals)
    assert len(mesh.occluder_triangles(both)[0]) == len(plane.triangles)   # one occluder
    assert mesh.with_back_sides(both) is both
