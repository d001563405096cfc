"""SSDF (Wang et al. 2009, §5.1-5.2, eq. 23) and its PCA (eq. 24): against brute force,
closed forms and the PCA error budget."""

import math

import numpy as np
import pytest

from prt_relight.core.sphere import directions
from prt_relight.core.methods.ssdf_sg import ssdf


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cap_bits(normals, centres, cos_radius, cube, noise=0.0, seed=0):
    """Visibility: above the horizon and inside a cap (optionally with random holes)."""
    d = cube.directions
    vis = (d @ normals.T > 0).T & ((d @ centres.T).T > np.asarray(cos_radius)[:, None])
    if noise:
        rng = np.random.default_rng(seed)
        vis ^= (rng.random(vis.shape) < noise) & (d @ normals.T > 0).T
    return np.packbits(vis, axis=1)


@pytest.fixture(scope="module")
def cube():
    return directions.cubemap(16)


def test_frames_orthonormal_and_continuous():
    rng = np.random.default_rng(1)
    n = _unit(rng.normal(size=(2000, 3)))
    t, b = ssdf.ssdf_frames(n)
    for u, v in ((t, b), (t, n), (b, n)):
        assert np.abs(np.sum(u * v, 1)).max() < 1e-12
    assert np.allclose(np.cross(t, b), n, atol=1e-12)
    # continuity across n_z = 0 (where Duff's frame flips): nearby normals, nearby tangents
    m = _unit(n + 1e-4 * rng.normal(size=n.shape))
    t2, _ = ssdf.ssdf_frames(m)
    far = np.abs(n @ ssdf.FRAME_REF) < 0.99
    assert np.linalg.norm(t - t2, axis=1)[far].max() < 0.02


def test_square_coordinates_invert_concentric_map():
    rng = np.random.default_rng(2)
    a, b = rng.uniform(-1, 1, 5000), rng.uniform(-1, 1, 5000)
    u, v = ssdf.square_coordinates(directions.shirley_chiu_to_hemisphere(a, b))
    assert np.abs(2 * u - 1 - a).max() < 1e-12 and np.abs(2 * v - 1 - b).max() < 1e-12


def test_fast_ssdf_equals_brute_force(cube):
    rng = np.random.default_rng(3)
    P = 7
    normals = _unit(rng.normal(size=(P, 3)))
    centres = _unit(normals + rng.normal(size=(P, 3)))
    cosr = rng.uniform(-0.3, 0.8, P)
    bits = _cap_bits(normals, centres, cosr, cube, noise=0.03)
    grid = ssdf.SSDFGrid(8, 2, 2)
    fast = ssdf.compute_ssdf(bits, normals, cube, grid, chunk=3)
    t, b = ssdf.ssdf_frames(normals)
    vis_hi = ssdf.square_visibility(bits, normals, cube, grid.visibility_size, t, b)
    vis_q = ssdf.square_visibility(bits, normals, cube, grid.query_size, t, b)
    assert vis_hi.any(1).all() and (~vis_hi).any(1).all()
    brute = ssdf.brute_force_ssdf(vis_hi, vis_q, grid)
    assert np.abs(fast - brute).max() < 2e-4


def test_open_and_blocked_hemispheres(cube):
    normals = _unit([[0, 0, 1], [0.3, -0.5, 0.8], [1, 0, 0]])
    grid = ssdf.SSDFGrid(8, 2, 1)
    open_bits = np.packbits((cube.directions @ normals.T > -1).T, axis=1)   # all sky visible
    s = ssdf.compute_ssdf(open_bits, normals, cube, grid)
    elev = np.arcsin(ssdf.square_centres(8).reshape(-1, 3)[:, 2])
    assert np.allclose(s, elev[None, :], atol=1e-5)
    blocked = np.zeros_like(open_bits)
    s = ssdf.compute_ssdf(blocked, normals, cube, grid)
    assert np.all(s == np.float32(ssdf.BLOCKED_VALUE))


