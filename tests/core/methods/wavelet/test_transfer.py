"""core.methods.wavelet.transfer (Ng 03 double product, Ng 04 triple product) against the
pixel-basis sums and REFERENCE.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.methods.wavelet import haar, transfer as wavelet
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.scene.visibility import hemisphere_mask


RNG = np.random.default_rng(7)


def _random_scene(n=8, points=24, seed=3):
    rng = np.random.default_rng(seed)
    cube = directions.cubemap(n)
    normals = rng.normal(size=(points, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    vis = hemisphere_mask(normals, cube) & (rng.random((points, cube.size)) > 0.3)
    bits = np.packbits(vis, axis=1)
    radiance = (rng.random((cube.size, 3)) ** 6 * 20).astype(np.float32)
    lighting = envmap.CubeLighting(radiance, cube.directions.copy())
    views = rng.normal(size=(points, 3))
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    views = np.where((np.sum(views * normals, axis=1) < 0)[:, None], -views, views)
    return cube, normals, vis, bits, lighting, views


def test_batched_triple_product_equals_pixel_sum_of_truncated_functions():
    n, S, B = 8, 6 * 64, 6
    L = RNG.random((S, 3)) ** 4
    light = wavelet.LightingApproximation(L, 25)
    Vpix = (RNG.random((B, S)) > 0.5).astype(float)
    rho_full = haar.cube_forward(RNG.random((B, S)) ** 3)
    idx, vals = haar.nonlinear_approximation(rho_full, 17)
    rho = np.zeros_like(rho_full)
    np.put_along_axis(rho, idx, vals, axis=1)
    got = wavelet.triple_product_points(light, haar.cube_forward(Vpix), rho, idx)
    want = np.einsum("sc,bs,bs->bc", light.pixels, Vpix, haar.cube_inverse(rho))
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
    # the scalar sparse evaluator of core.methods.wavelet.haar agrees
    one = haar.triple_product((light.indices, light.values[:, 1]), haar.cube_forward(Vpix[2]),
                              (idx[2], vals[2]), n)
    assert one == pytest.approx(want[2, 1], rel=1e-10)


def test_untruncated_wavelet_equals_reference():
    cube, normals, vis, bits, lighting, views = _random_scene()
    full = wavelet.LightingApproximation(lighting.radiance, cube.size)
    assert full.relative_error < 1e-12
    transfer = wavelet.diffuse_transfer(bits, normals, cube, cube.size)
    np.testing.assert_allclose(wavelet.diffuse_irradiance(transfer, full),
                               reference.diffuse_irradiance(bits, normals, cube, lighting),
                               rtol=2e-5, atol=1e-5)
    mat = materials.Material(distribution="BECKMANN", roughness=0.3, diffuse_albedo=(0, 0, 0),
                        specular_color=(1.0, 0.8, 0.6))
    got = wavelet.glossy_radiance(bits, normals, views, cube, lighting, mat, full, cube.size)
    want = reference.specular_radiance(bits, None, normals, None, cube, lighting, mat,
                                       view_dirs=views)
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=2e-5 * np.abs(want).max())


def test_ng03_diffuse_is_reference_under_the_approximated_lighting():
    """Keeping N lighting terms == integrating against the N-term reconstruction."""
    cube, normals, vis, bits, lighting, views = _random_scene(seed=5)
    transfer = wavelet.diffuse_transfer(bits, normals, cube, cube.size)
    errors = []
    exact = reference.diffuse_irradiance(bits, normals, cube, lighting)
    for terms in (8, 40, 200):
        light = wavelet.LightingApproximation(lighting.radiance, terms)
        approx = envmap.CubeLighting(light.pixels.astype(np.float32), lighting.directions)
        got = wavelet.diffuse_irradiance(transfer, light)
        np.testing.assert_allclose(got, reference.diffuse_irradiance(bits, normals, cube, approx),
                                   rtol=1e-4, atol=1e-4 * np.abs(exact).max())
        errors.append(np.linalg.norm(got - exact) / np.linalg.norm(exact))
    assert errors[2] < errors[0]


def test_truncated_transfer_error_shrinks_with_kept_terms():
    cube, normals, vis, bits, lighting, views = _random_scene(seed=9)
    full = wavelet.LightingApproximation(lighting.radiance, cube.size)
    exact = reference.diffuse_irradiance(bits, normals, cube, lighting)
    errs = []
    for m in (8, 64, 256):
        e = wavelet.diffuse_irradiance(wavelet.diffuse_transfer(bits, normals, cube, m), full)
        errs.append(np.linalg.norm(e - exact) / np.linalg.norm(exact))
    assert errs[0] > errs[1] > errs[2]


def test_non_finite_lighting_is_rejected():
    bad = np.ones((6 * 16, 3))
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        wavelet.LightingApproximation(bad, 10)
