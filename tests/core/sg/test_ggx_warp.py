"""core.sg.ggx_warp: the table's look-up against bilinear interpolation done separately
along each axis, the error of a set of lobes against an independent quadrature of GGX's
view slice over the hemisphere of light directions, and the lobes' axes and sharpness as
eq. 18-21 and the tilts define them.  No bpy; the fit's quality under an HDRI is
tests/integration/numerics/test_sg_lobes_under_forest.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.sg import ggx_warp
from prt_relight.core.sg.ndf import SG_ALPHA_MIN, LAMBDA_MAX
from prt_relight.core.sg.warp_table import GGX_WARP_TABLE

K = ggx_warp.GGX_WARP_LOBES


def _interp_separately(table, r, mu):
    """Bilinear interpolation as two linear ones: along n.o in each roughness row, then
    along the roughness (np.interp, clamped at the ends)."""
    rows = np.array([[np.interp(mu, ggx_warp.WARP_MU, table[i, :, k])
                      for k in range(table.shape[-1])] for i in range(table.shape[0])])
    return np.array([np.interp(r, ggx_warp.WARP_R, rows[:, k]) for k in range(table.shape[-1])])


def test_look_up_is_bilinear_between_nodes_and_exact_at_them():
    rng = np.random.default_rng(4)
    table = rng.normal(size=GGX_WARP_TABLE.shape)
    for r, mu in [(0.0, 0.0), (1.0, 1.0), (0.3, 0.65), (0.525, 0.125), (0.97, 0.01),
                  (-0.2, 0.5), (0.4, 1.3)]:                   # beyond the table: its edge
        got = ggx_warp.ggx_warp_params(r, mu, table)
        np.testing.assert_allclose(got, _interp_separately(table, np.clip(r, 0, 1),
                                                           np.clip(mu, 0, 1)), atol=1e-12)
    for i, j in [(0, 0), (7, 13), (20, 20)]:
        np.testing.assert_allclose(ggx_warp.ggx_warp_params(ggx_warp.WARP_R[i], ggx_warp.WARP_MU[j],
                                                             table), table[i, j], atol=1e-12)
    r = np.array([[0.1, 0.9], [0.5, 0.3]])                    # shapes broadcast
    assert ggx_warp.ggx_warp_params(r, 0.4).shape == (2, 2, 3 * K)


def _slice_error_by_quadrature(r, mu, params, n=800):
    """||g - t|| / ||t|| over the hemisphere of light directions i (a midpoint grid in the
    polar angle and azimuth): t = D(h) G2(i, o) / (4 n.o) (GGX, Fresnel 1, written here),
    g = sum_k f_k exp(lam_k (i.axis_k - 1)) n.i scaled to t's energy."""
    a = max(r * r, SG_ALPHA_MIN)
    mu = max(mu, ggx_warp.WARP_MU_MIN)
    th = (np.arange(n) + 0.5) / n * (0.5 * math.pi)
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * (2.0 * math.pi)
    T, PH = np.meshgrid(th, ph, indexing="ij")
    i = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], -1)
    dw = np.sin(T) * (0.5 * math.pi / n) * (math.pi / n)
    o = np.array([math.sqrt(1.0 - mu * mu), 0.0, mu])
    h = i + o
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    a2 = a * a
    D = a2 / (math.pi * (h[..., 2] ** 2 * (a2 - 1.0) + 1.0) ** 2)

    def lam_smith(c):
        return 0.5 * (-1.0 + np.sqrt(1.0 + a2 * (1.0 - c * c) / (c * c)))

    t = D / (1.0 + lam_smith(i[..., 2]) + lam_smith(mu)) / (4.0 * mu)
    el = math.acos(mu) + params[:K]
    axes = np.stack([-np.sin(el), np.zeros(K), np.cos(el)], 1)       # toward the mirror side
    sharp = np.minimum(2.0 / (4.0 * a2 * mu) * np.exp(params[K:2 * K]), LAMBDA_MAX)
    g = np.einsum("...k,k->...", np.exp(sharp * (i @ axes.T - 1.0)), params[2 * K:]) * i[..., 2]
    g *= np.sum(t * dw) / np.sum(g * dw)
    return math.sqrt(np.sum((g - t) ** 2 * dw) / np.sum(t * t * dw))


@pytest.mark.parametrize("ir, j", [(10, 12), (14, 8), (6, 16), (20, 4)])
def test_error_of_the_lobes_is_the_slice_misfit_over_the_hemisphere(ir, j):
    """ggx_warp_error (on the fit's graded half-vector quadrature) against the same misfit on
    a plain grid over the light directions: the stored lobes and the plain warp's."""
    r, mu = ggx_warp.WARP_R[ir], ggx_warp.WARP_MU[j]
    stored = GGX_WARP_TABLE[ir, j]
    plain = np.concatenate([np.zeros(K), np.zeros(K), np.full(K, 1.0 / K)])
    for params in (stored, plain):
        want = _slice_error_by_quadrature(r, mu, params)
        assert ggx_warp.ggx_warp_error(r, mu, params) == pytest.approx(want, rel=2e-3, abs=1e-4)


def test_corrected_lobes_lie_in_the_plane_of_incidence_tilted_as_stored():
    """ggx_warp_correct: each axis in the plane of n and o, at acos(n.o) + d_k from the
    normal on the mirror side; sharpness 2 / (4 a^2 n.o) e^l (eq. 18-21, capped); the
    shares as stored (bilinear at the point's roughness and view)."""
    rng = np.random.default_rng(2)
    P = 64
    n = rng.normal(size=(P, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    o = rng.normal(size=(P, 3))
    o -= np.minimum(np.sum(o * n, 1), 0.0)[:, None] * n * 2.0          # views above the surface
    o /= np.linalg.norm(o, axis=1, keepdims=True)
    alpha = rng.uniform(0.05, 0.9, P)
    axes, lam, shares = ggx_warp.ggx_warp_correct(alpha, n, o, P)
    cos_o = np.clip(np.sum(n * o, 1), 0.0, 1.0)
    q = ggx_warp.ggx_warp_params(np.sqrt(alpha), cos_o)
    mirror = 2.0 * cos_o[:, None] * n - o
    for k in range(K):
        ax = axes[:, k]
        np.testing.assert_allclose(np.linalg.norm(ax, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.einsum("pc,pc->p", np.cross(n, o), ax), 0.0, atol=1e-9)
        elevation = np.arccos(np.clip(np.sum(ax * n, 1), -1.0, 1.0))
        want = np.arccos(cos_o) + q[:, k]
        np.testing.assert_allclose(elevation, np.abs(want), atol=1e-6)
        side = np.sign(np.sum((ax - np.sum(ax * n, 1)[:, None] * n) * mirror, 1))
        assert (side[np.abs(np.sin(want)) > 1e-3] == np.sign(np.sin(want))[np.abs(np.sin(want)) > 1e-3]).all()
        warp = 2.0 / (4.0 * alpha * alpha * np.maximum(cos_o, ggx_warp.WARP_MU_MIN))
        np.testing.assert_allclose(lam[:, k], np.minimum(warp * np.exp(q[:, K + k]), LAMBDA_MAX),
                                   rtol=1e-12)
    np.testing.assert_allclose(shares, np.maximum(q[:, 2 * K:], 0.0))
