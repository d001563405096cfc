"""SSDF_SG shading: eq. 39, 41, 42, 43 of Wang, Ren, Gong, Snyder, Guo 2009
evaluated in numpy -- the reference for ``shaders/methods/ssdf_sg_frag.glsl``.

Per shading point with normal ``n`` (SSDF frame ``t, b, n`` from
:func:`.ssdf.ssdf_frames`) and view ``o``:

* eq. 39 (diffuse, environment)::

      R_d = sum_j (C*(i; n) (x) L*_j(i)) . V^d(i)
          = sum_j mu_j' f_h(theta_d(p_j'), lam_j')

  ``C*`` is the clamped-cosine SG of eq. 40, ``L*_j`` the SG mixture fitted to
  the environment, ``(p', lam', mu')`` their product lobe (eq. 5/45),
  ``theta_d = V^d(p')`` the SSDF at the product lobe's axis (§5.3) and ``f_h``
  eq. 30 through the eq. 47-49 fit (``sg.fh_hat_approx`` times
  ``f_h(pi/2, lam)``).  Radiance ``kd R_d`` with ``kd = albedo / pi`` (eq. 36).

* eq. 41 (specular, environment)::

      R_s(o) = sum_k ((C*(i; n) (x) rho*_k(i; o)) (x) V^d(i)) . L(i)
             = sum_k mu_k'' Gamma_L(p_k', lam_k')

  ``rho*_k`` the view slice of ``ks rho_s`` (``core.sg.brdf.specular_lobes``),
  product with ``C*`` (eq. 5), the visibility product of eq. 31 (same axis
  and sharpness, amplitude times ``f_h(theta_d, lam)/f_h(pi/2, lam)``), and the
  inner product with the environment from its SG-prefiltered pyramid
  ``Gamma_L`` (eq. 34-35).

* eq. 42/43 (local lights given as SG lobes ``L*_x``, e.g. eq. 32/33)::

      R_d = (L*_x (x) C*(i; z+)) . V^d,     R_s = (L*_x (x) C* (x) rho*_s) . V^d

  i.e. the triple product is one SG (eq. 5 twice) integrated against the SSDF
  with eq. 30.  The scene export has no lamps yet; :func:`lamp_radiance`
  implements and tests the formulas.

The SSDF is read either from full per-point images or from the PCA form
(eq. 24) ``mean + sum_j w_j E_j``, bilinearly in the Shirley-Chiu square (the
GLSL texture lookups do the same arithmetic: bilinear filtering is linear, so
interpolating each eigen-image and combining equals combining and
interpolating).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...sg import algebra as sg
from ...sphere.directions import orthonormal_frame
from .ssdf import bilinear, ssdf_frames, square_coordinates

LAMBDA_C, MU_C = sg.clamped_cosine_sg()


class CosineLobes(NamedTuple):
    """An SG mixture ``C*(i; n) = sum_m amplitudes[m] G(i; F d_m, sharpness, 1)``
    approximating ``max(0, n . i)``; ``d_m`` in the local frame ``F = (t, b, n)``."""

    directions: np.ndarray      # (M, 3) local unit vectors
    amplitudes: np.ndarray      # (M,)
    sharpness: float


def _ring(theta, count, offset=0.0):
    phi = 2.0 * math.pi * (np.arange(count) + offset) / count
    return np.stack([math.sin(theta) * np.cos(phi), math.sin(theta) * np.sin(phi),
                     np.full(count, math.cos(theta))], axis=1)


#: eq. 40: the paper's single lobe on the normal (L2 error 17.7 % of ||max(0, cos)||)
COSINE_EQ40 = CosineLobes(np.array([[0.0, 0.0, 1.0]]), np.array([MU_C]), LAMBDA_C)
# Mixtures spread over the hemisphere (the paper's "SG mixture approximation of the clamped
# cosine", eq. 39): a lobe on n plus rings, sharpness and ring angles by grid search,
# amplitudes by least squares over 200k Fibonacci directions with the constraint that the
# mixture integrates to pi (a uniform sky's irradiance is exact).  Each lobe probes the SSDF
# on its own side of the hemisphere, so broad lights are shadowed more locally too.
#: 7 lobes (n + 6 at 0.825 rad), L2 error 6.3 % of ||max(0, cos)||
COSINE_SG7 = CosineLobes(np.concatenate([[[0.0, 0.0, 1.0]], _ring(0.825, 6)]),
                         np.array([0.78653916] + [0.49391033] * 6), 7.5)
#: 19 lobes (n + 6 at 0.5 rad + 12 at 1.0 rad, half-step offset), L2 error 3.7 %
COSINE_SG19 = CosineLobes(np.concatenate([[[0.0, 0.0, 1.0]], _ring(0.5, 6), _ring(1.0, 12, 0.5)]),
                          np.array([0.40107974] + [0.46181845] * 6 + [0.27733413] * 12), 13.0)
COSINE_MODELS = {"EQ40": COSINE_EQ40, "SG7": COSINE_SG7, "SG19": COSINE_SG19}


#: step (radians) of the finite difference that maps the SSDF square's slope to a
#: direction's (:func:`theta_d_slopes`; the square's own slope is the bilinear cell's)
SLOPE_STEP = 1e-3


def _horizon(local):
    return np.arcsin(np.clip(-np.asarray(local)[..., 2], 0.0, 1.0))


def theta_d_slopes(sample, local, e1, e2):
    """``theta_d`` at local directions ``local`` (R, L, 3) and its derivatives along the
    unit tangents ``e1``, ``e2`` there: ``(theta, d1, d2)`` (R, L).  ``sample(u, v)`` gives
    the SSDF square's bilinear value and its slopes in u, v; the map from directions to
    the square is differenced over :data:`SLOPE_STEP` (as the GLSL twin)."""
    u, v = square_coordinates(local)
    val, du, dv = sample(u, v)
    hor = _horizon(local)
    out = [val - hor]
    for e in (e1, e2):
        q = local + SLOPE_STEP * e
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        uq, vq = square_coordinates(q)
        out.append((du * (uq - u) + dv * (vq - v) - (_horizon(q) - hor)) / SLOPE_STEP)
    return tuple(out)


class PCAField:
    """The SSDF of every point of one object in PCA form (eq. 24).

    ``mean`` (D,), ``eigen`` (K, D), ``coefficients`` (P, K), ``resolution`` n
    (``D = n * n``)."""

    def __init__(self, mean, eigen, coefficients, resolution: int):
        self.resolution = int(resolution)
        self.images = np.concatenate([np.asarray(mean, np.float64)[None, :],
                                      np.asarray(eigen, np.float64)], axis=0)     # (K+1, D)
        c = np.asarray(coefficients, np.float64)
        self.weights = np.concatenate([np.ones((len(c), 1)), c], axis=1)          # (P, K+1)

    def theta_d(self, rows, local):
        """SSDF of points ``rows`` at local directions ``local`` (len(rows), L, 3) -> (.., L)."""
        u, v = square_coordinates(local)
        val = bilinear(self.images, u, v, self.resolution)                        # (R, L, K+1)
        val = np.einsum("rlk,rk->rl", val, self.weights[rows])
        return val - _horizon(local)

    def theta_d_slopes(self, rows, local, e1, e2):
        """:func:`theta_d_slopes` of points ``rows``."""
        w = self.weights[rows]

        def sample(u, v):
            return tuple(np.einsum("rlk,rk->rl", x, w)
                         for x in bilinear(self.images, u, v, self.resolution, gradient=True))
        return theta_d_slopes(sample, local, e1, e2)


class ImageField:
    """The SSDF of every point as full images (P, n*n) (no compression)."""

    def __init__(self, images, resolution: int):
        self.images = np.asarray(images, np.float64)
        self.resolution = int(resolution)

    def theta_d(self, rows, local):
        u, v = square_coordinates(local)
        val = bilinear(self.images[rows][:, None, :], u, v, self.resolution)[..., 0]
        return val - _horizon(local)

    def theta_d_slopes(self, rows, local, e1, e2):
        """:func:`theta_d_slopes` of points ``rows``."""
        images = self.images[rows][:, None, :]

        def sample(u, v):
            return tuple(x[..., 0] for x in bilinear(images, u, v, self.resolution,
                                                     gradient=True))
        return theta_d_slopes(sample, local, e1, e2)


def _local(dirs, n, t, b):
    return np.stack([np.einsum("plk,pk->pl", dirs, t), np.einsum("plk,pk->pl", dirs, b),
                     np.einsum("plk,pk->pl", dirs, n)], axis=-1)


def visibility_integral(theta_d, lam, exact=False):
    """Eq. 30 ``f_h(theta_d, lam)`` (``exact``: quadrature; else eq. 47-49)."""
    if exact:
        return sg.visibility_integral_fh(theta_d, lam)
    return sg.fh_hat_approx(theta_d, lam) * sg.hemisphere_integral(lam)


def visibility_ratio(theta_d, lam, exact=False):
    """Eq. 31 amplitude factor ``f_h(theta_d, lam) / f_h(pi/2, lam)``."""
    return sg.fh_hat(theta_d, lam) if exact else sg.fh_hat_approx(theta_d, lam)


def diffuse_lobe_transfer(field, rows, normals, light_axes, light_lam, tangents=None,
                          bitangents=None, exact_fh=False, cosine=COSINE_EQ40,
                          per_cosine=False):
    """Eq. 39 per light lobe: ``T[r, j] = (C*(i; n_r) (x) G(i; p_j, lam_j, 1)) . V^d_r``
    (R, J), the diffuse transfer of each *unit-amplitude* light lobe, so that
    ``R_d = T mu`` for RGB amplitudes ``mu`` (J, 3).  ``per_cosine``: keep the terms of
    the clamped-cosine mixture's lobes apart, ``T[r, m, j]`` (R, M, J), for amplitudes
    ``mu[m, j]`` per (cosine lobe, light lobe) (:func:`diffuse_transfer_per_cosine`).
    ``light_axes`` (J, 3) or (R, J, 3) world, ``light_lam`` (J,)/(R, J); the rest as
    :func:`diffuse_transfer`."""
    n = np.asarray(normals, np.float64)
    R = len(n)
    if tangents is None:
        tangents, bitangents = ssdf_frames(n)
    ax = np.broadcast_to(np.asarray(light_axes, np.float64), (R,) + np.shape(light_axes)[-2:])
    lam = np.broadcast_to(np.asarray(light_lam, np.float64), ax.shape[:2])
    M = len(cosine.amplitudes)
    out = np.zeros((R, M, ax.shape[1]))
    if ax.shape[1] > 0:
        for k, (p, lam_m, amp) in enumerate(_cosine_products(cosine, n, tangents, bitangents,
                                                               ax, lam)):
            theta = field.theta_d(rows, _local(p, n, tangents, bitangents))
            out[:, k] = visibility_integral(theta, lam_m, exact_fh) * amp           # (R, J)
    return out if per_cosine else out.sum(axis=1)


def _cosine_products(cosine, n, tangents, bitangents, axes, lam):
    """Per lobe of the clamped-cosine mixture ``C*`` (in each point's frame): its SG product
    ``(axis (R, J, 3), sharpness (R, J), amplitude (R, J))`` with the lobes ``axes``
    (R, J, 3), ``lam`` (R, J) of unit amplitude (eq. 39 and 41 both probe the SSDF there)."""
    for d, c in zip(cosine.directions, cosine.amplitudes):
        cw = d[0] * tangents + d[1] * bitangents + d[2] * n
        cn = np.broadcast_to(cw[:, None, :], axes.shape)
        yield sg.product(cn, np.full(axes.shape[:2], cosine.sharpness),
                         np.full(axes.shape[:2], c), axes, lam, 1.0)


def diffuse_transfer(field, rows, normals, light_axes, light_lam, light_mu,
                     tangents=None, bitangents=None, exact_fh=False, cosine=COSINE_EQ40):
    """Eq. 39 (and eq. 42 with per-point light lobes): ``R_d`` (R, 3).

    ``light_axes`` (J, 3) or (R, J, 3) world, ``light_lam`` (J,)/(R, J),
    ``light_mu`` (J, 3)/(R, J, 3) RGB amplitudes; ``normals`` (R, 3) of the
    points ``rows`` of ``field``; ``cosine`` the SG mixture ``C*`` (eq. 40 by
    default): every (cosine lobe, light lobe) product gets its own SSDF value.
    """
    T = diffuse_lobe_transfer(field, rows, normals, light_axes, light_lam, tangents,
                              bitangents, exact_fh, cosine)
    mu = np.broadcast_to(np.asarray(light_mu, np.float64), T.shape + (3,))
    return np.einsum("rj,rjc->rc", T, mu)


def diffuse_transfer_per_cosine(field, rows, normals, light_axes, light_lam, cosine_mu,
                                tangents=None, bitangents=None, exact_fh=False,
                                cosine=COSINE_EQ40):
    """Eq. 39 with an RGB amplitude per (cosine lobe m, light lobe j), ``cosine_mu``
    (M, J, 3): ``R_d = sum_m sum_j cosine_mu[m, j] f_h(...)`` -- each lobe of the
    clamped-cosine mixture sees its own amplitudes of the same light lobes (the
    scene-fitted lighting, ``core.sg.lighting.fit_scene_amplitudes``).  With
    ``cosine_mu[m] = mu`` for every m it is :func:`diffuse_transfer`."""
    T = diffuse_lobe_transfer(field, rows, normals, light_axes, light_lam, tangents,
                              bitangents, exact_fh, cosine, per_cosine=True)
    return np.einsum("rmj,mjc->rc", T, np.asarray(cosine_mu, np.float64))


#: the visible part's lobe (:func:`visible_lobe`): its axis moves at most this far
#: (radians), and its spread across the cut keeps at least this share of the lobe's
SHIFT_MAX = 1.2
SPREAD_MIN = 0.02
#: the standard normal CDF's argument is clamped here (the ratio pdf/CDF stays accurate
#: in float32; a lobe 4 widths inside the shadow is dark by f_h anyway)
Z_RANGE = (-4.0, 6.0)


def visible_lobe(lam, theta, slope1, slope2):
    """The lobe standing for the visible part of ``G(i; p, lam)`` cut by the visibility
    boundary of eq. 31 -- a great circle at signed distance ``theta`` from ``p`` -- whose
    side is given by the SSDF's slopes ``(slope1, slope2)`` along tangents ``e1, e2`` at
    ``p``.  In the lobe's tangent plane (a Gaussian of variance ``s^2 = 1/lam``) the cut
    keeps ``x . g > -theta`` (``g`` the slope's direction); the kept part has its mean at
    ``s h`` along ``g`` and variance ``s^2 (1 - z h - h^2)`` there (``z = theta / s``,
    ``h = phi(z) / Phi(z)``: the truncated normal), ``s^2`` across.

    Returns ``(shift (R, K), (g1, g2) the unit slope direction's components along e1, e2,
    lam_v (R, K))``: the visible part's axis is ``cos(shift) p + sin(shift) g`` and its
    sharpness ``lam_v = 2 / (s^2 + var)`` (the same mean cosine).  Eq. 41's
    ``Gamma_L`` is read there: eq. 31 keeps the axis, i.e. the light of the whole lobe,
    where a lobe half in shadow sees only its open side's.  Far from the boundary
    (``z`` large) it is ``p`` and ``lam``; a flat field (no slope) keeps ``p``."""
    lam = np.asarray(lam, np.float64)
    s = 1.0 / np.sqrt(lam)
    z = np.clip(np.asarray(theta, np.float64) / s, *Z_RANGE)
    h = np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi) / np.maximum(sg.normal_cdf(z), 1e-30)
    shift = np.minimum(s * h, SHIFT_MAX)
    var = s * s * np.maximum(1.0 - z * h - h * h, SPREAD_MIN)
    length = np.hypot(slope1, slope2)
    flat = length < 1e-6
    inv = 1.0 / np.where(flat, 1.0, length)
    shift = np.where(flat, 0.0, shift)
    return shift, (slope1 * inv, slope2 * inv), 2.0 / (s * s + var)


def specular_radiance(field, rows, normals, lobe_axes, lobe_lam, lobe_mu, env_lookup,
                      tangents=None, bitangents=None, exact_fh=False, cosine=COSINE_EQ40):
    """Eq. 41: ``R_s(o)`` (R, 3) from the view slice ``(lobe_axes (R, K, 3), lobe_lam (R, K),
    lobe_mu (R, K, 3))`` of ``ks rho_s`` (world space, no cosine) and ``env_lookup(dirs
    (M, 3), lam (M,)) -> (M, 3)``, the SG-prefiltered environment ``Gamma_L`` (eq. 35).
    Each product lobe's visible fraction is eq. 31's; ``Gamma_L`` is read at the lobe of
    its visible part (:func:`visible_lobe`, from the SSDF's slope at the axis)."""
    n = np.asarray(normals, np.float64)
    R = len(n)
    ax = np.asarray(lobe_axes, np.float64)
    out = np.zeros((R, 3))
    if ax.shape[1] == 0:
        return out
    if tangents is None:
        tangents, bitangents = ssdf_frames(n)
    frame = np.stack([tangents, bitangents, n], axis=1)                         # (R, 3, 3)
    for p, lam_m, amp in _cosine_products(cosine, n, tangents, bitangents, ax,
                                          np.asarray(lobe_lam, np.float64)):
        local = _local(p, n, tangents, bitangents)
        e1, e2 = (x.reshape(local.shape) for x in orthonormal_frame(local.reshape(-1, 3)))
        theta, d1, d2 = field.theta_d_slopes(rows, local, e1, e2)
        scale = amp * visibility_ratio(theta, lam_m, exact_fh)                    # (R, K)
        shift, (g1, g2), lam_v = visible_lobe(lam_m, theta, d1, d2)
        c = (np.cos(shift)[..., None] * local
             + np.sin(shift)[..., None] * (g1[..., None] * e1 + g2[..., None] * e2))
        c = np.einsum("rkx,rxy->rky", c, frame)
        gamma = np.asarray(env_lookup(c.reshape(-1, 3), lam_v.reshape(-1)), np.float64)
        gamma = gamma.reshape(p.shape[:2] + (3,)) * (sg.integral(lam_m) / sg.integral(lam_v))[..., None]
        out += np.einsum("rk,rkc,rkc->rc", scale, np.asarray(lobe_mu, np.float64), gamma)
    return out


def lamp_radiance(field, rows, normals, lamp_axes, lamp_lam, lamp_mu, kd, lobe_axes=None,
                  lobe_lam=None, lobe_mu=None, tangents=None, bitangents=None, exact_fh=False,
                  cosine=COSINE_EQ40):
    """Eq. 42 + 43 for SG lights ``(lamp_axes (R, J, 3), lamp_lam (R, J), lamp_mu (R, J, 3))``:
    ``kd R_d + R_s`` (R, 3); ``kd`` (3,) or (R, 3) is ``albedo / pi``; ``cosine`` the
    clamped-cosine mixture of the diffuse part (eq. 42), as for the environment."""
    out = diffuse_transfer(field, rows, normals, lamp_axes, lamp_lam, lamp_mu, tangents,
                           bitangents, exact_fh, cosine=cosine) * np.asarray(kd, np.float64)
    if lobe_axes is None or np.shape(lobe_axes)[1] == 0:
        return out
    n = np.asarray(normals, np.float64)
    if tangents is None:
        tangents, bitangents = ssdf_frames(n)
    la = np.asarray(lamp_axes, np.float64)
    R, J = la.shape[:2]
    K = np.shape(lobe_axes)[1]
    # L* (x) C*: (R, J); then (x) rho*_k: (R, J, K)
    cn = np.broadcast_to(n[:, None, :], la.shape)
    p1, l1, a1 = sg.product(la, np.asarray(lamp_lam, np.float64), 1.0, cn,
                            np.full((R, J), LAMBDA_C), MU_C)
    p2, l2, a2 = sg.product(p1[:, :, None, :], l1[:, :, None], a1[:, :, None],
                            np.asarray(lobe_axes, np.float64)[:, None, :, :],
                            np.asarray(lobe_lam, np.float64)[:, None, :], 1.0)
    theta = field.theta_d(rows, _local(p2.reshape(R, J * K, 3), n, tangents, bitangents))
    f = (visibility_integral(theta, l2.reshape(R, J * K), exact_fh) * a2.reshape(R, J * K))
    f = f.reshape(R, J, K)
    return out + np.einsum("rjk,rjc,rkc->rc", f, np.asarray(lamp_mu, np.float64),
                           np.asarray(lobe_mu, np.float64))


def analytic_sg_environment(axes, lam, mu):
    """``Gamma_L(p, lam)`` of eq. 35 for an environment that *is* an SG mixture
    (exact inner products, eq. 4): a lookup for tests."""
    axes = np.asarray(axes, np.float64)
    lam_e = np.asarray(lam, np.float64)
    mu_e = np.asarray(mu, np.float64)

    def lookup(dirs, lam_q):
        d = np.asarray(dirs, np.float64)[:, None, :]
        ip = sg.inner_product(d, np.asarray(lam_q, np.float64)[:, None], 1.0,
                              axes[None], lam_e[None], 1.0)                       # (M, J)
        return ip @ mu_e

    return lookup


def sg_mixture_radiance(dirs, axes, lam, mu):
    """Radiance (M, 3) of an SG mixture at unit directions ``dirs`` (M, 3)."""
    g = sg.evaluate(np.asarray(dirs, np.float64)[:, None, :], np.asarray(axes)[None],
                    np.asarray(lam)[None], 1.0)
    return g @ np.asarray(mu, np.float64)


def equirect_from_sgs(height, axes, lam, mu):
    """An equirect image (H, 2H, 3) of an SG mixture (texture orientation of
    ``core.sphere.envmap``): lighting whose diffuse SG fit is exact, for tests."""
    from ...sphere.envmap import equirect_directions
    dirs, _ = equirect_directions(height, 2 * height, 1)
    return sg_mixture_radiance(dirs.reshape(-1, 3), axes, lam, mu).reshape(
        height, 2 * height, 3).astype(np.float32)


__all__ = ["CosineLobes", "COSINE_EQ40", "COSINE_SG7", "COSINE_SG19", "COSINE_MODELS", "PCAField", "ImageField", "diffuse_transfer", "diffuse_lobe_transfer", "diffuse_transfer_per_cosine", "specular_radiance", "lamp_radiance",
           "visibility_integral", "visibility_ratio", "analytic_sg_environment",
           "sg_mixture_radiance", "equirect_from_sgs", "LAMBDA_C", "MU_C"]
