# SPDX-License-Identifier: GPL-3.0-or-later
"""The NDFs of :mod:`.sg_brdf` as spherical-Gaussian lobes (Wang et al. 2009, §4.1-4.3):
the analytic NDFs, their least-squares SG fits (isotropic eq. 12, coaxial GGX lobes,
anisotropic pairs), the fitted tables and the fitted warp of the GGX lobes' view slice."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..common.cache import memo
from ..common.fitting import levenberg_marquardt

MODELS = ("COOK_TORRANCE", "BLINN_PHONG", "WARD", "WARD_ANISO", "ASHIKHMIN_SHIRLEY", "GGX")
ISOTROPIC_MODELS = MODELS[:3] + ("GGX",)
#: coaxial SG lobes of the GGX NDF fit (one lobe loses its long tails: 14-20 % L2 error)
GGX_LOBES = 2
FRESNEL_MODES = ("NONE", "SCHLICK", "DIELECTRIC", "PRINCIPLED")
#: integer codes used by the GLSL twin (``shaders/lib/sg.glsl``).
MODEL_INDEX = {m: i for i, m in enumerate(MODELS)}
FRESNEL_INDEX = {m: i for i, m in enumerate(FRESNEL_MODES)}
#: most lobes :func:`specular_lobes` returns per point.
MAX_LOBES = 8
#: smallest slope parameter an SG NDF lobe is fitted for (sharpness 2/a^2 = 8e4); the
#: microfacet lobes' floor is core.shading.microfacet.MICROFACET_ALPHA_MIN.
SG_ALPHA_MIN = 0.005
#: cosines inside ``M_o`` are floored here (view and light at the horizon).
COS_MIN = 1e-4
#: Ward / Ashikhmin-Shirley ``M`` diverges like 1/sqrt(cos) at the horizon; its
#: cosines are floored at this larger value (the integrand ``M cos`` still -> 0).
COS_MIN_SINGULAR = 0.05
#: warped lobes are capped at this sharpness (grazing facets, tau -> 0).
LAMBDA_MAX = 1e5
#: floor of an NDF lobe's sharpness (Blinn-Phong's fit at a = 1 is a nearly constant lobe).
LAMBDA_MIN = 1e-4


def broadcast_rows(v, P, shape=()):
    return np.broadcast_to(np.asarray(v, dtype=np.float64), (P,) + shape)


# --------------------------------------------------------------------------- analytic NDFs

def ndf_value(model, h_local, roughness=0.3, aniso=(0.3, 0.1)):
    """Analytic NDF ``D(h)`` (module docstring) for local half vectors ``h_local``
    (..., 3) in the frame (t, b, n).  ``roughness`` is used by the isotropic
    models, ``aniso`` = (alpha_x, alpha_y) or (nu, nv) by the anisotropic ones.
    Zero below the horizon."""
    h = np.asarray(h_local, dtype=np.float64)
    c = np.clip(h[..., 2], 0.0, 1.0)
    c2 = np.maximum(c * c, 1e-300)
    s2 = np.maximum(1.0 - c * c, 0.0)
    tan2 = s2 / c2
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        if model in ISOTROPIC_MODELS:
            a = np.maximum(np.asarray(roughness, dtype=np.float64), SG_ALPHA_MIN)
            a2 = a * a
            if model == "COOK_TORRANCE":
                d = np.exp(-tan2 / a2) / (math.pi * a2 * c2 * c2)
            elif model == "WARD":
                d = np.exp(-tan2 / a2) / (math.pi * a2)
            elif model == "GGX":
                d = a2 / (math.pi * (s2 + a2 * c2) ** 2)
            else:
                e = np.maximum(2.0 / a2 - 2.0, 0.0)
                d = (e + 2.0) / (2.0 * math.pi) * np.exp(e * np.log(np.maximum(c, 1e-300)))
        else:
            hx, hy = h[..., 0], h[..., 1]
            r2 = hx * hx + hy * hy
            cos2p = np.where(r2 > 0, hx * hx / np.where(r2 > 0, r2, 1.0), 1.0)
            sin2p = 1.0 - cos2p
            p, q = float(aniso[0]), float(aniso[1])
            if model == "WARD_ANISO":
                d = np.exp(-tan2 * (cos2p / (p * p) + sin2p / (q * q))) / (math.pi * p * q)
            elif model == "ASHIKHMIN_SHIRLEY":
                e = p * cos2p + q * sin2p
                d = (math.sqrt((p + 1.0) * (q + 1.0)) / (2.0 * math.pi)
                     * np.exp(e * np.log(np.maximum(c, 1e-300))))
            else:
                raise ValueError(f"unknown model {model!r}")
    return np.where(c > 0.0, np.nan_to_num(d, nan=0.0, posinf=0.0), 0.0)


# --------------------------------------------------------------------------- isotropic fit

def _iso_support_cos(model, a):
    """cos(theta) below which the isotropic NDF is < e^-40 of its peak."""
    a = max(float(a), SG_ALPHA_MIN)
    if model == "BLINN_PHONG":
        e = max(2.0 / (a * a) - 2.0, 0.0)
        return 0.0 if e <= 40.0 else math.exp(-40.0 / e)
    t = a * math.sqrt(40.0)                       # tan theta
    return 1.0 / math.sqrt(1.0 + t * t)


def _hemi_theta_quadrature(cos_min, n=160, panels=4):
    """Gauss-Legendre nodes in theta on [0, acos(cos_min)] with weights
    ``2 pi sin(theta) dtheta`` (isotropic integrals over the hemisphere)."""
    tmax = math.acos(min(max(cos_min, 0.0), 1.0))
    x, w = np.polynomial.legendre.leggauss(n)
    edges = np.linspace(0.0, tmax, panels + 1)
    lo, hi = edges[:-1, None], edges[1:, None]
    th = ((lo + hi) / 2 + (hi - lo) / 2 * x).ravel()
    wt = ((hi - lo) / 2 * w + 0 * x).ravel() * 2.0 * math.pi * np.sin(th)
    return th, wt


def _iso_quadrature(model, a):
    """:func:`fit_isotropic_ndf`'s quadrature: the hemisphere, cut where a sharp NDF vanishes."""
    return _hemi_theta_quadrature(_iso_support_cos(model, a) if a < 0.3 else 0.0)


