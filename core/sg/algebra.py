"""Spherical Gaussians (Wang, Ren, Gong, Snyder, Guo 2009, "All-Frequency
Rendering of Dynamic, Spatially-Varying Reflectance").

Equation numbers below refer to that paper.

Representation (eq. 2)::

    G(v; p, lam, mu) = mu * exp(lam * (v . p - 1))

with unit lobe axis ``p`` (..., 3), sharpness ``lam`` > 0 (...,) and amplitude
``mu`` (...,).  Every function broadcasts over leading lobe axes and works in
float64.  Lobes are passed as plain arrays ``(p, lam, mu)``; functions that
return a lobe return such a tuple.

Numerics.  Everything is written so that ``exp`` only ever sees non-positive
arguments: ``e^{-(lam1+lam2)} sinh(d)/d`` is rewritten as
``exp(-(lam1 + lam2 - d)) * (-expm1(-2 d)) / (2 d)`` and the "defect"
``lam1 + lam2 - d`` (which cancels catastrophically for nearly aligned lobes
when computed as a difference) is evaluated as
``2 lam1 lam2 (1 - cos g) / (lam1 + lam2 + d)`` with ``1 - cos g = |p1 - p2|^2/2``.
Nothing overflows for lam in [1e-3, 1e5] (or any finite lam); values that are
genuinely below the float64 range underflow to 0, and their logarithm is
available from :func:`log_inner_product` / :func:`log_product_amplitude`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = [
    "SG", "evaluate", "integral", "hemisphere_integral", "inner_product",
    "log_inner_product", "product", "log_product_amplitude", "rotate",
    "support_area", "support_area_inverse", "warp_distortion", "spherical_warp",
    "CLAMPED_COSINE_LAMBDA", "CLAMPED_COSINE_MU", "clamped_cosine_sg",
    "visibility_integral_fh", "fh_hat", "fh_hat_approx",
    "visibility_integral_fh_approx", "visibility_product", "tabulate_fh_hat",
    "fit_fh_coefficients", "fh_fit_errors", "fh_hat_slope", "fh_slope", "normal_cdf",
    "FH_COEFFS", "FH_FIT_MAX_ABS_ERROR", "FH_FIT_RMS_ERROR",
]

TWO_PI = 2.0 * math.pi
FOUR_PI = 4.0 * math.pi


class SG(NamedTuple):
    """Convenience container for a (batch of) lobe(s): eq. 2 parameters."""

    axis: np.ndarray        # (..., 3) unit p
    sharpness: np.ndarray   # (...,)   lam
    amplitude: np.ndarray   # (...,)   mu


def _f64(x):
    return np.asarray(x, dtype=np.float64)


def _one_minus_exp_neg(lam, x=1.0):
    """``(1 - exp(-lam * x)) / lam`` for lam >= 0, stable (limit x at lam = 0)."""
    lam = _f64(lam)
    x = _f64(x)
    safe = np.where(lam > 0, lam, 1.0)
    return np.where(lam > 0, -np.expm1(-safe * x) / safe, x + 0.0 * lam)


def _dot(a, b):
    return np.sum(_f64(a) * _f64(b), axis=-1)


# --------------------------------------------------------------------------- basics

def evaluate(v, p, lam, mu=1.0):
    """Eq. 2: ``G(v; p, lam, mu) = mu * exp(lam (v . p - 1))``.

    ``v`` and ``p`` are (..., 3) unit vectors, broadcast against each other and
    against ``lam`` / ``mu`` (...,).  ``v . p - 1`` is taken as ``-|v - p|^2/2``
    so that sharp lobes are accurate next to their axis.
    """
    v = _f64(v)
    p = _f64(p)
    d = v - p
    return _f64(mu) * np.exp(-0.5 * _f64(lam) * np.sum(d * d, axis=-1))


def integral(lam, mu=1.0):
    """Integral of one SG over the sphere.

    ``int_S2 mu e^{lam (v.p - 1)} dv = 2 pi mu (1 - e^{-2 lam}) / lam``, i.e. the
    inner product (eq. 4) with the constant SG ``G(v; ., 0, 1)``:
    ``4 pi mu e^{-lam} sinh(lam)/lam``.  Evaluated as ``2 pi mu (-expm1(-2 lam))/lam``
    (limit ``4 pi mu`` as lam -> 0).
    """
    return TWO_PI * _f64(mu) * _one_minus_exp_neg(lam, 2.0)


def hemisphere_integral(lam, mu=1.0):
    """Integral over the hemisphere around the lobe axis: ``f_h(pi/2, lam)`` (eq. 31, 47).

    ``int_{v.p >= 0} G dv = (2 pi mu / lam)(1 - e^{-lam})``.
    """
    return TWO_PI * _f64(mu) * _one_minus_exp_neg(lam, 1.0)


def _defect(p1, lam1, p2, lam2):
    """``(d_m, lam1 + lam2 - d_m)`` with ``d_m = |lam1 p1 + lam2 p2|``, both stable."""
    p1 = _f64(p1)
    p2 = _f64(p2)
    lam1 = _f64(lam1)
    lam2 = _f64(lam2)
    dvec = lam1[..., None] * p1 + lam2[..., None] * p2
    dm = np.sqrt(np.sum(dvec * dvec, axis=-1))
    diff = p1 - p2
    one_minus_cos = np.clip(0.5 * np.sum(diff * diff, axis=-1), 0.0, 2.0)
    s = lam1 + lam2
    denom = s + dm
    defect = np.where(denom > 0, 2.0 * lam1 * lam2 * one_minus_cos / np.where(denom > 0, denom, 1.0), 0.0)
    return dm, defect, dvec


def inner_product(p1, lam1, mu1, p2, lam2, mu2):
    """Eq. 4: ``int G1 G2 dv = 4 pi mu1 mu2 e^{-(lam1+lam2)} sinh(d_m)/d_m``,
    ``d_m = |lam1 p1 + lam2 p2|``.

    Evaluated as ``2 pi mu1 mu2 exp(-(lam1 + lam2 - d_m)) (-expm1(-2 d_m)) / d_m``
    (limit ``4 pi mu1 mu2 e^{-(lam1+lam2)}`` for d_m -> 0, e.g. equal antipodal
    lobes): finite for all finite inputs, >= 0 for non-negative amplitudes.
    """
    dm, defect, _ = _defect(p1, lam1, p2, lam2)
    return TWO_PI * _f64(mu1) * _f64(mu2) * np.exp(-defect) * _one_minus_exp_neg(dm, 2.0)


def log_inner_product(p1, lam1, mu1, p2, lam2, mu2):
    """Natural log of :func:`inner_product` (amplitudes must be > 0).

    ``log(2 pi mu1 mu2) - (lam1 + lam2 - d_m) + log((1 - e^{-2 d_m})/d_m)``: exact
    even where the inner product itself underflows (antipodal sharp lobes).
    """
    dm, defect, _ = _defect(p1, lam1, p2, lam2)
    return (np.log(TWO_PI * _f64(mu1) * _f64(mu2)) - defect
            + np.log(_one_minus_exp_neg(dm, 2.0)))


def product(p1, lam1, mu1, p2, lam2, mu2):
    """Eq. 5 / 45: the vector product ``G1(v) G2(v)`` is exactly one SG.

    With ``d = lam1 p1 + lam2 p2`` (the paper writes ``p_m = d/(lam1+lam2)``,
    ``lam_m = lam1 + lam2``)::

        axis      = d / |d|
        sharpness = |d|                          (= lam_m |p_m|)
        amplitude = mu1 mu2 exp(|d| - lam1 - lam2)   (= mu1 mu2 e^{lam_m(|p_m| - 1)})

    Returns ``(axis, sharpness, amplitude)``.  The exponent is <= 0 and is
    computed without cancellation.  When ``d = 0`` (equal antipodal lobes) the
    product is the constant ``mu1 mu2 e^{-2 lam}``: axis ``p1``, sharpness 0.
    """
    dm, defect, dvec = _defect(p1, lam1, p2, lam2)
    p1 = _f64(p1)
    ok = dm > 0
    axis = np.where(ok[..., None], dvec / np.where(ok, dm, 1.0)[..., None],
                    np.broadcast_to(p1, dvec.shape))
    amp = _f64(mu1) * _f64(mu2) * np.exp(-defect)
    return axis, dm, amp


def log_product_amplitude(p1, lam1, mu1, p2, lam2, mu2):
    """``log`` of the product amplitude of eq. 45 (mu1, mu2 > 0), for tiny products."""
    _, defect, _ = _defect(p1, lam1, p2, lam2)
    return np.log(_f64(mu1) * _f64(mu2)) - defect


def rotate(rotation, p):
    """Eq. 7: rotating an SG (mixture) rotates its axes only: ``p' = R p``.

    ``rotation`` is (3, 3) or (..., 3, 3); ``p`` (..., 3).  Sharpness and
    amplitude are unchanged.
    """
    return np.einsum("...ij,...j->...i", _f64(rotation), _f64(p))


# --------------------------------------------------------------------------- warp (sec. 4.3)

#: threshold of the epsilon-support (eq. 3); the paper uses 0.1.
SUPPORT_EPSILON = 0.1


def support_area(lam, eps=SUPPORT_EPSILON):
    """Eq. 3: ``f_a(lam) = area{G(v; z, lam, 1) >= eps} = -2 pi ln(eps) / lam``
    (valid for lam > -ln eps)."""
    return -TWO_PI * math.log(eps) / _f64(lam)


def support_area_inverse(area, eps=SUPPORT_EPSILON):
    """Inverse of eq. 3: ``f_a^{-1}(A) = -2 pi ln(eps) / A``."""
    return -TWO_PI * math.log(eps) / _f64(area)


def warp_distortion(h, o):
    """Eq. 21: ``tau(h) = |di/dh| = 4 |h . o|`` for the warp ``i = 2 (o.h) h - o``."""
    return 4.0 * np.abs(_dot(h, o))


def spherical_warp(p, lam, mu, o, min_tau=1e-9):
    """Eq. 17-20: per-lobe warp of an NDF lobe ``G(h; p, lam, mu)`` into the
    light domain for view direction ``o`` (unit, (..., 3)).

    * axis (eq. 18):       ``p_W = psi(p) = 2 (o . p) p - o``
    * sharpness (eq. 19):  ``lam_W = f_a^{-1}(f_a(lam) tau(p)) = lam / tau(p)``,
      ``tau(p) = 4 |p . o|`` (eq. 21)
    * amplitude (eq. 20):  ``mu_W = mu``

    ``tau`` is floored at ``min_tau`` so that a lobe axis exactly perpendicular
    to ``o`` (where the warp degenerates) yields a large finite sharpness
    instead of ``inf``.  The axis is renormalised (it is unit analytically).
    Returns ``(p_W, lam_W, mu_W)``.
    """
    p = _f64(p)
    o = _f64(o)
    c = _dot(o, p)
    pw = 2.0 * c[..., None] * p - o
    pw = pw / np.linalg.norm(pw, axis=-1, keepdims=True)
    tau = np.maximum(4.0 * np.abs(c), min_tau)
    lam_w = support_area_inverse(support_area(lam) * tau)
    mu_w = np.broadcast_to(_f64(mu), np.broadcast_shapes(np.shape(mu), lam_w.shape)).copy()
    return pw, lam_w, mu_w


# --------------------------------------------------------------------------- clamped cosine (eq. 40)

#: Eq. 40: single-lobe SG fit of ``max(0, n . v)``: ``G(v; n, 2.133, 1.170)``.
CLAMPED_COSINE_LAMBDA = 2.133
CLAMPED_COSINE_MU = 1.170


def clamped_cosine_sg(n=None):
    """Eq. 40: ``C*(i; n) = G(i; n, lam_c = 2.133, mu_c = 1.170)``.

    Without ``n`` returns ``(lam_c, mu_c)``; with unit normals ``n`` (..., 3)
    returns the lobe ``(n, lam_c, mu_c)`` broadcast to ``n``'s batch shape.
    (L2 error against ``max(0, cos)`` over the sphere, by quadrature in
    tests/core/sg/test_algebra.py: 0.2568, i.e. 17.7% of ``||max(0, cos)||_2 = sqrt(2 pi/3)``;
    a grid search finds the L2 optimum within 0.5% of it.)
    """
    if n is None:
        return CLAMPED_COSINE_LAMBDA, CLAMPED_COSINE_MU
    n = _f64(n)
    shape = n.shape[:-1]
    return n, np.full(shape, CLAMPED_COSINE_LAMBDA), np.full(shape, CLAMPED_COSINE_MU)


# --------------------------------------------------------------------------- visibility f_h (eq. 25-31)

def _gauss_legendre(n):
    x, w = np.polynomial.legendre.leggauss(int(n))
    return x, w


def visibility_integral_fh(theta_d, lam, panels=4, nodes=32):
    """Eq. 30: ``f_h(theta_d, lam)``, integral of ``G(i; z+, lam, 1)`` over the
    intersection of the lobe's hemisphere ``{i . z+ >= 0}`` with the visibility
    hemisphere of eq. 25-26 whose boundary lies at angular distance ``theta_d``
    from the lobe axis (visible side containing the axis when ``theta_d > 0``).

    In the paper's parameterisation this is
    ``int_0^pi int_{pi/2 - theta_d}^pi exp(lam (i.z - 1)) sin(xi) d delta d xi``
    with ``i . z = sin(xi) sin(delta)``, i.e. ``delta`` measured from x+ towards
    z+.  (Eq. 27 as printed swaps ``sin(delta)`` and ``cos(delta)``; that reading
    would make ``f_h(pi/2, lam)`` half the sphere integral instead of the
    ``(2 pi/lam)(1 - e^{-lam})`` stated under eq. 31 / 47, and the normalised
    ``f_h/f_h(pi/2)`` would not lie in (0, 1) as eq. 47 requires.)

    Computed by reducing to one dimension in the polar angle ``t`` about the
    axis: the visible fraction of the circle ``{angle(i, z) = t}`` is
    ``F(t) = 1 - arccos(clip(tan(theta_d)/tan(t), -1, 1))/pi``, so::

        f_h = 2 pi int_0^{pi/2} e^{lam (cos t - 1)} sin t F(t) dt.

    ``F`` is constant (1 or 0) for ``t < |theta_d|`` (done in closed form) and
    has a square-root kink at ``t = |theta_d|``; the rest is integrated by
    composite Gauss-Legendre in ``s`` with ``t = |theta_d| + s^2`` (which makes
    the integrand smooth) up to where the lobe has decayed by ``e^{-60}``
    relative to its value at the kink.  Relative accuracy ~1e-12 for lam in
    [1e-3, 1e5].  ``theta_d`` is clipped to [-pi/2, pi/2] (beyond it the
    visibility hemisphere contains or misses the whole lobe hemisphere).
    Broadcasts ``theta_d`` against ``lam``.
    """
    td = np.clip(_f64(theta_d), -0.5 * math.pi, 0.5 * math.pi)
    lam = _f64(lam)
    td, lam = np.broadcast_arrays(td, lam)
    a = np.abs(td)
    # piece 1: t in [0, |theta_d|], F = 1 if theta_d > 0 else 0
    one_minus_cos_a = 2.0 * np.sin(0.5 * a) ** 2
    piece1 = np.where(td > 0, TWO_PI * _one_minus_exp_neg(lam, one_minus_cos_a), 0.0)
    # piece 2: t in [a, t_max]
    cos_a = np.cos(a)
    safe_lam = np.where(lam > 0, lam, 1.0)
    cos_end = np.where(lam > 0, np.maximum(cos_a - 60.0 / safe_lam, 0.0), 0.0)
    t_max = np.minimum(np.arccos(np.clip(cos_end, -1.0, 1.0)), 0.5 * math.pi)
    s_max = np.sqrt(np.maximum(t_max - a, 0.0))
    x, w = _gauss_legendre(nodes)
    edges = np.linspace(0.0, 1.0, panels + 1)
    u = ((edges[:-1, None] + edges[1:, None]) * 0.5 + (edges[1:, None] - edges[:-1, None]) * 0.5 * x[None, :]).ravel()
    wu = (np.broadcast_to((edges[1:, None] - edges[:-1, None]) * 0.5 * w[None, :], (panels, nodes))).ravel()
    s = s_max[..., None] * u                        # (..., Q)
    t = a[..., None] + s * s
    sin_t = np.sin(t)
    sin_td = np.sin(td)[..., None]
    cos_td = np.cos(td)[..., None]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c = sin_td * np.cos(t) / np.maximum(cos_td * sin_t, 1e-300)
    c = np.clip(np.nan_to_num(c, nan=0.0, posinf=1.0, neginf=-1.0), -1.0, 1.0)
    frac = 1.0 - np.arccos(c) / math.pi
    g = np.exp(-2.0 * lam[..., None] * np.sin(0.5 * t) ** 2) * sin_t * frac * 2.0 * s
    piece2 = TWO_PI * s_max * np.sum(g * wu, axis=-1)
    return piece1 + piece2


def fh_hat(theta_d, lam, **kw):
    """Eq. 46: ``f_h(theta_d, lam) / f_h(pi/2, lam)`` in [0, 1] (exact, by quadrature)."""
    return visibility_integral_fh(theta_d, lam, **kw) / hemisphere_integral(lam)


# Eq. 47-49 fit f_h / f_h(pi/2) with a sigmoid of slope k(lam) in theta_d: the logistic
# ``a / (1 + e^{-k theta_d}) + (1 - a)/2`` with a = 1.05 and k a cubic in lam.  As printed
# the constants do not reproduce the tabulated f_h (k(0) = 0.067 is almost flat where the
# true small-lam curve is 1/2 + theta_d/pi; k ~ lam^3 grows far faster than ~sqrt(lam):
# max error 0.47), and no logistic follows the true tails (refitted with a cubic in
# sqrt(lam): 0.079 off in every lam range; a lobe 3 widths inside a shadow kept 4 % of its
# light instead of 0.1 %).  Ours keeps the structure, one slope per lobe (what the GPU's
# pair table stores), with the sigmoid of a sharp lobe: cut by a great circle at theta_d
# it keeps Phi(theta_d sqrt(lam)) of itself (a Gaussian in its tangent plane), scaled so
# that theta_d = -pi/2 and pi/2 give 0 and 1 exactly as eq. 46 does (fh_hat_slope; as
# k -> 0 that is the broad lobe's 1/2 + theta_d/pi):
#     fh_hat ~ (Phi(k theta_d) - Phi(-k pi/2)) / (1 - 2 Phi(-k pi/2)),
#     k^2 = lam + c0 - b lam / (lam + d),
# (c0, b, d) by fit_fh_coefficients() on tabulate_fh_hat()'s table (lam = logspace(-3, 5,
# 81); per lam 121 uniform theta_d on [-pi/2, pi/2] plus 61 within +-5/sqrt(lam); exact
# values from visibility_integral_fh): max error 0.0019 at lam < 1, 0.0046 at 1-10, 0.0032
# at 10-100, 0.0007 beyond (rms 0.00076; the logistic refit: 0.079 / 0.031).
#: (c0, b, d) of k(lam)
FH_COEFFS = (0.0046413591658328954, 1.4672958011923942, 3.6002488734472657)
#: max |fh_hat_approx - fh_hat| over the default table (clipped), rounded up.
FH_FIT_MAX_ABS_ERROR = 0.0047
#: rms of the same, rounded up.
FH_FIT_RMS_ERROR = 0.0008


def normal_cdf(z):
    """Standard normal CDF through erfc of Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7;
    the GLSL twins use the same formula)."""
    z = np.asarray(z, np.float64)
    x = np.abs(z) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.3275911 * x)
    y = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                          + t * 1.061405429))))
    half_erfc = 0.5 * y * np.exp(-x * x)
    return np.where(z >= 0.0, 1.0 - half_erfc, half_erfc)


def fh_slope(lam, coeffs=None):
    """The sigmoid's slope ``k(lam) = sqrt(lam + c0 - b lam / (lam + d))`` (:data:`FH_COEFFS`)."""
    c0, b, d = FH_COEFFS if coeffs is None else coeffs
    lam = _f64(lam)
    return np.sqrt(np.maximum(lam + c0 - b * lam / (lam + d), 1e-12))


