# SPDX-License-Identifier: GPL-3.0-or-later
"""Checks of core/sphere/directions.py and core/sphere/envmap.py against analytic values.

Pure numpy (+ OpenImageIO for the EXR round trip); no bpy.
"""

import numpy as np
import pytest

from prt_relight.core.sphere import directions, envmap

RESOLUTIONS = (32, 64, 128)


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_unit(rng, n):
    return unit(rng.normal(size=(n, 3)))


def pixel_centre_direction(row, col, h, w):
    """Texture-space direction of an equirect pixel centre, from the Blender
    convention u = 0.5 - atan2(y, x)/2pi, v = acos(z)/pi (inverted by hand)."""
    theta = (row + 0.5) * np.pi / h
    phi = (0.5 - (col + 0.5) / w) * 2.0 * np.pi
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


# --------------------------------------------------------------------------- #
# directions
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("n", RESOLUTIONS)
def test_cubemap_solid_angles_sum_to_4pi(n):
    cube = directions.cubemap(n)
    assert cube.size == 6 * n * n
    assert cube.solid_angles.shape == (6 * n * n,)
    assert np.all(cube.solid_angles > 0)
    np.testing.assert_allclose(cube.solid_angles.sum(), 4.0 * np.pi, rtol=1e-12)


@pytest.mark.parametrize("n", RESOLUTIONS)
def test_cubemap_directions_unit_and_texel_roundtrip(n):
    cube = directions.cubemap(n)
    np.testing.assert_allclose(np.linalg.norm(cube.directions, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(directions.direction_to_texel(cube.directions, n),
                                  np.arange(cube.size))
    np.testing.assert_array_equal(cube.texel_index(cube.directions), np.arange(cube.size))
    # Each face holds the directions whose major axis is that face's axis.
    faces = np.arange(cube.size) // (n * n)
    major = np.argmax(np.abs(cube.directions), axis=1)
    sign_neg = cube.directions[np.arange(cube.size), major] < 0
    np.testing.assert_array_equal(faces, 2 * major + sign_neg)


@pytest.mark.parametrize("n", RESOLUTIONS)
def test_mean_directions_integrate_clamped_cosine(n):
    cube = directions.cubemap(n)
    rng = np.random.default_rng(n)
    normals = random_unit(rng, 64)
    normals = np.vstack([normals, [[0, 0, 1], [0, 0, -1], [1, 0, 0]]])
    # integral over the sphere of max(0, n.w) dw = pi
    irr = np.maximum(0.0, normals @ cube.mean_directions.T) @ cube.solid_angles
    np.testing.assert_allclose(irr, np.pi, atol=2e-3)
    # integral of w dw over the sphere = 0
    np.testing.assert_allclose(cube.mean_directions.T @ cube.solid_angles, 0.0, atol=1e-12)
    # mean directions are shorter than one but close to it, and inside their texel
    length = np.linalg.norm(cube.mean_directions, axis=1)
    assert np.all(length < 1.0) and np.all(length > 0.99)
    np.testing.assert_array_equal(cube.texel_index(cube.mean_directions), np.arange(cube.size))


@pytest.mark.parametrize("n", (32, 64))
def test_axis_normal_mean_cosine_is_exact(n):
    # For n = +Z no texel straddles the horizon, so the sum is pi to quadrature accuracy.
    cube = directions.cubemap(n)
    for axis in np.eye(3).tolist() + (-np.eye(3)).tolist():
        irr = np.maximum(0.0, cube.mean_directions @ np.asarray(axis)) @ cube.solid_angles
        # mean directions come from an 8x8 midpoint rule per texel: ~5e-6 at N=32
        np.testing.assert_allclose(irr, np.pi, rtol=2e-5)


@pytest.mark.parametrize("face,row,col", [(2, 3, 17), (4, 15, 16), (5, 0, 0), (1, 31, 7)])
def test_single_texel_solid_angle_and_mean_by_quadrature(face, row, col):
    n = 32
    cube = directions.cubemap(n)
    k = (face * n + row) * n + col
    a, U, V = directions.FACE_AXES[face]
    s0, t0 = -1.0 + 2.0 * col / n, -1.0 + 2.0 * row / n
    h = 2.0 / n
    m = 400   # dense midpoint rule on the face plane
    c = (np.arange(m) + 0.5) / m * h
    S, T = np.meshgrid(s0 + c, t0 + c, indexing="xy")
    r2 = 1.0 + S * S + T * T
    dens = r2 ** -1.5 * (h / m) ** 2
    omega = dens.sum()
    np.testing.assert_allclose(cube.solid_angles[k], omega, rtol=1e-6)
    # the sample directions all belong to texel k
    w = unit(a[None, None] + S[..., None] * U + T[..., None] * V)
    assert np.all(directions.direction_to_texel(w, n) == k)
    # centre direction
    np.testing.assert_allclose(cube.directions[k],
                               unit(a + (s0 + h / 2) * U + (t0 + h / 2) * V), atol=1e-12)
    # mean direction = (1/omega) * integral of w dw
    mean = np.einsum("ij,ijk->k", dens, w) / omega
    # (core uses an 8x8 sub-texel midpoint rule: error ~1e-5 at N=32)
    np.testing.assert_allclose(cube.mean_directions[k], mean, atol=2e-5)
    assert np.linalg.norm(cube.mean_directions[k]) == pytest.approx(np.linalg.norm(mean), abs=1e-5)


def test_solid_angles_by_monte_carlo_per_face_band():
    # Independent of the face-plane parametrisation: uniform sphere samples
    # binned with direction_to_texel; compare summed solid angles of 4x4 blocks.
    n = 16
    cube = directions.cubemap(n)
    rng = np.random.default_rng(7)
    count = 2_000_000
    d = random_unit(rng, count)
    hist = np.bincount(directions.direction_to_texel(d, n), minlength=cube.size)
    est = hist.reshape(6, 4, 4, 4, 4).sum(axis=(2, 4)) * (4 * np.pi / count)
    exact = cube.solid_angles.reshape(6, 4, 4, 4, 4).sum(axis=(2, 4))
    # relative standard error ~ 1/sqrt(count * p) with p ~ 1/96 -> ~0.7 %
    np.testing.assert_allclose(est, exact, rtol=0.04)


@pytest.mark.parametrize("normal", [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0],
                                    [0, 0, 0.9999999999], [1e-9, 0, -1]])
def test_orthonormal_frame_special(normal):
    nrm = unit(np.array([normal], dtype=np.float64))
    t, b = directions.orthonormal_frame(nrm)
    _check_frame(nrm, t, b)


def test_orthonormal_frame_random():
    rng = np.random.default_rng(3)
    nrm = random_unit(rng, 1000)
    t, b = directions.orthonormal_frame(nrm)
    _check_frame(nrm, t, b)


def _check_frame(nrm, t, b):
    assert np.all(np.isfinite(t)) and np.all(np.isfinite(b))
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, b), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, nrm), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", b, nrm), 0.0, atol=1e-12)
    # right handed: t x b = n
    np.testing.assert_allclose(np.cross(t, b), nrm, atol=1e-12)


