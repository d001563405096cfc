# SPDX-License-Identifier: GPL-3.0-or-later
"""core.sphere.resample: the equirect's exact resampling to the cubemap (the overlap of every
pixel with every texel) against the image's energy, constant images, exact texel mean
directions and a fine grid over single pixels.  Pure numpy; no bpy."""

import numpy as np
import pytest

from prt_relight.core.sphere import directions, envmap


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def pixel_centre_direction(row, col, h, w):
    """Texture-space direction of an equirect pixel centre, from the Blender
    convention u = 0.5 - atan2(y, x)/2pi, v = acos(z)/pi (inverted by hand)."""
    theta = (row + 0.5) * np.pi / h
    phi = (0.5 - (col + 0.5) / w) * 2.0 * np.pi
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


# --------------------------------------------------------------------------- #
# envmap: WorldLighting / resampling
# --------------------------------------------------------------------------- #

def cube_energy(lighting, cube):
    return (lighting.radiance.astype(np.float64) * cube.solid_angles[:, None]).sum(axis=0)


TURNS = [(0.0, 0.0, 0.0), (0.0, 0.0, 1.234), (0.4, -0.7, 2.5), (np.pi / 2, 0.0, 0.0)]


@pytest.mark.parametrize("angles", TURNS)
@pytest.mark.parametrize("h,w,n", [(16, 32, 32), (64, 128, 32), (100, 201, 16), (256, 512, 64)])
def test_resample_preserves_energy_random_image(h, w, n, angles):
    rng = np.random.default_rng(h + n)
    img = rng.uniform(0.0, 4.0, size=(h, w, 3)).astype(np.float32)
    img[rng.uniform(size=(h, w)) < 0.2] = 0.0
    wl = envmap.WorldLighting(img, strength=1.7, rotation=envmap.euler_xyz_matrix(*angles))
    cl = wl.to_cubemap(n)
    cube = directions.cubemap(n)
    assert cl.radiance.shape == (cube.size, 3)
    assert np.all(np.isfinite(cl.radiance)) and np.all(cl.radiance >= 0)
    np.testing.assert_allclose(cube_energy(cl, cube), wl.total_power(), rtol=1e-6)
    # total power itself: sum over rows of mean radiance * exact band solid angle
    th = np.linspace(0, np.pi, h + 1)
    band = (np.cos(th[:-1]) - np.cos(th[1:])) * 2 * np.pi / w
    np.testing.assert_allclose(wl.total_power(),
                               1.7 * np.einsum("h,hwc->c", band, img.astype(np.float64)),
                               rtol=1e-10)


def test_resample_constant_image_mean_radiance():
    img = np.full((128, 256, 3), 0.7, np.float32)
    img[..., 2] = 2.0
    cube = directions.cubemap(16)
    cl = envmap.WorldLighting(img).to_cubemap(16)
    np.testing.assert_allclose(cube_energy(cl, cube), 4 * np.pi * np.array([0.7, 0.7, 2.0]),
                               rtol=1e-6)
    np.testing.assert_allclose(cl.radiance, np.tile([0.7, 0.7, 2.0], (cube.size, 1)), rtol=1e-6)


def exact_texel_means(n):
    """Mean direction vector of every texel, 1/(2 |T|) sum over its great-circle edges of
    (unit normal * arc angle) -- independent of the cubemap's own quadrature."""
    e = (2.0 * np.arange(n + 1) - n) / n
    t, s = np.meshgrid(e, e, indexing="ij")
    fa = directions.FACE_AXES
    p = fa[:, None, None, 0] + s[None, :, :, None] * fa[:, None, None, 1] \
        + t[None, :, :, None] * fa[:, None, None, 2]
    p = unit(p)
    c = np.stack([p[:, :-1, :-1], p[:, :-1, 1:], p[:, 1:, 1:], p[:, 1:, :-1]], axis=3)
    c = c.reshape(-1, 4, 3)
    cr = np.cross(c, np.roll(c, -1, axis=1))
    sin = np.linalg.norm(cr, axis=-1)
    ang = np.arctan2(sin, np.einsum("tkc,tkc->tk", c, np.roll(c, -1, axis=1)))
    m = 0.5 * np.einsum("tkc,tk->tc", cr / sin[..., None], ang)
    cube = directions.cubemap(n)
    m *= np.sign(np.einsum("tc,tc->t", m, cube.directions))[:, None]    # orientation
    return m / cube.solid_angles[:, None]