def fit_isotropic_ndf(model, roughness):
    """Least-squares single-SG fit ``G(h; n, lam, mu) ~ D(h)`` of an isotropic NDF
    (eq. 12 generalised): minimises ``int_{h.n>0} (G - D)^2 dh``.

    For a trial ``lam`` the optimal ``mu = <g, D>/<g, g>`` is closed form; ``log lam``
    is found by golden-section search in ``[lam0 e^-5, lam0 e^5]`` around the
    small-angle value ``lam0 = 2/a^2`` (Blinn-Phong: the exponent).  Returns
    ``(lam, mu, rel_error)`` with ``rel_error = ||G - D||_2 / ||D||_2`` over the
    hemisphere.
    """
    if model not in ISOTROPIC_MODELS:
        raise ValueError(f"{model} is not isotropic")
    a = max(float(roughness), SG_ALPHA_MIN)
    th, wt = _iso_quadrature(model, a)
    h = np.stack([np.sin(th), 0 * th, np.cos(th)], axis=1)
    d = ndf_value(model, h, a)
    one_minus_c = 2.0 * np.sin(0.5 * th) ** 2
    dd = float(np.sum(wt * d * d))

    def cost(log_lam):
        g = np.exp(-math.exp(log_lam) * one_minus_c)
        gg = float(np.sum(wt * g * g))
        mu = float(np.sum(wt * g * d)) / gg
        return dd - mu * mu * gg, mu

    lam0 = 2.0 / (a * a) if model != "BLINN_PHONG" else max(2.0 / (a * a) - 2.0, 1e-2)
    lo, hi = math.log(lam0) - 5.0, math.log(lam0) + 5.0
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c1, c2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = cost(c1)[0], cost(c2)[0]
    for _ in range(90):
        if f1 < f2:
            hi, c2, f2 = c2, c1, f1
            c1 = hi - g * (hi - lo)
            f1 = cost(c1)[0]
        else:
            lo, c1, f1 = c1, c2, f2
            c2 = lo + g * (hi - lo)
            f2 = cost(c2)[0]
    ll = 0.5 * (lo + hi)
    mu = cost(ll)[1]
    return math.exp(ll), mu, coaxial_ndf_error(model, a, [math.exp(ll)], [mu], "ISOTROPIC")


