"""Spherical-harmonic transfer (core/methods/sh/harmonics.py) against quadrature and REFERENCE."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.methods.sh import harmonics as sh
from prt_relight.core.shading.materials import Material

FINE = directions.cubemap(128)


def _band_limited(order, seed):
    return np.random.default_rng(seed).normal(size=sh.coefficient_count(order))


@pytest.mark.parametrize("order", sh.ORDERS)
def test_basis_is_orthonormal(order):
    Y = sh.basis(FINE.directions, order)
    gram = (Y * FINE.solid_angles[:, None]).T @ Y
    np.testing.assert_allclose(gram, np.eye(order * order), atol=2e-4)


def test_known_low_order_values():
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    Y = sh.basis(d, 2)
    c0, c1 = 0.5 / np.sqrt(np.pi), np.sqrt(3.0 / (4.0 * np.pi))
    np.testing.assert_allclose(Y[:, 0], c0)
    np.testing.assert_allclose(Y[0, 2], c1)                 # Y_1^0 = c1 z
    np.testing.assert_allclose(abs(Y[1, 3]), c1)            # Y_1^1 ~ x
    np.testing.assert_allclose(abs(Y[2, 1]), c1)            # Y_1^-1 ~ y


@pytest.mark.parametrize("order", sh.ORDERS)
def test_project_reconstruct_round_trip_and_parseval(order):
    c = _band_limited(order, order)
    values = sh.reconstruct(c, FINE.directions)
    back = sh.project(values, FINE.directions, FINE.solid_angles, order)
    np.testing.assert_allclose(back, c, atol=5e-4 * np.abs(c).max())
    energy = float((values ** 2) @ FINE.solid_angles)
    assert energy == pytest.approx(float(c @ c), rel=5e-4)


@pytest.mark.parametrize("order", sh.ORDERS)
def test_rotation_matches_reprojection(order):
    R = envmap.euler_xyz_matrix(0.4, -1.1, 2.3)
    M = sh.rotation_matrix(R, order)
    np.testing.assert_allclose(M @ M.T, np.eye(order * order), atol=1e-10)
    c = _band_limited(order, 10 + order)
    rotated = sh.reconstruct(c, FINE.directions @ R)     # f(R^T w)
    reprojected = sh.project(rotated, FINE.directions, FINE.solid_angles, order)
    np.testing.assert_allclose(M @ c, reprojected, atol=5e-4 * np.abs(c).max())
    # composition: rotating by R2 then R1 is rotating by R1 R2
    R2 = envmap.euler_xyz_matrix(-0.3, 0.2, 0.9)
    np.testing.assert_allclose(sh.rotation_matrix(R @ R2, order),
                               M @ sh.rotation_matrix(R2, order), atol=1e-10)


def _bits_with_occluder(cube):
    """Points on a ground grid next to a box: real, varied visibility."""
    g = mesh.grid(size=2.0, cuts=6)
    sp = mesh.shading_points(g)
    box = np.array([[[0.2, -0.5, 0.0], [0.8, -0.5, 0.0], [0.8, -0.5, 0.8]],
                    [[0.2, -0.5, 0.0], [0.8, -0.5, 0.8], [0.2, -0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, -0.5, 0.8], [0.8, 0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, 0.5, 0.8], [0.2, 0.5, 0.8]]])
    scene = visibility.build_occluder_scene(np.concatenate([g.triangle_positions, box]))
    bits = visibility.trace_visibility(scene, sp.positions, sp.normals, cube, 1e-4)
    return sp, bits


def test_transfer_equals_reference_for_band_limited_lighting():
    """With lighting inside the SH span, sum_i l_i T_i is the exact triple product:
    SH and REFERENCE agree to quadrature error."""
    order = 3
    cube = directions.cubemap(32)
    sp, bits = _bits_with_occluder(cube)
    c = np.stack([_band_limited(order, s) for s in (1, 2, 3)], axis=1)
    c[0] += 4.0                                              # keep it mostly positive
    lighting = envmap.CubeLighting(sh.reconstruct(c, cube.directions).astype(np.float32),
                                   np.array(cube.mean_directions))
    ref = reference.diffuse_irradiance(bits, sp.normals, cube, lighting)
    T = sh.transfer(bits, sp.normals, cube, order)
    ours = sh.shade_diffuse(T, sh.project_lighting(lighting, cube, order))
    np.testing.assert_allclose(ours, ref, rtol=5e-3, atol=5e-3 * np.abs(ref).max())
    assert np.ptp(ref[:, 0]) > 0.1 * np.abs(ref).max()       # shadows really vary


def test_uniform_white_unshadowed_is_albedo():
    cube = directions.cubemap(32)
    normals = directions.fibonacci_sphere(20)
    bits = np.packbits(visibility.hemisphere_mask(normals, cube), axis=1)
    world = envmap.WorldLighting(color=(1.0, 1.0, 1.0))
    light = sh.project_lighting(world.to_cubemap(32), cube, 2)
    E = sh.shade_diffuse(sh.transfer(bits, normals, cube, 2), light)
    radiance = reference.lambert_layer(Material(diffuse_albedo=(0.5, 0.6, 0.7)), E, normals, None)
    np.testing.assert_allclose(radiance, np.tile([0.5, 0.6, 0.7], (20, 1)), rtol=2e-3)


def test_world_rotation_rotates_coefficients_instead_of_reprojecting():
    h, w = 64, 128
    th = (np.arange(h) + 0.5) / h * np.pi
    ph = (0.5 - (np.arange(w) + 0.5) / w) * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    img = (1.5 + d @ [0.8, -0.3, 0.5] + 0.4 * d[..., 0] * d[..., 2])[..., None] * [1.0, 0.8, 0.6]
    R = envmap.euler_xyz_matrix(0.0, 0.0, 1.3)
    rotated_world = envmap.WorldLighting(image=img.astype(np.float32), strength=2.0, rotation=R)
    projector = sh.LightingProjector(4)
    fast = projector.coefficients(rotated_world, "smooth")
    cube = directions.cubemap(64)
    slow = 2.0 * sh.project_lighting(
        envmap.WorldLighting(image=img.astype(np.float32), rotation=R).to_cubemap(64), cube, 4)
    np.testing.assert_allclose(fast, slow, atol=2e-2 * np.abs(slow).max())
    assert np.abs(fast - projector.coefficients(
        envmap.WorldLighting(image=img.astype(np.float32), strength=2.0), "smooth")).max() > 0.1