@pytest.mark.parametrize("h,w,n,angles", [
    (256, 512, 32, (0.0, 0.0, 0.0)),
    (256, 512, 32, (0.0, 0.0, 0.3)),
    (512, 1024, 64, (0.4, -0.7, 2.5)),
    (201, 400, 64, (np.pi / 2, 0.0, 0.0)),
    (1024, 2048, 128, (0.0, 0.0, 1.234)),
    (256, 512, 128, (1.1, 0.2, -0.4)),
])
def test_resample_constant_image_gives_constant_radiance(h, w, n, angles):
    """Exact overlaps: a constant image is a constant cubemap, and every texel's direction
    is its own exact mean direction (both to rounding)."""
    img = np.ones((h, w, 3), np.float32)
    cl = envmap.WorldLighting(img, rotation=envmap.euler_xyz_matrix(*angles)).to_cubemap(n)
    np.testing.assert_allclose(cl.radiance, 1.0, rtol=1e-6)      # float32 radiance
    cube = directions.cubemap(n)
    lr = envmap.resample_equirect_to_cubemap(img, cube, envmap.euler_xyz_matrix(*angles))
    energy = lr.radiance.astype(np.float64) * cube.solid_angles[:, None]
    np.testing.assert_allclose(energy.sum(axis=0), 4 * np.pi, rtol=1e-9)
    np.testing.assert_allclose(cl.directions, exact_texel_means(n), atol=1e-9)


def test_image_sums_kept_every_few_rows_give_the_same_texels():
    """Past their memory budget the per-column sums are kept every ``stride`` rows; the
    rows up to the next kept one are added per lookup, to the same result."""
    from prt_relight.core.sphere import resample
    rng = np.random.default_rng(0)
    img = rng.uniform(0.0, 3.0, (101, 202, 3)).astype(np.float32)
    R = envmap.euler_xyz_matrix(0.4, -0.7, 2.5)
    e1, m1 = resample.texel_sums(resample.ImageSums(img), 16, R)
    for budget in (10_000, 400_000):
        sums = resample.ImageSums(img, budget=budget)
        assert sums.stride > 1
        e2, m2 = resample.texel_sums(sums, 16, R)
        np.testing.assert_allclose(e2, e1, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(m2, m1, rtol=1e-11, atol=1e-14)


def sun_image(h, w, row, col, value=1e6):
    img = np.zeros((h, w, 3), np.float32)
    img[row, col] = value
    return img


def pixel_grid(h, w, row, col, k):
    """k x k equal-area sample directions (texture frame) over pixel (row, col) and the
    solid angle of each."""
    z0, z1 = np.cos((row + 1) * np.pi / h), np.cos(row * np.pi / h)
    z = z0 + (np.arange(k) + 0.5) / k * (z1 - z0)
    u = (col + (np.arange(k) + 0.5) / k) / w
    Z, U = np.meshgrid(z, u, indexing="ij")
    phi = (0.5 - U) * 2.0 * np.pi
    r = np.sqrt(1.0 - Z * Z)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), Z], axis=-1).reshape(-1, 3)
    return dirs, (z1 - z0) * 2.0 * np.pi / w / (k * k)


def brute_overlaps(h, w, row, col, n, R, k=1500):
    """Solid angle and first moment (world) of pixel (row, col) in every texel, by a
    k x k grid over the pixel."""
    tex, dw = pixel_grid(h, w, row, col, k)
    world = tex @ R                                     # tex = R @ world
    t = directions.direction_to_texel(world, n)
    size = 6 * n * n
    area = np.bincount(t, minlength=size) * dw
    mom = np.stack([np.bincount(t, weights=world[:, c], minlength=size) for c in range(3)], 1)
    return area, mom * dw


