"""Cycles' tabulated microfacet albedos, made by our own quadrature (no bpy): the GGX
directional albedo ``E(roughness, mu)`` and its average, and the dielectric's
``s(roughness, mu, z)`` table of the generalised Schlick IOR fit -- on Cycles' grids,
lazily per column (``core/shading/brdf.py``'s multiscatter and Principled layering read them).
"""

from __future__ import annotations

import numpy as np

from ..common.cache import memo
from .microfacet import dielectric_s, lambda_raw, ior_from_F0


# --------------------------------------------------------------------------- #
# Tables: Cycles' grids, our own quadrature
# --------------------------------------------------------------------------- #

#: samples per axis of the deterministic VNDF quadrature (n*n per table node).
QUADRATURE_N = 256
_E_SIZE = 32          # ggx_E: 32 x 32 (rough, mu); ggx_Eavg: 32 (rough)
_S_SIZE = 16          # ggx_gen_schlick_ior_s: 16^3 (rough, mu, z)
_GL_MU = 32           # Gauss-Legendre nodes for E_avg


def _grid_value(i: int, n: int, hi: float = 1.0) -> float:
    """Cycles' precompute grid: ``clamp(i / (n - 1), 1e-4, hi)``."""
    return min(max(i / (n - 1), 1e-4), hi)


@memo(8)
def _unit_disk_grid(n: int, alpha: float):
    """Quadrature on the unit disk for the VNDF mapping: ``(x, y, weight)``.

    Polar, ``rho^2 = u``; ``u`` is graded towards the rim as
    ``u = 1 - exp(-w)`` with ``w`` on a midpoint grid over ``[0, W]``,
    ``W = ln(1 / alpha^2) + 14``, because the GGX tails that matter (steep
    microfacets, ``tan(theta_m) ~ 1``) sit at ``1 - u ~ alpha^2``; ``phi`` is a
    periodic midpoint grid.  Weights sum to 1.
    """
    W = np.log(1.0 / (alpha * alpha)) + 14.0
    w = (np.arange(n) + 0.5) * (W / n)
    u = -np.expm1(-w)
    wu = np.exp(-w)
    wu /= wu.sum()
    r = np.sqrt(u)[:, None]
    phi = 2.0 * np.pi * (np.arange(n) + 0.5)[None, :] / n
    weight = np.repeat(wu[:, None] / n, n, axis=1)
    return ((r * np.cos(phi)).reshape(-1), (r * np.sin(phi)).reshape(-1),
            weight.reshape(-1))


def _vndf_reflect(rough: float, mus: np.ndarray, n: int = QUADRATURE_N):
    """Deterministic quadrature over Cycles' GGX VNDF sampling
    (``microfacet_ggx_sample_vndf``, Heitz 2018) for views at ``mus``.

    Returns ``(cos_HI, cos_NO, weights)``: ``(M, n*n)`` microfacet/view cosines,
    cosines of the mirrored directions and ``(n*n,)`` quadrature weights (sum 1)
    with respect to the VNDF of the view.
    """
    alpha = max(rough * rough, 1e-7)
    mu = np.clip(np.asarray(mus, dtype=np.float64), 1e-6, 1.0)[:, None]
    wx = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    wz = mu
    # stretched view (x-z plane); basis T1 = y, T2 = cross(wi_, T1)
    ln = np.sqrt((alpha * wx) ** 2 + wz * wz)
    vx, vz = alpha * wx / ln, wz / ln
    t1, t2, weights = _unit_disk_grid(n, alpha)
    t1 = t1[None, :]
    a = 0.5 * (1.0 + vz)
    t2 = (1.0 - a) * np.sqrt(np.maximum(1.0 - t1 * t1, 0.0)) + a * t2[None, :]
    tz = np.sqrt(np.maximum(1.0 - t1 * t1 - t2 * t2, 0.0))
    # H_ = t1 * (0,1,0) + t2 * (-vz, 0, vx) + tz * (vx, 0, vz)
    hx = -t2 * vz + tz * vx
    hy = t1
    hz = t2 * vx + tz * vz
    hx, hy, hz = alpha * hx, alpha * hy, np.maximum(hz, 0.0)
    hl = np.sqrt(hx * hx + hy * hy + hz * hz)
    hl = np.where(hl > 0.0, hl, 1.0)
    hx, hy, hz = hx / hl, hy / hl, hz / hl
    cos_hi = np.clip(hx * wx + hz * wz, 0.0, 1.0)
    cos_no = 2.0 * cos_hi * hz - wz
    return cos_hi, cos_no, weights


