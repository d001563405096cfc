"""core.methods.auto.screen: the pixels each corner stands for in a camera's image (AUTO weighs its
per-vertex errors by them), against analytic projected areas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.scene import mesh, visibility
from prt_relight.core.methods.auto import screen

pytestmark = pytest.mark.skipif(not visibility.have_embree(), reason="needs embreex")


def _quad(centre, size, axis=2, flip=False):
    """A square of side ``size`` (two triangles, corners not shared) facing +axis."""
    u, v = [(1, 2), (2, 0), (0, 1)][axis]
    h = size / 2
    corners = []
    for a, b in ((-h, -h), (h, -h), (h, h), (-h, h)):
        p = np.array(centre, dtype=np.float64)
        p[u] += a
        p[v] += b
        corners.append(p)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    if flip:
        tris = tris[:, ::-1]
    n = np.zeros(3)
    n[axis] = -1.0 if flip else 1.0
    return mesh.MeshArrays(np.array(corners), np.arange(4), np.tile(n, (4, 1)), tris)


def _ortho(half=2.0):
    """Orthographic camera looking down -Z at [-half, half]² (GL clip matrix)."""
    return np.array([[1 / half, 0, 0, 0], [0, 1 / half, 0, 0], [0, 0, -0.1, 0],
                     [0, 0, 0, 1.0]])


def _perspective(eye, fov, near=0.1, far=100.0):
    """GL perspective looking down -Z from ``eye`` (square image)."""
    f = 1.0 / math.tan(fov / 2)
    P = np.array([[f, 0, 0, 0], [0, f, 0, 0],
                  [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                  [0, 0, -1.0, 0]])
    V = np.eye(4)
    V[:3, 3] = -np.asarray(eye, dtype=np.float64)
    return P @ V


def test_orthographic_square_covers_its_pixels_and_hides_what_is_behind():
    up = np.array([0.0, 0.0, 1.0])
    near = _quad((0.0, 0.0, 1.0), 1.0)
    far = _quad((0.0, 0.0, 0.0), 1.0)
    beside = _quad((1.2, 0.0, 0.0), 0.5)
    w = screen.corner_pixel_weights([near, far, beside], _ortho(), 100, 100, view_dir=up)
    assert w[0].sum() == pytest.approx(625.0)            # (1 / 4 of 100 px)²
    assert w[1].sum() == 0.0                            # hidden by the near square
    assert w[2].sum() == pytest.approx(156.25)          # (0.5 / 4 × 100)²
    # each corner carries a third of each triangle it is in
    assert w[0][[1, 3]] == pytest.approx([625 / 6] * 2)
    assert w[0][[0, 2]] == pytest.approx([625 / 3] * 2)
    # alone, nothing hides it
    alone = screen.corner_pixel_weights([far], _ortho(), 100, 100, view_dir=up)
    assert alone[0].sum() == pytest.approx(625.0)


def test_perspective_area_off_screen_and_behind_the_camera():
    eye = (0.0, 0.0, 5.0)
    fov = math.radians(40.0)
    clip = _perspective(eye, fov)
    f_px = 0.5 * 200 / math.tan(fov / 2)
    facing = _quad((0.3, -0.2, 1.0), 0.8)                # 4 units in front of the eye
    outside = _quad((30.0, 0.0, 1.0), 0.8)               # far outside the frame
    behind = _quad((0.0, 0.0, 7.0), 0.8)                 # behind the camera
    w = screen.corner_pixel_weights([facing, outside, behind], clip, 200, 200, eye=eye)
    assert w[0].sum() == pytest.approx((f_px * 0.8 / 4.0) ** 2, rel=1e-9)
    assert w[1].sum() == 0.0 and w[2].sum() == 0.0


def test_closed_box_counts_only_the_faces_the_camera_sees():
    faces = []
    for axis in range(3):
        for sign in (1, -1):
            c = [0.0, 0.0, 0.0]
            c[axis] = 0.5 * sign
            faces.append(_quad(c, 1.0, axis, flip=sign < 0))
    eye = np.array([3.0, 2.0, 4.0])
    # a camera looking at the origin from ``eye``
    fwd = -eye / np.linalg.norm(eye)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    V = np.eye(4)
    V[:3, :3] = np.stack([right, upv, -fwd])
    V[:3, 3] = -V[:3, :3] @ eye
    P = _perspective((0, 0, 0), math.radians(30.0))
    w = screen.corner_pixel_weights(faces, P @ V, 300, 300, eye=eye)
    seen = [float(x.sum()) > 0 for x in w]
    # +X, +Y, +Z faces face the eye (all coordinates positive); the others are hidden
    assert seen == [True, False, True, False, True, False]
    # a face's weight is its projected area: larger where it faces the eye more squarely
    normals = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    cosines = normals @ -fwd
    order = np.argsort(cosines)
    sums = np.array([w[0].sum(), w[2].sum(), w[4].sum()])
    assert list(np.argsort(sums)) == list(order)


def test_look_at_clip_centres_the_target():
    eye, target = np.array([2.0, -3.0, 1.5]), np.array([0.2, 0.1, 0.4])
    clip = screen.look_at_clip(eye, target, math.radians(50.0))
    h = clip @ np.append(target, 1.0)
    assert h[3] > 0 and np.allclose(h[:2] / h[3], 0.0, atol=1e-12)
    # a point 1 unit off the axis at distance d lands at f / d in NDC (f = 1/tan(fov/2))
    d = float(np.linalg.norm(target - eye))
    fwd = (target - eye) / d
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    h = clip @ np.append(target + right, 1.0)
    assert h[0] / h[3] == pytest.approx(1.0 / math.tan(math.radians(25.0)) / d)
    # looking straight down still gives a frame
    down = screen.look_at_clip([0, 0, 5.0], [0, 0, 0.0], 1.0)
    assert np.isfinite(down).all()