def test_hemisphere_uniform_and_fibonacci():
    d, w = directions.hemisphere_uniform(16)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.all(d[:, 2] > 0)
    np.testing.assert_allclose(w.sum(), 2 * np.pi, rtol=1e-12)
    # integral of cos over the hemisphere = pi (midpoint rule in cos theta is exact for linear)
    np.testing.assert_allclose((d[:, 2] * w).sum(), np.pi, rtol=1e-12)
    f = directions.fibonacci_sphere(1000)
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(f.mean(axis=0), 0.0, atol=2e-3)


# --------------------------------------------------------------------------- #
# envmap: convention
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("d,u,v", [
    ([1, 0, 0], 0.5, 0.5),
    ([0, 1, 0], 0.25, 0.5),
    ([0, -1, 0], 0.75, 0.5),
    ([-1, 0, 0], 0.0, 0.5),
    ([0, 0, 1], None, 0.0),
    ([0, 0, -1], None, 1.0),
    ([1, 1, 0], 0.375, 0.5),
    ([1, 0, 1], 0.5, 0.25),
])
def test_direction_to_equirect_uv_known(d, u, v):
    uu, vv = envmap.direction_to_equirect_uv(unit(np.array(d, dtype=np.float64)))
    if u is not None:
        assert float(np.mod(uu - u + 0.5, 1.0) - 0.5) == pytest.approx(0.0, abs=1e-12)
    assert float(vv) == pytest.approx(v, abs=1e-12)


def test_direction_to_equirect_uv_formula_random():
    rng = np.random.default_rng(11)
    d = random_unit(rng, 5000)
    u, v = envmap.direction_to_equirect_uv(d)
    assert np.all((u >= 0) & (u < 1)) and np.all((v >= 0) & (v <= 1))
    ref_u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)
    np.testing.assert_allclose(np.mod(u - ref_u + 0.5, 1.0) - 0.5, 0.0, atol=1e-12)
    np.testing.assert_allclose(v, np.arccos(d[:, 2]) / np.pi, atol=1e-12)