#: roughness nodes of the correction tables (uniform, linear interpolation).
ISO_TABLE_ALPHA = np.linspace(0.0, 1.0, 21)


def iso_table_fit(model):
    """``(c_lam, c_mu)`` on :data:`ISO_TABLE_ALPHA` from :func:`fit_isotropic_ndf`
    (``lam = c_lam 2/a^2``, ``mu = c_mu/(pi a^2)``; node 0 is the a -> 0 limit,
    fitted at ``a = SG_ALPHA_MIN``).  This is how :data:`ISO_NDF_TABLE` was made."""
    cl, cm = [], []
    for a in ISO_TABLE_ALPHA:
        a = max(float(a), SG_ALPHA_MIN)
        lam, mu, _ = fit_isotropic_ndf(model, a)
        cl.append(lam * a * a / 2.0)
        cm.append(mu * math.pi * a * a)
    return np.array(cl), np.array(cm)


def graded_theta_quadrature(a, per_panel=24):
    """Gauss-Legendre in theta on [0, pi/2], panels growing geometrically from ``a / 4``
    (a heavy-tailed NDF: its peak and its tails both resolved); weights ``2 pi sin dtheta``."""
    edges = np.concatenate([[0.0], np.geomspace(max(a, SG_ALPHA_MIN) / 4.0, 0.5 * math.pi, 28)])
    x, w = np.polynomial.legendre.leggauss(per_panel)
    lo, hi = edges[:-1, None], edges[1:, None]
    th = ((lo + hi) / 2 + (hi - lo) / 2 * x).ravel()
    wt = ((hi - lo) / 2 * w + 0 * x).ravel() * 2.0 * math.pi * np.sin(th)
    return th, wt


def coaxial_ndf_error(model, roughness, lam, mu, fit="COAXIAL"):
    """Relative L2 error ``||sum_k G(h; n, lam_k, mu_k) - D||_2 / ||D||_2`` over the hemisphere
    of ``h`` of coaxial lobes ``lam``, ``mu`` (K,) against the NDF ``model`` at ``roughness``,
    on the quadrature of the fit named by ``fit``: ``"COAXIAL"`` (:func:`fit_coaxial_ndf`,
    graded panels) or ``"ISOTROPIC"`` (:func:`fit_isotropic_ndf`).  The error the fits
    report, and how any other lobes (e.g. a table's) compare with them."""
    a = max(float(roughness), SG_ALPHA_MIN)
    th, wt = graded_theta_quadrature(a) if fit == "COAXIAL" else _iso_quadrature(model, a)
    d = ndf_value(model, np.stack([np.sin(th), 0 * th, np.cos(th)], axis=1), a)
    lam, mu = np.asarray(lam, dtype=np.float64), np.asarray(mu, dtype=np.float64)
    g = np.exp(-(2.0 * np.sin(0.5 * th) ** 2)[:, None] * lam[None, :]) @ mu
    return math.sqrt(float(np.sum(wt * (g - d) ** 2)) / float(np.sum(wt * d * d)))