def fh_hat_slope(theta_d, k, clip=True):
    """``(Phi(k theta_d) - Phi(-k pi/2)) / (1 - 2 Phi(-k pi/2))`` for ``theta_d`` clipped to
    [-pi/2, pi/2]: 0 and 1 at the ends as eq. 46 (a lobe whose whole hemisphere is blocked
    is black), ``1/2 + theta_d/pi`` as ``k -> 0`` (the GLSL ``fh_hat_slope``; ``clip``: the
    result too, to [0, 1])."""
    td = np.clip(_f64(theta_d), -0.5 * math.pi, 0.5 * math.pi)
    k = _f64(k)
    low = normal_cdf(-0.5 * math.pi * k)
    val = (normal_cdf(k * td) - low) / (1.0 - 2.0 * low)
    return np.clip(val, 0.0, 1.0) if clip else val


def fh_hat_approx(theta_d, lam, coeffs=None, clip=True):
    """Eq. 47-48 refitted: ``fh_hat ~ Phi(k(lam) theta_d)`` (:func:`fh_slope`)."""
    return fh_hat_slope(theta_d, fh_slope(lam, coeffs), clip)


def visibility_integral_fh_approx(theta_d, lam, coeffs=None):
    """Eq. 49: ``f_h(theta_d, lam) ~ fh_hat_approx(theta_d, lam) f_h(pi/2, lam)``."""
    return fh_hat_approx(theta_d, lam, coeffs) * hemisphere_integral(lam)


