"""Haar wavelets on the cubemap (Ng 03 non-linear approximation, Ng 04 triple products)."""

import itertools

import numpy as np
import pytest

from prt_relight.core.methods.wavelet import haar
from prt_relight.core.sphere.directions import cubemap


def _basis_on_pixels(n):
    """(N*N basis functions, N*N pixels): unit-square-normalised Haar basis values."""
    nn = n * n
    return haar.inverse(np.eye(nn).reshape(nn, n, n)).reshape(nn, nn) * n


# --- transform ----------------------------------------------------------------


def test_transform_matrix_is_orthogonal_and_matches_forward():
    W = haar.transform_matrix(8)
    assert np.allclose(W @ W.T, np.eye(64), atol=1e-14)
    assert np.allclose(W.T @ W, np.eye(64), atol=1e-14)
    x = np.random.default_rng(1).normal(size=(3, 8, 8))
    assert np.allclose(haar.forward(x).reshape(3, 64), x.reshape(3, 64) @ W.T, atol=1e-13)
    # not the identity: it really mixes pixels
    assert np.abs(W - np.eye(64)).max() > 0.1


def test_basis_layout_and_values():
    # the scaling coefficient is sum / N; level-l wavelets take values +-2**l on the unit square
    n = 8
    x = np.random.default_rng(2).random((n, n))
    assert haar.forward(x)[0, 0] == pytest.approx(x.sum() / n)
    B = _basis_on_pixels(n)
    lv = haar.decode_index(np.arange(n * n), n)[1]
    for q in range(1, n * n):
        assert set(np.unique(np.abs(B[q]))) <= {0.0, 2.0 ** lv[q]}
        assert np.count_nonzero(B[q]) == (n >> lv[q]) ** 2


def test_round_trip_and_parseval():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(2, 3, 16, 16))
    c = haar.forward(x)
    assert np.allclose(haar.inverse(c), x, atol=1e-12)
    assert np.allclose((c ** 2).sum(axis=(-1, -2)), (x ** 2).sum(axis=(-1, -2)), rtol=1e-12)
    cube = rng.normal(size=(4, 6 * 32 * 32))
    cc = haar.cube_forward(cube)
    assert np.allclose(haar.cube_inverse(cc), cube, atol=1e-12)
    assert np.allclose((cc ** 2).sum(-1), (cube ** 2).sum(-1), rtol=1e-12)
    # faces are independent: a change on face 3 leaves the others' coefficients alone
    bumped = cube[0].copy()
    bumped[3 * 1024 + 17] += 1.0
    diff = (haar.cube_forward(bumped) - cc[0]).reshape(6, -1)
    assert np.flatnonzero(np.abs(diff).max(axis=1) > 0).tolist() == [3]
    with pytest.raises(ValueError):
        haar.forward(np.zeros((6, 6)))
    with pytest.raises(ValueError):
        haar.cube_forward(np.zeros(100))


# --- non-linear approximation -------------------------------------------------


def test_nonlinear_approximation_keeps_exactly_keep_terms():
    rng = np.random.default_rng(4)
    c = haar.cube_forward(rng.normal(size=6 * 16 * 16))
    for keep in (1, 15, 154, 1536):
        idx, vals = haar.nonlinear_approximation(c, keep)
        assert idx.shape == vals.shape == (keep,)
        assert np.all(np.diff(idx) > 0)
        assert np.array_equal(vals, c[idx])
        dense = haar.nonlinear_approximation(c, keep, dense=True)
        assert np.count_nonzero(dense) == keep
        assert np.array_equal(dense, haar.sparse_to_dense(idx, vals, c.size))
        # every kept magnitude >= every dropped magnitude
        dropped = np.delete(np.abs(c), idx)
        assert dropped.size == 0 or np.abs(vals).min() >= dropped.max()
    # batched over leading axes: one ranking per row
    cb = rng.normal(size=(3, 24))
    idx, vals = haar.nonlinear_approximation(cb, 5)
    assert idx.shape == (3, 5)
    for r in range(3):
        assert set(idx[r]) == set(np.argsort(-np.abs(cb[r]))[:5])


def test_nonlinear_approximation_is_best_n_term():
    # N = 2 cube: 24 coefficients; brute force over all 3-term subsets in the pixel domain
    rng = np.random.default_rng(5)
    pixels = rng.normal(size=24)
    c = haar.cube_forward(pixels)
    keep = 3
    subsets = np.array(list(itertools.combinations(range(24), keep)))
    trunc = np.zeros((len(subsets), 24))
    np.put_along_axis(trunc, subsets, c[subsets], axis=1)
    errors = ((haar.cube_inverse(trunc) - pixels) ** 2).sum(axis=1)
    ours = haar.nonlinear_approximation(c, keep, dense=True)
    our_error = ((haar.cube_inverse(ours) - pixels) ** 2).sum()
    assert our_error == pytest.approx(errors.min(), rel=1e-12)
    # and a naive "first coefficients" choice is worse
    assert errors[0] > our_error