def _ggx_E_quadrature(rough: float, mus) -> np.ndarray:
    """Single-scatter GGX directional albedo ``E(rough, mu)`` (F = 1), i.e.
    the VNDF mean of ``G2 / G1 = (1 + L_i) / (1 + L_i + L_o)`` over samples
    reflected above the horizon (what Cycles' ``precompute_ggx_E`` averages)."""
    mus = np.asarray(mus, dtype=np.float64)
    a2 = max(rough * rough, 1e-7) ** 2
    _, cos_no, wq = _vndf_reflect(rough, mus)
    lam_i = lambda_raw("GGX", a2, np.clip(mus, 1e-6, 1.0))[:, None]
    lam_o = lambda_raw("GGX", a2, cos_no)
    w = np.where(cos_no > 0.0, (1.0 + lam_i) / (1.0 + lam_i + lam_o), 0.0)
    return w @ wq


@memo(64)
def ggx_E_table_column(ix: int) -> np.ndarray:
    """``E`` at roughness node ``ix`` of Cycles' 32 x 32 ``ggx_E`` grid, all 32 mu nodes."""
    rough = _grid_value(ix, _E_SIZE)
    mus = np.array([_grid_value(j, _E_SIZE) for j in range(_E_SIZE)])
    return np.clip(_ggx_E_quadrature(rough, mus), 0.0, 1.0)


@memo(64)
def ggx_E_avg_node(ix: int) -> float:
    """``E_avg = 2 int_0^1 E(mu) mu dmu`` at roughness node ``ix`` (Gauss-Legendre in mu)."""
    rough = _grid_value(ix, _E_SIZE) if ix > 0 else 0.0
    x, w = np.polynomial.legendre.leggauss(_GL_MU)
    mu = 0.5 * (x + 1.0)
    return float(np.clip(np.sum(w * mu * _ggx_E_quadrature(max(rough, 1e-4), mu)), 0.0, 1.0))


@memo(512)
def dielectric_s_table_column(ix: int, iz: int) -> np.ndarray:
    """``S`` of Cycles' 16^3 ``ggx_gen_schlick_ior_s`` grid at (rough node ``ix``,
    z node ``iz``), all 16 mu nodes: VNDF mean of ``s(h.wi)`` (0 below horizon)."""
    rough = _grid_value(ix, _S_SIZE)
    z = _grid_value(iz, _S_SIZE, 0.99)
    eta = ior_from_F0(z ** 4)
    mus = np.array([_grid_value(j, _S_SIZE) for j in range(_S_SIZE)])
    cos_hi, cos_no, wq = _vndf_reflect(rough, mus)
    s = np.where(cos_no >= 0.0, dielectric_s(cos_hi, eta), 0.0)
    return np.clip(s @ wq, 0.0, 1.0)


def _lerp_index(x: float, n: int):
    """Cycles ``lookup_table_read`` indexing: (index, next index, t)."""
    x = min(max(float(x), 0.0), 1.0) * (n - 1)
    i = min(int(x), n - 1)
    return i, min(i + 1, n - 1), x - i


def _interp_mu(column: np.ndarray, mu) -> np.ndarray:
    n = len(column)
    x = np.clip(np.nan_to_num(np.asarray(mu, dtype=np.float64), nan=0.0), 0.0, 1.0) * (n - 1)
    i = np.minimum(x.astype(np.int64), n - 1)
    j = np.minimum(i + 1, n - 1)
    t = x - i
    return (1.0 - t) * column[i] + t * column[j]


def ggx_E(roughness: float, mu) -> np.ndarray:
    """Single-scatter GGX directional albedo at ``mu = n.wo`` (Cycles' grid and
    bilinear interpolation, our quadrature)."""
    i0, i1, t = _lerp_index(roughness, _E_SIZE)
    col = (1.0 - t) * ggx_E_table_column(i0) + t * ggx_E_table_column(i1)
    return _interp_mu(col, mu)


def ggx_E_avg(roughness: float) -> float:
    """Cosine-weighted average of :func:`ggx_E` over views (Cycles' ``ggx_Eavg`` grid)."""
    i0, i1, t = _lerp_index(roughness, _E_SIZE)
    return (1.0 - t) * ggx_E_avg_node(i0) + t * ggx_E_avg_node(i1)


def dielectric_albedo_s(roughness: float, mu, eta: float) -> np.ndarray:
    """Cycles' ``S(r, mu, z)`` (``ggx_gen_schlick_ior_s``, trilinear), so that the
    Principled specular albedo estimate is ``mix(f0, 1, S)``."""
    z = np.sqrt(abs((float(eta) - 1.0) / (float(eta) + 1.0)))
    i0, i1, t = _lerp_index(roughness, _S_SIZE)
    k0, k1, u = _lerp_index(z, _S_SIZE)
    col = ((1.0 - u) * ((1.0 - t) * dielectric_s_table_column(i0, k0)
                        + t * dielectric_s_table_column(i1, k0))
           + u * ((1.0 - t) * dielectric_s_table_column(i0, k1)
                  + t * dielectric_s_table_column(i1, k1)))
    return _interp_mu(col, mu)