def fit_coaxial_ndf(model, roughness, lobes):
    """Least-squares fit of ``lobes`` SGs on the normal, ``sum_k G(h; n, lam_k, mu_k) ~ D(h)``
    (eq. 12 with several lobes, as §4.2 fits anisotropic NDFs): minimises
    ``int_{h.n>0} (sum G - D)^2 dh`` by Levenberg-Marquardt on ``log lam_k`` with the
    amplitudes solved by linear least squares.  For GGX, whose tails one lobe cannot
    follow (from ``a ~ 0.8`` the second lobe is the constant ``lam -> 0``).
    Returns ``(lam (K,), mu (K,), rel_error)``, sharpest lobe first."""
    a = max(float(roughness), SG_ALPHA_MIN)
    th, wt = graded_theta_quadrature(a)
    h = np.stack([np.sin(th), 0 * th, np.cos(th)], axis=1)
    d = ndf_value(model, h, a)
    omc = 2.0 * np.sin(0.5 * th) ** 2
    sw = np.sqrt(wt)

    def solve(x):
        B = np.exp(-np.exp(x)[None, :] * omc[:, None]) * sw[:, None]
        coef, *_ = np.linalg.lstsq(B, d * sw, rcond=None)
        return coef, B @ coef - d * sw

    x0 = math.log(2.0 / (a * a)) + np.linspace(0.5, -2.5, lobes) if lobes > 1 else \
        np.array([math.log(2.0 / (a * a))])
    x, _ = levenberg_marquardt(lambda v: solve(v)[1], x0, 100,
                               fd_step=lambda v: 1e-6 * max(1.0, abs(v)), tries=12,
                               min_gain=1e-12)
    coef = solve(x)[0]
    order = np.argsort(-x)
    lam, mu = np.exp(x)[order], np.maximum(coef[order], 0.0)
    return lam, mu, coaxial_ndf_error(model, a, lam, mu)


def ggx_table_fit(lobes=GGX_LOBES):
    """``(c_lam (21, K), c_mu (21, K))`` of the GGX lobes on :data:`ISO_TABLE_ALPHA`
    (``lam_k = c_lam_k 2/a^2``, ``mu_k = c_mu_k/(pi a^2)``), each node's fit started from
    the previous one's so the lobes vary smoothly.  How :data:`GGX_NDF_TABLE` was made."""
    cl, cm = [], []
    for a in ISO_TABLE_ALPHA:
        a = max(float(a), SG_ALPHA_MIN)
        lam, mu, _ = fit_coaxial_ndf("GGX", a, lobes)
        cl.append(lam * a * a / 2.0)
        cm.append(mu * math.pi * a * a)
    return np.array(cl), np.array(cm)

# Generated by iso_table_fit(model) (rounded to 7 digits); tests refit and compare the errors.
# shaders/lib/constants.glsl is generated from them (tools/glsl_constants.py).
ISO_NDF_TABLE = {
    "COOK_TORRANCE": (
        np.array([0.9999875, 0.998759, 0.9951434, 0.9894735, 0.9822715, 0.9742365, 0.9661932, 0.9590131, 0.9535198, 0.9504024, 0.9501555, 0.9530325, 0.9589624, 0.9674702, 0.9777121, 0.9886328, 0.9991382, 1.008208, 1.014945, 1.018575, 1.018442]),
        np.array([1.000009, 1.000942, 1.003824, 1.00881, 1.016176, 1.0263, 1.039642, 1.056713, 1.078028, 1.104056, 1.135187, 1.171698, 1.213695, 1.261066, 1.313499, 1.370577, 1.431874, 1.497024, 1.56574, 1.637814, 1.713104])),
    "BLINN_PHONG": (
        np.array([0.9999875, 0.9987504, 0.9950063, 0.9887823, 0.9801036, 0.9690081, 0.9555488, 0.9397978, 0.9218516, 0.9018378, 0.8799089, 0.8561223, 0.830001, 0.7998931, 0.7626473, 0.7136991, 0.6471314, 0.5553527, 0.4281937, 0.250977, 3.368977e-05]),
        np.array([1.000003, 1.000313, 1.001261, 1.002869, 1.005181, 1.008263, 1.012208, 1.01714, 1.023227, 1.030694, 1.039831, 1.050948, 1.064152, 1.078992, 1.094267, 1.108047, 1.117649, 1.119314, 1.107412, 1.072862, 1.000034])),
    "WARD": (
        np.array([1.000038, 1.003747, 1.014944, 1.033472, 1.059136, 1.091688, 1.130836, 1.176271, 1.227673, 1.284734, 1.347164, 1.414696, 1.487091, 1.564131, 1.645614, 1.731344, 1.821123, 1.914752, 2.012031, 2.11276, 2.216747]),
        np.array([1.000009, 1.000934, 1.003699, 1.008185, 1.014223, 1.0216, 1.03008, 1.039424, 1.049401, 1.059803, 1.070449, 1.081186, 1.091891, 1.102468, 1.112836, 1.122934, 1.132709, 1.142121, 1.151137, 1.159735, 1.167898])),
}