@pytest.mark.parametrize("h,w,s", [(8, 16, 1), (16, 32, 3), (33, 70, 2)])
def test_equirect_directions(h, w, s):
    dirs, sa = envmap.equirect_directions(h, w, s)
    assert dirs.shape == (h * s, w * s, 3) and sa.shape == (h * s, w * s)
    np.testing.assert_allclose(sa.sum(), 4 * np.pi, rtol=1e-12)
    assert np.all(sa > 0)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    u, v = envmap.direction_to_equirect_uv(dirs)
    # (sub-)pixel centres map back to their own (sub-)pixel centres
    np.testing.assert_allclose(u, ((np.arange(w * s) + 0.5) / (w * s))[None, :].repeat(h * s, 0),
                               atol=1e-12)
    np.testing.assert_allclose(v, ((np.arange(h * s) + 0.5) / (h * s))[:, None].repeat(w * s, 1),
                               atol=1e-12)
    # exact pixel solid angle: (cos th0 - cos th1) * 2pi / W
    r = 0
    exact = (np.cos(r * np.pi / (h * s)) - np.cos((r + 1) * np.pi / (h * s))) * 2 * np.pi / (w * s)
    np.testing.assert_allclose(sa[0, 0], exact, rtol=1e-12)


def test_euler_xyz_matrix():
    rng = np.random.default_rng(5)
    for rx, ry, rz in rng.uniform(-np.pi, np.pi, size=(10, 3)):
        R = envmap.euler_xyz_matrix(rx, ry, rz)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    # known axis rotations (right handed, counter-clockwise)
    q = np.pi / 2
    np.testing.assert_allclose(envmap.euler_xyz_matrix(q, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(envmap.euler_xyz_matrix(0, q, 0) @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(envmap.euler_xyz_matrix(0, 0, q) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    # Blender XYZ Euler: X first, then Y, then Z -> Rz @ Ry @ Rx
    rx, ry, rz = 0.3, -1.1, 2.0
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    np.testing.assert_allclose(envmap.euler_xyz_matrix(rx, ry, rz), Rz @ Ry @ Rx, atol=1e-14)
    # X then Z by 90 degrees each: +Y -> +Z -> +Z ; +X -> +X -> +Y
    R = envmap.euler_xyz_matrix(q, 0, q)
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)


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


def _sun_image(h, w, row, col, value=1e6):
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
        cl = envmap.resample_equirect_to_cubemap(_sun_image(h, w, row, col, 1.0), cube, R)
        weights = cl.radiance[:, 0].astype(np.float64) * cube.solid_angles
        area, _ = brute_overlaps(h, w, row, col, n, R)
        omega = area.sum()
        np.testing.assert_allclose(weights.sum(), omega, rtol=1e-6)   # float32 radiance
        np.testing.assert_allclose(weights, area, atol=1e-3 * omega)
        np.testing.assert_array_equal(weights > 0, area > 0)
        faces_seen = max(faces_seen, len(np.unique(np.nonzero(weights)[0] // (n * n))))
    assert faces_seen == 3


@pytest.mark.parametrize("h,w,n,row,col", [
    (512, 1024, 32, 100, 333),
    (512, 1024, 32, 255, 701),
    (1024, 2048, 64, 40, 1407),
    (1024, 2048, 64, 600, 12),
])
def test_one_pixel_sun_lands_in_its_texel(h, w, n, row, col):
    # Pixels inside one texel (no texel edge crosses them): the sun's energy and direction
    # go to that texel alone.
    img = _sun_image(h, w, row, col)
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
        cl = envmap.resample_equirect_to_cubemap(_sun_image(h, w, row, col), cube, R)
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
    img = _sun_image(h, w, 20, 50)
    wl = envmap.WorldLighting(img)
    cl = wl.to_cubemap(n)
    assert np.all(np.isfinite(cl.radiance))
    np.testing.assert_allclose(cube_energy(cl, cube), wl.total_power(), rtol=1e-6)
    area, _ = brute_overlaps(h, w, 20, 50, n, np.eye(3), k=400)
    np.testing.assert_array_equal(np.nonzero(cl.radiance[:, 0])[0], np.nonzero(area)[0])
    assert len(np.nonzero(area)[0]) > 1


@pytest.mark.parametrize("angles", [(0.0, 0.0, np.pi / 2), (0.4, -0.7, 2.5), (np.pi / 2, 0.0, 0.0)])
def test_rotation_moves_sun(angles):
    h, w, n = 512, 1024, 32
    row, col = 150, 600
    R = envmap.euler_xyz_matrix(*angles)
    img = _sun_image(h, w, row, col)
    wl = envmap.WorldLighting(img, rotation=R)
    cl = wl.to_cubemap(n)
    cube = directions.cubemap(n)
    t = pixel_centre_direction(row, col, h, w)         # texture-space sun
    d = R.T @ t                                         # world-space sun: L(d) = E(R d)
    k = int(cube.texel_index(d))
    e = cl.radiance[:, 0].astype(np.float64) * cube.solid_angles
    assert e[k] == pytest.approx(e.sum(), rel=1e-6)
    np.testing.assert_allclose(e.sum(), wl.total_power()[0], rtol=1e-6)
    assert np.degrees(np.arccos(np.clip(cl.unit_directions[k] @ d, -1, 1))) < 0.2
    assert float(wl.radiance(d)[0]) == pytest.approx(1e6)
    # unrotated world puts the sun elsewhere (for a non-trivial rotation)
    k0 = int(cube.texel_index(t))
    assert k0 != k


def test_uniform_world():
    wl = envmap.WorldLighting(None, color=(0.2, 0.5, 1.0), strength=2.0)
    cube = directions.cubemap(32)
    cl = wl.to_cubemap(32)
    np.testing.assert_allclose(cl.radiance, np.tile([0.4, 1.0, 2.0], (cube.size, 1)), rtol=1e-6)
    np.testing.assert_allclose(cl.directions, cube.mean_directions)
    np.testing.assert_allclose(wl.total_power(), 4 * np.pi * np.array([0.4, 1.0, 2.0]), rtol=1e-12)
    np.testing.assert_allclose(cube_energy(cl, cube), wl.total_power(), rtol=1e-6)
    rng = np.random.default_rng(2)
    np.testing.assert_allclose(wl.radiance(random_unit(rng, 10)),
                               np.tile([0.4, 1.0, 2.0], (10, 1)), rtol=1e-6)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_world_rejects_non_finite(bad):
    img = np.ones((8, 16, 3), np.float32)
    img[3, 4, 1] = bad
    with pytest.raises(envmap.EnvironmentError_):
        envmap.WorldLighting(img)
    assert envmap.count_non_finite(img) == 1
    with pytest.raises(envmap.EnvironmentError_):
        envmap.WorldLighting(None, strength=float(bad))


def test_world_clamps_negative_and_as_rgb():
    img = np.ones((4, 8, 4), np.float32)
    img[0, 0, 0] = -5.0
    wl = envmap.WorldLighting(img)
    assert wl.image.shape == (4, 8, 3) and wl.image.min() == 0.0
    grey = envmap.as_rgb(np.arange(6, dtype=np.float32).reshape(2, 3))
    assert grey.shape == (2, 3, 3)
    np.testing.assert_array_equal(grey[..., 0], grey[..., 2])


def test_load_equirect_roundtrip(tmp_path):
    oiio = pytest.importorskip("OpenImageIO")
    h, w = 6, 12
    rng = np.random.default_rng(9)
    img = rng.uniform(0, 100, size=(h, w, 3)).astype(np.float32)
    img[0, :, :] = 1000.0          # top row marker (zenith)
    img[-1, :, :] = 0.001
    path = tmp_path / "env.exr"
    out = oiio.ImageOutput.create(str(path))
    assert out is not None
    spec = oiio.ImageSpec(w, h, 3, "float")
    assert out.open(str(path), spec)
    assert out.write_image(img)
    out.close()
    back = envmap.load_equirect(str(path))
    assert back.dtype == np.float32 and back.shape == (h, w, 3)
    np.testing.assert_array_equal(back, img)
    # and the top row is the zenith for lighting
    wl = envmap.WorldLighting(back)
    assert float(wl.radiance(np.array([0.0, 0.0, 1.0]))[0]) == 1000.0
    # RGBA is reduced to RGB
    path4 = tmp_path / "env4.exr"
    out = oiio.ImageOutput.create(str(path4))
    img4 = np.concatenate([img, np.full((h, w, 1), 0.5, np.float32)], axis=2)
    assert out.open(str(path4), oiio.ImageSpec(w, h, 4, "float"))
    assert out.write_image(img4)
    out.close()
    np.testing.assert_array_equal(envmap.load_equirect(str(path4)), img)


def test_load_equirect_missing(tmp_path):
    pytest.importorskip("OpenImageIO")
    with pytest.raises(envmap.EnvironmentError_):
        envmap.load_equirect(str(tmp_path / "does_not_exist.exr"))


# --------------------------------------------------------------------------- #
# hemisphere parameterizations (Shirley-Chiu square for SSDFs, Xu et al. 2006's disk)
# --------------------------------------------------------------------------- #

def _uniform_hemisphere(count, seed=7):
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.0, 1.0, count)
    phi = rng.uniform(0.0, 2 * np.pi, count)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def test_shirley_chiu_round_trip_and_unit_directions():
    rng = np.random.default_rng(0)
    a, b = rng.uniform(-1, 1, 5000), rng.uniform(-1, 1, 5000)
    d = directions.shirley_chiu_to_hemisphere(a, b)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert (d[:, 2] >= 0).all()
    a2, b2 = directions.hemisphere_to_shirley_chiu(d)
    np.testing.assert_allclose(a2, a, atol=1e-12)
    np.testing.assert_allclose(b2, b, atol=1e-12)
    # corners and centre
    np.testing.assert_allclose(directions.shirley_chiu_to_hemisphere(0.0, 0.0), [0, 0, 1])
    assert abs(directions.shirley_chiu_to_hemisphere(1.0, 1.0)[2]) < 1e-12


def test_shirley_chiu_cells_have_equal_solid_angle():
    n = 8
    dirs, w = directions.shirley_chiu_hemisphere(n)
    np.testing.assert_allclose(w.sum(), 2 * np.pi, rtol=1e-12)
    samples = _uniform_hemisphere(2_000_000)
    a, b = directions.hemisphere_to_shirley_chiu(samples)
    col = np.clip(((a + 1) / 2 * n).astype(int), 0, n - 1)
    row = np.clip(((b + 1) / 2 * n).astype(int), 0, n - 1)
    frac = np.bincount(row * n + col, minlength=n * n) / len(samples)
    np.testing.assert_allclose(frac * 2 * np.pi, w, rtol=0.03)
    # texel centres map back into their own texel
    a, b = directions.hemisphere_to_shirley_chiu(dirs)
    c = -1 + (np.arange(n) + 0.5) * 2 / n
    B, A = np.meshgrid(c, c, indexing="ij")
    np.testing.assert_allclose(a, A.ravel(), atol=1e-12)
    np.testing.assert_allclose(b, B.ravel(), atol=1e-12)


def test_rsl_map_matches_the_papers_formula_and_is_equal_area():
    theta, phi = 0.7, 2.1
    d = [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    px, py = directions.hemisphere_to_rsl_disk(np.array(d))
    scale = np.sin(theta) / np.sqrt(1 + np.cos(theta))
    np.testing.assert_allclose([px, py], [scale * np.sin(phi), scale * np.cos(phi)], atol=1e-12)
    np.testing.assert_allclose(directions.rsl_disk_to_hemisphere(px, py), d, atol=1e-12)
    n = 16
    _, w = directions.rsl_hemisphere(n)
    np.testing.assert_allclose(w.sum(), 2 * np.pi, rtol=1e-12)
    samples = _uniform_hemisphere(2_000_000, seed=3)
    px, py = directions.hemisphere_to_rsl_disk(samples)
    col = np.clip(((px + 1) / 2 * n).astype(int), 0, n - 1)
    row = np.clip(((py + 1) / 2 * n).astype(int), 0, n - 1)
    frac = np.bincount(row * n + col, minlength=n * n) / len(samples)
    big = w > 0.2 * w.max()                  # texels with enough samples for 3 %
    np.testing.assert_allclose(frac[big] * 2 * np.pi, w[big], rtol=0.03)
    assert np.all(w[frac == 0] < 1e-3)       # texels no sample reached are (almost) empty


def test_disk_area_of_boxes_is_exact():
    rng = np.random.default_rng(5)
    for _ in range(20):
        x0, x1 = np.sort(rng.uniform(-1.2, 1.2, 2))
        y0, y1 = np.sort(rng.uniform(-1.2, 1.2, 2))
        # dense midpoint rule of the indicator as the reference
        xs = np.linspace(x0, x1, 400001)[:-1] + (x1 - x0) / 800000
        h = np.sqrt(np.clip(1 - xs * xs, 0, None)) * (np.abs(xs) <= 1)
        length = np.clip(np.minimum(y1, h) - np.maximum(y0, -h), 0, None)
        ref = length.sum() * (x1 - x0) / 400000
        got = float(directions.disk_strip_area(np.array(x0), np.array(x1),
                                                np.array(y0), np.array(y1)))
        assert got == pytest.approx(ref, abs=2e-6)
    assert float(directions.disk_strip_area(np.array(-1.0), np.array(1.0),
                                             np.array(-1.0), np.array(1.0))) == \
        pytest.approx(np.pi, rel=1e-12)