def test_area_weighted_selection_prefers_coarse_terms():
    c = np.zeros(6 * 4 * 4)
    c[2] = 1.0          # level-1 wavelet (area 1/4)
    c[1] = 0.6          # level-0 wavelet (area 1)
    assert haar.decode_index([1, 2], 4)[1].tolist() == [0, 1]
    assert haar.nonlinear_approximation(c, 1)[0].tolist() == [2]
    w = haar.support_areas(4)
    assert haar.nonlinear_approximation(c, 1, weights=w)[0].tolist() == [1]


# --- tripling coefficients ----------------------------------------------------


def test_tripling_coefficients_match_brute_force_integrals():
    n = 4
    nn = n * n
    B = _basis_on_pixels(n)
    brute = np.einsum("ip,jp,kp->ijk", B, B, B) / nn      # integral over the unit square
    I, J, K = np.meshgrid(np.arange(nn), np.arange(nn), np.arange(nn), indexing="ij")
    for face in (0, 5):
        C = haar.tripling_coefficient(I + face * nn, J + face * nn, K + face * nn, n)
        assert np.allclose(C, brute, atol=1e-13)
    assert np.count_nonzero(np.abs(brute) > 1e-12) == np.count_nonzero(C)
    assert set(np.unique(C)) == {-1.0, 0.0, 1.0, 2.0}
    # across faces everything vanishes; scalar arguments give a float
    assert not np.any(haar.tripling_coefficient(I, J + nn, K, n))
    assert haar.tripling_coefficient(0, 0, 0, n) == 1.0
    assert haar.tripling_coefficient(3 * nn + 5, 3 * nn + 5, 3 * nn, n) == 1.0


def test_tripling_coefficients_n8_sample():
    n = 8
    nn = n * n
    B = _basis_on_pixels(n)
    rng = np.random.default_rng(6)
    i, j, k = rng.integers(0, nn, size=(3, 4000))
    # mix in the structured cases (pairs) which random draws rarely hit
    j[:2000] = i[:2000]
    brute = np.einsum("qp,qp,qp->q", B[i], B[j], B[k]) / nn
    assert np.allclose(haar.tripling_coefficient(i, j, k, n), brute, atol=1e-12)
    assert np.count_nonzero(brute) > 100


# --- products -----------------------------------------------------------------


def _random_cube(rng, n, face=None):
    d = 6 * n * n
    L = rng.random(d) * 3.0
    V = (rng.random(d) > 0.4).astype(np.float64)
    R = rng.random(d)
    if face is not None:                       # data supported on one face only
        mask = np.zeros(d, dtype=bool)
        mask[face * n * n:(face + 1) * n * n] = True
        L, R = L * mask, R * mask
    return L, V, R


@pytest.mark.parametrize("n", [8, 16])
def test_triple_product_full_equals_pixel_sum(n):
    rng = np.random.default_rng(10 + n)
    d = 6 * n * n
    cube = cubemap(n)
    for face in (None, 0, 1, 2, 3, 4, 5):
        L, V, R = _random_cube(rng, n, face)
        # REFERENCE form: fold max(0, n.w) dw into the BRDF factor
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        rho_t = R * np.maximum(0.0, cube.directions @ normal) * cube.solid_angles
        if face is not None:
            rho_t = R * cube.solid_angles      # cosine could empty the face
        ref = haar.pixel_triple_sum(L, V, rho_t)
        assert ref > 0
        Lc, Vc, Rc = (haar.cube_forward(x) for x in (L, V, rho_t))
        Ls = haar.nonlinear_approximation(Lc, d)
        Rs = haar.nonlinear_approximation(Rc, d)
        Vs = haar.nonlinear_approximation(Vc, d)
        assert haar.triple_product(Ls, Vc, Rs, n) == pytest.approx(ref, rel=1e-10)
        assert haar.triple_product(Ls, Vs, Rs, n) == pytest.approx(ref, rel=1e-10)
        assert haar.triple_product(Lc, Vc, Rc, n) == pytest.approx(ref, rel=1e-10)
        Lp = haar.HaarFunction(Ls, n, parent_table=True)
        assert haar.triple_product(Lp, Vc, Rs, n) == pytest.approx(ref, rel=1e-10)
        # symmetric in its arguments
        assert haar.triple_product(Rs, Ls, Vc, n) == pytest.approx(ref, rel=1e-10)