# Generated by ggx_table_fit() (7 digits, below 1e-6 written 0); tests refit and compare the errors.
GGX_NDF_TABLE = (
    np.array([[1.992838, 0.3828076], [1.98416, 0.3794611], [1.957449, 0.3691366], [1.911287, 0.3512051], [1.84205, 0.3240784], [1.740421, 0.2836717], [1.611464, 0.2315964], [1.535449, 0.2018369], [1.501452, 0.1891955], [1.478714, 0.1796236], [1.456021, 0.1679977], [1.427885, 0.1521422], [1.390106, 0.130881], [1.338649, 0.1035195], [1.269413, 0.06974741], [1.178129, 0.02971582], [1.099019, 0], [1.08185, 0], [1.055609, 0], [1.019339, 0], [1.541843, 0]]),
    np.array([[0.7645672, 0.2045907], [0.7653469, 0.2035765], [0.7678104, 0.2003622], [0.7723066, 0.1944554], [0.7796551, 0.1846765], [0.7918028, 0.1680978], [0.8071456, 0.1459605], [0.8093663, 0.1417465], [0.8011657, 0.1528181], [0.7880022, 0.1708359], [0.7715373, 0.1929814], [0.7523974, 0.2180762], [0.7309676, 0.2453626], [0.7076121, 0.2741905], [0.6827244, 0.3039604], [0.6567133, 0.3341347], [0.6114557, 0.3842979], [0.5127084, 0.4888012], [0.3841785, 0.6200544], [0.217368, 0.7863972], [0, 1]]))


def _table_lookup(table, a):
    x = np.clip(np.asarray(a, dtype=np.float64), 0.0, 1.0) * (len(table) - 1)
    i = np.minimum(x.astype(np.int64), len(table) - 2)
    t = x - i
    return (1.0 - t) * table[i] + t * table[i + 1]


def iso_ndf_lobes(model, roughness):
    """Coaxial SG lobes of an isotropic NDF from its table: ``(lam, mu)`` of shape
    ``roughness.shape + (K,)`` (K = 1, or :data:`GGX_LOBES` for GGX)."""
    if model != "GGX":
        lam, mu = iso_ndf_sg(model, roughness)
        return lam[..., None], mu[..., None]
    a = np.maximum(np.asarray(roughness, dtype=np.float64), SG_ALPHA_MIN)[..., None]
    c_lam, c_mu = GGX_NDF_TABLE
    x = np.clip(a, 0.0, 1.0) * (len(c_lam) - 1)
    i = np.minimum(x.astype(np.int64), len(c_lam) - 2)
    t = x - i
    k = np.arange(c_lam.shape[1])
    lam = ((1.0 - t) * c_lam[i, k] + t * c_lam[i + 1, k]) * 2.0 / (a * a)
    mu = ((1.0 - t) * c_mu[i, k] + t * c_mu[i + 1, k]) / (math.pi * a * a)
    return np.maximum(lam, LAMBDA_MIN), mu


def iso_ndf_sg(model, roughness):
    """Single-lobe SG of an isotropic NDF from the correction table:
    ``(lam, mu)`` arrays of the shape of ``roughness`` (floored at SG_ALPHA_MIN).
    GGX has several lobes: :func:`iso_ndf_lobes`."""
    if model == "GGX":
        raise ValueError("GGX is fitted by several lobes: use iso_ndf_lobes")
    a = np.maximum(np.asarray(roughness, dtype=np.float64), SG_ALPHA_MIN)
    c_lam, c_mu = ISO_NDF_TABLE[model]
    lam = _table_lookup(c_lam, a) * 2.0 / (a * a)
    mu = _table_lookup(c_mu, a) / (math.pi * a * a)
    return np.maximum(lam, LAMBDA_MIN), mu


