"""core.sphere.resample's overlap weights w(pixel, texel) against a 1500 x 1500 grid over
each pixel (pole rows, the seam, a cube corner, a face edge; unrotated and turned).  No bpy,
but 2.25 million directions per pixel: kept out of tests/core's minute."""

import numpy as np
import pytest

from prt_relight.core.sphere import directions, envmap

from ...core.sphere.test_resample import brute_overlaps, sun_image


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def pixel_of(d, h, w):
    u, v = envmap.direction_to_equirect_uv(d)
    return min(int(v * h), h - 1), min(int(u * w), w - 1)


@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (0.4, -0.7, 2.5)])
def test_overlap_weights_against_a_fine_grid(angles):
    """Weights w(pixel, texel) of the resampling (a one-pixel image of radiance 1 gives
    its pixel's row of weights) against a 1500 x 1500 grid over the pixel: pixels on both
    pole rows, on the seam (first and last column), at a cube corner (texels of three
    faces) and on a face edge."""
    h, w, n = 30, 60, 8            # no cube corner on a pixel boundary
    R = envmap.euler_xyz_matrix(*angles)
    cube = directions.cubemap(n)
    corner = R @ unit([1.0, 1.0, 1.0])
    edge = R @ unit([1.0, 0.0, 0.9])
    pixels = [(0, 5), (0, 40), (h - 1, w - 1), (h - 1, 0), (13, 0), (20, w - 1),
              pixel_of(corner, h, w), pixel_of(edge, h, w)]
    faces_seen = 0
    for row, col in pixels:
        cl = envmap.resample_equirect_to_cubemap(sun_image(h, w, row, col, 1.0), cube, R)
        weights = cl.radiance[:, 0].astype(np.float64) * cube.solid_angles
        area, _ = brute_overlaps(h, w, row, col, n, R)
        omega = area.sum()
        np.testing.assert_allclose(weights.sum(), omega, rtol=1e-6)   # float32 radiance
        np.testing.assert_allclose(weights, area, atol=1e-3 * omega)
        np.testing.assert_array_equal(weights > 0, area > 0)
        faces_seen = max(faces_seen, len(np.unique(np.nonzero(weights)[0] // (n * n))))
    assert faces_seen == 3