def test_half_space_ssdf_matches_closed_form():
    """Visibility = {d . c > 0} above the horizon: the true SSDF is the signed angle to
    the great circle (visible side also bounded by the elevation)."""
    cube = directions.cubemap(32)
    rng = np.random.default_rng(4)
    P = 12
    normals = _unit(rng.normal(size=(P, 3)))
    c = _unit(rng.normal(size=(P, 3)))
    bits = _cap_bits(normals, c, np.zeros(P), cube)
    grid = ssdf.SSDFGrid(16, 4, 1)
    s = ssdf.compute_ssdf(bits, normals, cube, grid)
    t, b = ssdf.ssdf_frames(normals)
    local = ssdf.square_centres(16).reshape(-1, 3)
    world = np.einsum("qk,pkj->pqj", local, np.stack([t, b, normals], 1))
    # exact boundary: the arc of the great circle c.d = 0 above the horizon and the arc
    # of the horizon inside the half-space, densely sampled
    phi = np.linspace(0, 2 * math.pi, 20000, endpoint=False)
    truth = np.empty_like(s, dtype=float)
    for p in range(P):
        arcs = []
        for axis, other in ((c[p], normals[p]), (normals[p], c[p])):
            u, _ = ssdf.ssdf_frames(axis[None])
            v = np.cross(axis, u[0])
            circle = np.cos(phi)[:, None] * u[0] + np.sin(phi)[:, None] * v
            arcs.append(circle[circle @ other >= 0])
        bnd = np.concatenate(arcs)
        dist = np.arccos(np.clip(world[p] @ bnd.T, -1, 1)).min(axis=1)
        visible = (world[p] @ c[p] > 0)
        truth[p] = np.where(visible, dist, -dist)
    err = np.abs(s - truth)
    # cubemap texel angle: the data's resolution.  The worst cases are thin visible
    # slivers along the horizon, where texels whose centre lies below the horizon are
    # stored as blocked (a staircase up to about a texel above it).
    texel = math.pi / 2 / 32
    assert err.mean() < 0.5 * texel and err.max() < 2.5 * texel


def test_lookup_reproduces_texels_and_continues_below_horizon():
    n = 8
    rng = np.random.default_rng(5)
    img = rng.normal(size=(2, n * n))
    local = ssdf.square_centres(n).reshape(1, -1, 3).repeat(2, 0)
    val = ssdf.lookup_ssdf(img, local, n)
    assert np.allclose(val, img, atol=1e-9)
    below = _unit(np.array([[[0.6, 0.0, -0.3]]]))
    horizon = _unit(np.array([[[0.6, 0.0, 0.0]]]))
    diff = ssdf.lookup_ssdf(img[:1], horizon, n) - ssdf.lookup_ssdf(img[:1], below, n)
    assert np.isclose(diff[0, 0], math.asin(0.3 / math.hypot(0.6, 0.3)))


def test_pca_error_within_budget_and_streaming(cube):
    rng = np.random.default_rng(6)
    P = 400
    normals = _unit(rng.normal(size=(P, 3)) + [0, 0, 2])
    centres = _unit(normals + 0.8 * rng.normal(size=(P, 3)))
    bits = _cap_bits(normals, centres, rng.uniform(-0.5, 0.7, P), cube, noise=0.01, seed=7)
    grid = ssdf.SSDFGrid(8, 2, 1)
    full = ssdf.compute_ssdf(bits, normals, cube, grid)
    for budget in (0.15, 0.05):
        basis, coeffs = ssdf.ssdf_pca(bits, normals, cube, grid, budget, max_terms=64,
                                      chunk_points=97)
        rec = basis.reconstruct(coeffs)
        rms = float(np.sqrt(np.mean((rec - full) ** 2)))
        assert basis.terms % 4 == 0 and 4 <= basis.terms <= 64
        assert rms <= budget + 1e-6
        assert abs(rms - basis.rms_error) < 1e-3 + 0.02 * rms
        if basis.terms > 4:          # the budget decides: 4 fewer terms would exceed it
            fewer = ssdf.SSDFBasis(8, basis.mean, basis.eigen[:-4], basis.eigenvalues, P,
                                   budget, 0.0)
            rms4 = float(np.sqrt(np.mean((fewer.reconstruct(fewer.project(full)) - full) ** 2)))
            assert rms4 > budget
    # streamed covariance equals the one-shot PCA
    one = ssdf.fit_basis([full], 8, 0.05)
    assert one.terms == basis.terms
    assert np.allclose(np.abs(np.sum(one.eigen * basis.eigen, 1)), 1.0, atol=1e-4)


