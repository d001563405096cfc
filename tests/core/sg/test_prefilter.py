"""core.sg.prefilter (Wang et al. 2009, §6, eq. 35): the prefiltered environment's look-up
against a brute-force convolution over the cubemap, its inner product, rotation, and the
limit a one-texel sun sets.  No bpy."""


import numpy as np
import pytest

from prt_relight.core.sphere import envmap
from prt_relight.core.sg import lighting as sg_lighting
from prt_relight.core.sg import prefilter
from prt_relight.core.sphere.directions import cubemap

from .environments import random_dirs, smooth_env, sun_env


# --------------------------------------------------------------------------- prefiltered pyramid

def _brute_force_mean(L, cube, p, lam):
    G = np.exp(lam * (np.minimum(p @ np.asarray(cube.directions).T, 1.0) - 1.0)) * cube.solid_angles
    return (G @ L) / G.sum(axis=1, keepdims=True)


@pytest.fixture(scope="module")
def smooth_prefiltered():
    cube = cubemap(32)
    L = smooth_env(cube)
    return cube, L, prefilter.PrefilteredEnvironment(L, cube)


@pytest.mark.parametrize("lam,max_err", [(1e-3, 1e-3), (0.2, 0.005), (3.0, 0.01), (17.0, 0.02),
                                         (60.0, 0.03), (1e4, 0.05), (1e5, 0.05)])
def test_prefiltered_lookup_matches_brute_force_convolution(smooth_prefiltered, lam, max_err):
    cube, L, pe = smooth_prefiltered
    assert pe.levels.shape == (pe.lambdas.size, 6, 32, 32, 3) and pe.levels.dtype == np.float32
    p = random_dirs(200, 11)
    got = pe.lookup(p, np.full(len(p), lam))
    if lam >= 1e4:   # beyond the finest level: the kernel is inside one texel -> radiance itself
        ref = prefilter.face_bilinear(L.reshape(6, 32, 32, 3), *sg_lighting.face_coordinates(p))
        ref_exact = _smooth_env_at(p)
        print(f"lam {lam}: vs analytic radiance {np.linalg.norm(got - ref_exact) / np.linalg.norm(ref_exact):.4f}")
    else:
        ref = _brute_force_mean(L, cube, p, lam)
    err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
    print(f"prefiltered lookup lam={lam}: rel L2 {err:.5f}")
    assert err <= max_err


def _smooth_env_at(p):
    class _C:
        directions = p
        size = len(p)
    return smooth_env(_C)


def test_prefiltered_inner_product_eq35(smooth_prefiltered):
    """mu * Gamma_L(p, lam) vs the brute-force inner product sum_k G(w_k) L_k dw_k."""
    cube, L, pe = smooth_prefiltered
    p = random_dirs(50, 5)
    lam = np.geomspace(0.01, 100.0, 50)
    mu = np.linspace(0.5, 2.0, 50)[:, None] * [1.0, 0.5, 0.25]
    got = pe.inner_product(p, lam, mu)
    G = np.exp(lam[:, None] * (np.minimum(p @ np.asarray(cube.directions).T, 1) - 1)) * cube.solid_angles
    ref = mu * (G @ L)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.02


def test_rotated_lookup_equals_lookup_of_rotated_directions(smooth_prefiltered):
    cube, L, pe = smooth_prefiltered
    R = envmap.euler_xyz_matrix(0.3, -0.2, 1.1)
    p = random_dirs(100, 3)
    lam = np.geomspace(0.05, 300, 100)
    assert np.allclose(pe.lookup(p, lam, rotation=R), pe.lookup(p @ R.T, lam))
    # a rotated world needs no refilter: the rotated lookup equals the brute-force
    # convolution of the rotated environment L(R d)
    rotated = _smooth_env_at(np.asarray(cube.directions) @ R.T)
    ref = _brute_force_mean(rotated, cube, p[:20], 17.0)
    got = pe.lookup(p[:20], np.full(20, 17.0), rotation=R)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.01


def test_prefiltered_lookup_with_a_sun_reports_its_limit():
    """A one-texel sun (contrast 1e5): the pyramid can only be as sharp as the cube."""
    cube = cubemap(32)
    L = sun_env(cube)
    pe = prefilter.PrefilteredEnvironment(L, cube)
    p = random_dirs(200, 2)
    for lam, lim in ((0.5, 0.01), (5.0, 0.02), (30.0, 0.06)):
        got = pe.lookup(p, np.full(200, lam))
        ref = _brute_force_mean(L, cube, p, lam)
        err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
        print(f"sun env, lam {lam}: rel L2 {err:.4f}")
        assert err <= lim
