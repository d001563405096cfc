# SPDX-License-Identifier: GPL-3.0-or-later
"""core.sphere.directions against analytic values: the cubemap's texels, solid angles and
mean directions, frames, hemisphere samplings, and the Shirley-Chiu square and Xu et al.
2006's disk maps of the hemisphere.  Pure numpy; no bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.sphere import directions


RESOLUTIONS = (32, 64, 128)
CUBE = directions.cubemap(32)


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_unit(rng, n):
    return unit(rng.normal(size=(n, 3)))


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


def test_texel_of_components_equals_the_face_axis_lookup():
    rng = np.random.default_rng(8)
    d = rng.normal(size=(20000, 3))
    d = np.concatenate([d, directions.fibonacci_sphere(500), np.eye(3), -np.eye(3),
                        CUBE.directions, [[1, 1, 0], [1, -1, 1], [-1, -1, -1], [0, 1, -1]]])
    face, s, t = directions.face_coordinates(d)              # FACE_AXES dot products
    col = np.clip(((s + 1.0) * 0.5 * 32).astype(np.int64), 0, 31)
    row = np.clip(((t + 1.0) * 0.5 * 32).astype(np.int64), 0, 31)
    np.testing.assert_array_equal(directions.direction_to_texel(d, 32),
                                  (face * 32 + row) * 32 + col)