@pytest.mark.parametrize("h,w,n,row,col", [
    (512, 1024, 32, 100, 333),
    (512, 1024, 32, 255, 701),
    (1024, 2048, 64, 40, 1407),
    (1024, 2048, 64, 600, 12),
])
def test_one_pixel_sun_lands_in_its_texel(h, w, n, row, col):
    # Pixels inside one texel (no texel edge crosses them): the sun's energy and direction
    # go to that texel alone.
    img = sun_image(h, w, row, col)
    wl = envmap.WorldLighting(img)
    cl = wl.to_cubemap(n)
    cube = directions.cubemap(n)
    assert np.all(np.isfinite(cl.radiance))
    energy = cube_energy(cl, cube)
    np.testing.assert_allclose(energy, wl.total_power(), rtol=1e-6)
    sun = pixel_centre_direction(row, col, h, w)
    k = int(cube.texel_index(sun))
    e = cl.radiance[:, 0].astype(np.float64) * cube.solid_angles
    assert e[k] == pytest.approx(e.sum(), rel=1e-6)
    assert np.count_nonzero(cl.radiance[:, 0]) == 1
    ang = np.degrees(np.arccos(np.clip(cl.unit_directions[k] @ sun, -1, 1)))
    assert ang < 0.05
    # the point-sampled radiance in the sun direction is the sun
    assert float(wl.radiance(sun)[0]) == pytest.approx(1e6)


@pytest.mark.parametrize("h,w,n,angles", [(64, 128, 32, (0.0, 0.0, 0.0)),
                                          (256, 512, 32, (0.4, -0.7, 2.5)),
                                          (128, 256, 16, (0.0, 0.0, 0.77))])
def test_one_pixel_sun_keeps_its_direction_when_split(h, w, n, angles):
    """A sun pixel crossed by texel edges: every texel it lights points at the centroid of
    its own part of the sun (within 0.05 deg), and the lit texels together at the sun."""
    R = envmap.euler_xyz_matrix(*angles)
    cube = directions.cubemap(n)
    rng = np.random.default_rng(h + n)
    split = 0
    for _ in range(6):
        row, col = int(rng.integers(0, h)), int(rng.integers(0, w))
        cl = envmap.resample_equirect_to_cubemap(sun_image(h, w, row, col), cube, R)
        area, mom = brute_overlaps(h, w, row, col, n, R, k=600)
        lit = np.nonzero(cl.radiance[:, 0])[0]
        np.testing.assert_array_equal(lit, np.nonzero(area)[0])
        split += len(lit) > 1
        ang = np.arccos(np.clip(np.einsum("tc,tc->t", cl.unit_directions[lit], unit(mom[lit])),
                                -1, 1))
        assert np.degrees(ang).max() < 0.05
        y = cl.radiance[lit, 0].astype(np.float64) * cube.solid_angles[lit]
        total = (y[:, None] * cl.directions[lit]).sum(axis=0)
        assert np.degrees(np.arccos(min(1.0, unit(total) @ unit(mom.sum(axis=0))))) < 0.05
    assert split > 0


def test_one_pixel_sun_larger_than_a_texel():
    # A sun pixel larger than a texel: energy preserved, spread over the texels it overlaps.
    h, w, n = 64, 128, 32
    cube = directions.cubemap(n)
    img = sun_image(h, w, 20, 50)
    wl = envmap.WorldLighting(img)
    cl = wl.to_cubemap(n)
    assert np.all(np.isfinite(cl.radiance))
    np.testing.assert_allclose(cube_energy(cl, cube), wl.total_power(), rtol=1e-6)
    area, _ = brute_overlaps(h, w, 20, 50, n, np.eye(3), k=400)
    np.testing.assert_array_equal(np.nonzero(cl.radiance[:, 0])[0], np.nonzero(area)[0])
    assert len(np.nonzero(area)[0]) > 1