def visibility_product(p, lam, mu, theta_d, exact=False):
    """Eq. 31: ``G(i; p, lam, mu) (x) V(i) ~ G(i; p, lam, mu f_h(theta_d, lam)/f_h(pi/2, lam))``."""
    ratio = fh_hat(theta_d, lam) if exact else fh_hat_approx(theta_d, lam)
    return _f64(p), _f64(lam), _f64(mu) * ratio


def tabulate_fh_hat(theta_d=None, lam=None):
    """Dense table of eq. 46: returns ``(theta_d (L, T), lam (L,), fhat (L, T))``.

    Defaults: ``lam = logspace(-3, 5, 81)``; per ``lam`` the row of ``theta_d``
    is the union of ``linspace(-pi/2, pi/2, 121)`` and 61 points
    ``linspace(-5, 5, 61) / sqrt(lam)`` adapted to the lobe width (clipped to
    [-pi/2, pi/2]), sorted -- a uniform grid alone would put no sample inside
    the transition of sharp lobes.  A 1-D ``theta_d`` is used for every row.
    """
    lam = np.logspace(-3.0, 5.0, 81) if lam is None else _f64(lam)
    if theta_d is None:
        uni = np.linspace(-0.5 * math.pi, 0.5 * math.pi, 121)
        adapt = np.clip(np.linspace(-5.0, 5.0, 61)[None, :] / np.sqrt(lam)[:, None],
                        -0.5 * math.pi, 0.5 * math.pi)
        theta_d = np.sort(np.concatenate([np.broadcast_to(uni, (lam.size, uni.size)), adapt], axis=1), axis=1)
    theta_d = np.broadcast_to(_f64(theta_d), (lam.size, np.shape(theta_d)[-1])).copy()
    return theta_d, lam, fh_hat(theta_d, lam[:, None])