def _small_occluders(cube, seed, P=300):
    """Mostly open points with a small blocker each (a ground near small objects):
    ``(normals, bits, grid, exact SSDFs)``."""
    rng = np.random.default_rng(seed)
    normals = _unit(rng.normal(size=(P, 3)) * 0.2 + [0, 0, 1])
    centres = _unit(normals + 1.2 * rng.normal(size=(P, 3)))
    bits = _cap_bits(normals, centres, rng.uniform(-0.95, -0.6, P), cube)
    grid = ssdf.SSDFGrid(8, 2, 1)
    return normals, bits, grid, ssdf.compute_ssdf(bits, normals, cube, grid)


def test_pca_reports_the_share_of_blocked_directions_it_keeps(cube):
    """``occlusion_kept``: of the texels with a negative SSDF (blocked, eq. 23), the share
    whose compressed SSDF is still negative -- counted here from the reconstruction."""
    normals, bits, grid, full = _small_occluders(cube, 11)
    P = len(normals)
    assert 0.0 < np.mean(full < 0) < 0.5
    kept = []
    for budget in (0.2, 0.05, 0.001):
        basis, coeffs = ssdf.ssdf_pca(bits, normals, cube, grid, budget, max_terms=64,
                                      chunk_points=70)
        rec = basis.reconstruct(coeffs)
        blocked = full < 0
        expect = np.sum(blocked & (rec < 0)) / np.sum(blocked)
        # ssdf_pca reconstructs chunk by chunk (other float32 matrix products): a texel
        # within rounding of 0 may land on the other side
        near = np.sum(blocked & (np.abs(rec) < 1e-4)) / np.sum(blocked)
        assert basis.occlusion_kept == pytest.approx(expect, abs=near + 1e-12)
        kept.append(basis.occlusion_kept)
    assert kept[0] < kept[1] <= kept[2]
    assert kept[2] > 0.98                  # 64 terms of 64 texels: (almost) exact
    # nothing blocked: nothing to lose
    open_bits = _cap_bits(normals, normals, np.full(P, -2.0), cube)
    basis, _ = ssdf.ssdf_pca(open_bits, normals, cube, grid, 0.2)
    assert basis.occlusion_kept == 1.0


def test_pca_takes_more_terms_for_an_occlusion_target(cube):
    """``occlusion_target``: the fewest terms (steps of 4 from the RMS budget's) whose
    compression keeps that share of the blocked texels blocked; the cap when none does."""
    normals, bits, grid, full = _small_occluders(cube, 12)
    P = len(normals)
    blocked = full < 0

    def share(basis, k):
        e = basis.eigen[:k]
        rec = basis.mean + ((full - basis.mean) @ e.T) @ e
        return np.sum(blocked & (rec < 0)) / np.sum(blocked)

    plain, _ = ssdf.ssdf_pca(bits, normals, cube, grid, 0.2, max_terms=48)
    target = min(0.97, plain.occlusion_kept + 0.5 * (1 - plain.occlusion_kept))
    basis, coeffs = ssdf.ssdf_pca(bits, normals, cube, grid, 0.2, max_terms=48,
                                  chunk_points=70, occlusion_target=target)
    assert basis.terms > plain.terms and basis.terms % 4 == 0 and coeffs.shape == (P, basis.terms)
    assert basis.occlusion_kept >= target
    assert basis.occlusion_kept == pytest.approx(share(basis, basis.terms), abs=1e-3)
    assert share(basis, basis.terms - 4) < target          # 4 fewer terms would not do
    assert np.allclose(coeffs, basis.project(full), atol=1e-4)
    ev = basis.eigenvalues
    assert basis.rms_error == pytest.approx(np.sqrt(ev[basis.terms:].sum() / 64))
    # an unreachable target takes the cap
    capped, _ = ssdf.ssdf_pca(bits, normals, cube, grid, 0.2, max_terms=24,
                              occlusion_target=1.01)
    assert capped.terms == 24