# --------------------------------------------------------------------------- anisotropic fit

class NDFLobes(NamedTuple):
    """SG mixture of an NDF in the local frame (t, b, n): ``D(h) ~ sum_k
    G(h; axes[k], lam[k], mu[k])``; ``rel_error = ||D* - D||_2/||D||_2`` over
    the hemisphere of ``h``."""

    axes: np.ndarray       # (K, 3)
    lam: np.ndarray        # (K,)
    mu: np.ndarray         # (K,)
    rel_error: float


def _aniso_widths(model, p, q):
    """Angular widths (std-like, radians) along t and b."""
    if model == "WARD_ANISO":
        return p / math.sqrt(2.0), q / math.sqrt(2.0)
    return 1.0 / math.sqrt(max(p, 1e-6)), 1.0 / math.sqrt(max(q, 1e-6))


def _aniso_grid(model, p, q, wide_x, nt=72, nphi=48):
    """Quadrature over one quadrant of the hemisphere (the NDF and the fitted
    mixtures are mirror symmetric in t and b) -- returns (h (Q,3), w (Q,))."""
    wx, wy = _aniso_widths(model, p, q)
    tmax = min(0.5 * math.pi, 7.0 * max(wx, wy))
    x, w = np.polynomial.legendre.leggauss(nt // 2)
    edges = np.array([0.0, 0.3 * tmax, tmax])
    lo, hi = edges[:-1, None], edges[1:, None]
    th = ((lo + hi) / 2 + (hi - lo) / 2 * x).ravel()
    wt = ((hi - lo) / 2 * w + 0 * x).ravel() * np.sin(th)
    xp, wp = np.polynomial.legendre.leggauss(nphi)
    ph = 0.25 * math.pi * (xp + 1.0)
    wph = 0.25 * math.pi * wp
    T, PH = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], axis=-1).reshape(-1, 3)
    return h, (wt[:, None] * wph[None, :]).reshape(-1) * 4.0


def _aniso_design(params, n_pairs, h, wide_x):
    """Basis functions (Q, K) of the symmetric lobe layout for nonlinear params
    ``[log lam0, (t_k, log lam_k) * n_pairs]``; also returns axes (K,3), lam (K,)."""
    axes = [np.array([0.0, 0.0, 1.0])]
    lams = [math.exp(params[0])]
    for k in range(n_pairs):
        t, ll = params[1 + 2 * k], params[2 + 2 * k]
        for s in (1.0, -1.0):
            ax = np.array([s * math.sin(t), 0.0, math.cos(t)]) if wide_x else \
                np.array([0.0, s * math.sin(t), math.cos(t)])
            axes.append(ax)
            lams.append(math.exp(ll))
    axes = np.array(axes)
    lams = np.array(lams)
    G = np.exp(-0.5 * lams[None, :] * np.sum((h[:, None, :] - axes[None, :, :]) ** 2, axis=-1))
    # pair columns share one amplitude: sum the two mirrored lobes
    cols = [G[:, 0]] + [G[:, 1 + 2 * k] + G[:, 2 + 2 * k] for k in range(n_pairs)]
    return np.stack(cols, axis=1), axes, lams


def _project(B, d, w):
    sw = np.sqrt(w)
    A = B * sw[:, None]
    coef, *_ = np.linalg.lstsq(A, d * sw, rcond=None)
    coef = np.maximum(coef, 0.0)
    r = (B @ coef - d) * sw
    return coef, r