def fit_fh_coefficients(theta_d=None, lam=None, fhat=None, start=FH_COEFFS, iterations=100):
    """Least-squares fit of ``(c0, b, d)`` of :func:`fh_slope` to a tabulation of ``fh_hat``
    (eq. 46; default :func:`tabulate_fh_hat`): Levenberg-Marquardt from ``start`` on
    ``sum (Phi(k theta_d) - fhat)^2`` over the whole (lam, theta_d) grid, the Jacobian by
    central differences.  Returns the coefficients."""
    if fhat is None:
        theta_d, lam, fhat = tabulate_fh_hat(theta_d, lam)
    th = np.broadcast_to(_f64(theta_d), np.shape(fhat))
    lam = _f64(lam)[:, None]
    fhat = _f64(fhat)

    def residual(c):
        return (fh_hat_slope(th, fh_slope(lam, c), clip=False) - fhat).ravel()

    def jacobian(c):
        cols = []
        for i in range(len(c)):
            h = 1e-6 * max(abs(c[i]), 1.0)
            up, down = np.array(c, float), np.array(c, float)
            up[i] += h
            down[i] -= h
            cols.append((residual(up) - residual(down)) / (2.0 * h))
        return np.stack(cols, axis=1)

    c = np.array(start, np.float64)
    r = residual(c)
    cost = r @ r
    damp = 1e-3
    for _ in range(int(iterations)):
        J = jacobian(c)
        JTJ, g = J.T @ J, J.T @ r
        improved = False
        for _ in range(30):
            step = np.linalg.solve(JTJ + damp * np.diag(np.diag(JTJ) + 1e-300), -g)
            r_new = residual(c + step)
            cost_new = r_new @ r_new
            if cost_new < cost:
                improved = True
                rel = (cost - cost_new) / max(cost, 1e-300)
                c, r, cost = c + step, r_new, cost_new
                damp = max(damp / 3.0, 1e-12)
                break
            damp *= 4.0
        if not improved or rel < 1e-12:
            break
    return tuple(float(x) for x in c)


def fh_fit_errors(coeffs=None, theta_d=None, lam=None, fhat=None):
    """Errors of :func:`fh_hat_approx` against a tabulation (default :func:`tabulate_fh_hat`).

    Returns a dict: ``max_abs`` = max |approx - fhat| (this is also the max error
    of eq. 49 relative to the hemisphere integral ``f_h(pi/2, lam)``), ``rms``,
    ``max_rel`` = max relative error of ``f_h`` where ``fhat >= 0.1``, and
    ``mean_sq`` = mean squared error over the grid (the paper's figure of merit
    up to normalisation).
    """
    if fhat is None:
        theta_d, lam, fhat = tabulate_fh_hat(theta_d, lam)
    approx = fh_hat_approx(np.broadcast_to(_f64(theta_d), np.shape(fhat)), _f64(lam)[:, None],
                           coeffs)
    err = approx - fhat
    mask = fhat >= 0.1
    return {
        "max_abs": float(np.max(np.abs(err))),
        "rms": float(np.sqrt(np.mean(err * err))),
        "max_rel": float(np.max(np.abs(err[mask]) / fhat[mask])),
        "mean_sq": float(np.mean(err * err)),
    }