def test_triple_product_matches_explicit_tripling_sum():
    # small N: the evaluator equals (1/N) sum_ijk C_ijk L_i V_j R_k on sparse inputs
    n = 4
    nn = n * n
    rng = np.random.default_rng(7)
    for _ in range(5):
        L, V, R = (np.where(rng.random(nn) < 0.5, rng.normal(size=nn), 0.0) for _ in range(3))
        I, J, K = np.meshgrid(np.arange(nn), np.arange(nn), np.arange(nn), indexing="ij")
        C = haar.tripling_coefficient(I + 2 * nn, J + 2 * nn, K + 2 * nn, n)
        want = np.einsum("ijk,i,j,k->", C, L, V, R) / n
        pad = lambda x: np.concatenate([np.zeros(2 * nn), x, np.zeros(3 * nn)])  # noqa: E731
        Lc, Vc, Rc = pad(L), pad(V), pad(R)
        Ls = (np.flatnonzero(Lc), Lc[np.flatnonzero(Lc)])
        Rs = (np.flatnonzero(Rc), Rc[np.flatnonzero(Rc)])
        assert haar.triple_product(Ls, Vc, Rs, n) == pytest.approx(want, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("n", [8, 16])
def test_double_product_full_equals_pixel_sum(n):
    rng = np.random.default_rng(20 + n)
    d = 6 * n * n
    cube = cubemap(n)
    for face in (None, 0, 1, 2, 3, 4, 5):
        L, V, _ = _random_cube(rng, n, face)
        T = V * np.maximum(0.0, cube.directions @ np.array([0.3, -0.2, 0.93])) * cube.solid_angles
        if face is not None:
            T = V * cube.solid_angles
        ref = float(np.sum(L * T))
        Lc, Tc = haar.cube_forward(L), haar.cube_forward(T)
        Ls = haar.nonlinear_approximation(Lc, d)
        assert haar.double_product(Ls, Tc) == pytest.approx(ref, rel=1e-10)
        assert haar.double_product(Ls, haar.nonlinear_approximation(Tc, d), n) == pytest.approx(ref, rel=1e-10)
        assert haar.double_product(Lc, Tc) == pytest.approx(ref, rel=1e-10)


def _scene(n, normals):
    """Smooth sky + sun, a box occluder, a Phong lobe: L, V, rho~ per normal."""
    cube = cubemap(n)
    w = cube.directions
    sun = np.array([0.4, 0.3, 0.866])
    sun /= np.linalg.norm(sun)
    L = 0.3 + 0.7 * np.maximum(0.0, w[:, 2]) + 40.0 * np.exp((w @ sun - 1.0) / 0.003)
    V, R = [], []
    view = np.array([0.0, -0.6, 0.8])
    for nrm in normals:
        V.append(~((w[:, 0] > 0.2) & (w[:, 2] < 0.6) & (w[:, 1] > -0.3)) & (w @ nrm > 0))
        refl = 2 * (view @ nrm) * nrm - view
        lobe = 0.2 / np.pi + 2.0 * np.maximum(0.0, w @ refl) ** 60
        R.append(lobe * np.maximum(0.0, w @ nrm) * cube.solid_angles)
    return L, np.array(V, dtype=np.float64), np.array(R)


def test_truncation_error_decreases_with_more_terms():
    n = 16
    d = 6 * n * n
    rng = np.random.default_rng(8)
    normals = rng.normal(size=(12, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.5
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    L, V, R = _scene(n, normals)
    ref = np.einsum("k,pk,pk->p", L, V, R)
    Lc, Vc, Rc = haar.cube_forward(L), haar.cube_forward(V), haar.cube_forward(R)
    errors = {}
    for frac in (0.01, 0.05, 0.2, 1.0):
        keep = haar.keep_count(frac, n)
        Ls = haar.HaarFunction(haar.nonlinear_approximation(Lc, keep), n, parent_table=True)
        out = np.array([haar.triple_product(Ls, Vc[p], haar.nonlinear_approximation(Rc[p], keep), n)
                        for p in range(len(normals))])
        errors[frac] = float(np.sqrt(np.mean((out - ref) ** 2)) / np.sqrt(np.mean(ref ** 2)))
    print("relative RMS error by kept fraction:", errors)
    assert errors[1.0] < 1e-12
    assert errors[0.01] > errors[0.05] > errors[0.2] > errors[1.0]
    assert errors[0.01] < 1.0