def fit_anisotropic_ndf(model, p, q, n_pairs=None, iterations=60):
    """SG mixture of an anisotropic NDF (§4.2: several isotropic lobes with
    variable axes), ``1 + 2 n_pairs`` lobes mirror-symmetric along the wide
    axis, minimising ``int (D* - D)^2 dh`` by Levenberg-Marquardt on the lobe
    angles and log-sharpnesses with the amplitudes solved by linear least
    squares at each step (variable projection; amplitudes clipped at 0).

    ``n_pairs=None`` picks the smallest count in 0..3 whose relative L2 error
    is below 5 % (else 3).  Returns :class:`NDFLobes` in the local frame.
    """
    if model not in ("WARD_ANISO", "ASHIKHMIN_SHIRLEY"):
        raise ValueError(f"{model} is not anisotropic")
    p, q = float(p), float(q)
    wx, wy = _aniso_widths(model, p, q)
    wide_x = wx >= wy
    wide, narrow = max(wx, wy), min(wx, wy)
    h, w = _aniso_grid(model, p, q, wide_x)
    d = ndf_value(model, h, aniso=(p, q))
    dn = math.sqrt(float(np.sum(w * d * d)))
    counts = range(4) if n_pairs is None else [int(n_pairs)]
    best = None
    for npairs in counts:
        # initial layout: lobes with the narrow width, spread along the wide axis
        lam_n = 1.0 / (narrow * narrow)
        x0 = [math.log(lam_n)]
        span = 1.6 * wide
        for k in range(npairs):
            x0 += [span * (k + 1) / (npairs + 0.5), math.log(lam_n)]
        x = np.array(x0, dtype=np.float64)

        def resid(xx):
            B, _, _ = _aniso_design(xx, npairs, h, wide_x)
            _, r = _project(B, d, w)
            return r

        x, _ = levenberg_marquardt(resid, x, iterations,
                                   fd_step=lambda v: 1e-6 * max(1.0, abs(v)), tries=12,
                                   min_gain=1e-9)
        B, axes, lams = _aniso_design(x, npairs, h, wide_x)
        coef, r = _project(B, d, w)
        err = math.sqrt(float(r @ r)) / dn
        mus = np.concatenate([[coef[0]], np.repeat(coef[1:], 2)])
        keep = mus > 0
        if not np.any(keep):
            keep[0] = True
        fit = NDFLobes(axes[keep], lams[keep], mus[keep], err)
        if best is None or err < best.rel_error - 1e-3:
            best = fit
        if n_pairs is None and err < 0.05:
            break
    return best


@memo(64)
def _aniso_cached(model, p, q):
    return fit_anisotropic_ndf(model, p, q)


def _round_sig(x, digits=4):
    x = float(x)
    return float(f"{x:.{digits}g}")


def ndf_lobes(material) -> NDFLobes:
    """SG fit of the material's NDF (Fig. 2) in the local frame (t, b, n).

    Isotropic models: one lobe on ``n`` from the correction table
    (:func:`iso_ndf_sg`; scalar ``roughness`` -- use :func:`specular_lobes` for
    textured values); ``rel_error`` is measured against the analytic NDF.
    Anisotropic models: :func:`fit_anisotropic_ndf`, fitted once per parameter
    set (cached on the parameters rounded to 4 significant digits).
    Returns :class:`NDFLobes` ``(axes (K,3), lam (K,), mu (K,), rel_error)``.
    """
    if material.is_anisotropic:
        p, q = material.aniso_params()
        return _aniso_cached(material.model, _round_sig(p), _round_sig(q))
    a = np.asarray(material.roughness, dtype=np.float64)
    if a.size != 1:
        raise ValueError("ndf_lobes needs a scalar roughness (textured values: specular_lobes)")
    a = float(a.reshape(-1)[0])
    return _iso_cached(material.model, _round_sig(a, 6))


@memo(256)
def _iso_cached(model, a):
    lam, mu = iso_ndf_lobes(model, a)
    err = coaxial_ndf_error(model, a, lam, mu, "COAXIAL" if model == "GGX" else "ISOTROPIC")
    return NDFLobes(np.tile([0.0, 0.0, 1.0], (len(lam), 1)), lam, mu, err)
