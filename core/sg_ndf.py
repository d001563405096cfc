# SPDX-License-Identifier: GPL-3.0-or-later
"""The NDFs of :mod:`.sg_brdf` as spherical-Gaussian lobes (Wang et al. 2009, §4.1-4.3):
the analytic NDFs, their least-squares SG fits (isotropic eq. 12, coaxial GGX lobes,
anisotropic pairs), the fitted tables and the fitted warp of the GGX lobes' view slice."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .cache import memo
from .directions import orthonormal_frame
from .fitting import levenberg_marquardt
from .microfacet import _lambda_raw

MODELS = ("COOK_TORRANCE", "BLINN_PHONG", "WARD", "WARD_ANISO", "ASHIKHMIN_SHIRLEY", "GGX")
ISOTROPIC_MODELS = MODELS[:3] + ("GGX",)
#: coaxial SG lobes of the GGX NDF fit (one lobe loses its long tails: 14-20 % L2 error)
GGX_LOBES = 2
FRESNEL_MODES = ("NONE", "SCHLICK", "DIELECTRIC", "PRINCIPLED")
#: integer codes used by the GLSL twin (``shaders/sg_common.glsl``).
MODEL_INDEX = {m: i for i, m in enumerate(MODELS)}
FRESNEL_INDEX = {m: i for i, m in enumerate(FRESNEL_MODES)}
#: most lobes :func:`specular_lobes` returns per point.
MAX_LOBES = 8
#: smallest slope parameter (NDF lobe sharpness 2/a^2 = 8e4).
ALPHA_MIN = 0.005
#: cosines inside ``M_o`` are floored here (view and light at the horizon).
COS_MIN = 1e-4
#: Ward / Ashikhmin-Shirley ``M`` diverges like 1/sqrt(cos) at the horizon; its
#: cosines are floored at this larger value (the integrand ``M cos`` still -> 0).
COS_MIN_SINGULAR = 0.05
#: warped lobes are capped at this sharpness (grazing facets, tau -> 0).
LAMBDA_MAX = 1e5



def _per_point(v, P, shape=()):
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
            a = np.maximum(np.asarray(roughness, dtype=np.float64), ALPHA_MIN)
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
    a = max(float(a), ALPHA_MIN)
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
    a = max(float(roughness), ALPHA_MIN)
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
    fitted at ``a = ALPHA_MIN``).  This is how :data:`ISO_NDF_TABLE` was made."""
    cl, cm = [], []
    for a in ISO_TABLE_ALPHA:
        a = max(float(a), ALPHA_MIN)
        lam, mu, _ = fit_isotropic_ndf(model, a)
        cl.append(lam * a * a / 2.0)
        cm.append(mu * math.pi * a * a)
    return np.array(cl), np.array(cm)



def _graded_theta_quadrature(a, per_panel=24):
    """Gauss-Legendre in theta on [0, pi/2], panels growing geometrically from ``a / 4``
    (a heavy-tailed NDF: its peak and its tails both resolved); weights ``2 pi sin dtheta``."""
    edges = np.concatenate([[0.0], np.geomspace(max(a, ALPHA_MIN) / 4.0, 0.5 * math.pi, 28)])
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
    a = max(float(roughness), ALPHA_MIN)
    th, wt = _graded_theta_quadrature(a) if fit == "COAXIAL" else _iso_quadrature(model, a)
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
    a = max(float(roughness), ALPHA_MIN)
    th, wt = _graded_theta_quadrature(a)
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
        a = max(float(a), ALPHA_MIN)
        lam, mu, _ = fit_coaxial_ndf("GGX", a, lobes)
        cl.append(lam * a * a / 2.0)
        cm.append(mu * math.pi * a * a)
    return np.array(cl), np.array(cm)

# Generated by iso_table_fit(model) (rounded to 7 digits); tests refit and compare the errors.
# Also written, with the same digits, in shaders/sg_common.glsl.
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
# Also in shaders/sg_common.glsl.
GGX_NDF_TABLE = (
    np.array([[1.992838, 0.3828076], [1.98416, 0.3794611], [1.957449, 0.3691366], [1.911287, 0.3512051], [1.84205, 0.3240784], [1.740421, 0.2836717], [1.611464, 0.2315964], [1.535449, 0.2018369], [1.501452, 0.1891955], [1.478714, 0.1796236], [1.456021, 0.1679977], [1.427885, 0.1521422], [1.390106, 0.130881], [1.338649, 0.1035195], [1.269413, 0.06974741], [1.178129, 0.02971582], [1.099019, 0], [1.08185, 0], [1.055609, 0], [1.019339, 0], [1.541843, 0]]),
    np.array([[0.7645672, 0.2045907], [0.7653469, 0.2035765], [0.7678104, 0.2003622], [0.7723066, 0.1944554], [0.7796551, 0.1846765], [0.7918028, 0.1680978], [0.8071456, 0.1459605], [0.8093663, 0.1417465], [0.8011657, 0.1528181], [0.7880022, 0.1708359], [0.7715373, 0.1929814], [0.7523974, 0.2180762], [0.7309676, 0.2453626], [0.7076121, 0.2741905], [0.6827244, 0.3039604], [0.6567133, 0.3341347], [0.6114557, 0.3842979], [0.5127084, 0.4888012], [0.3841785, 0.6200544], [0.217368, 0.7863972], [0, 1]]))

#: view-cosine nodes of :data:`GGX_WARP_TABLE` (node 0 is fitted at ``n.o = WARP_MU_MIN``).
WARP_MU = np.linspace(0.0, 1.0, 21)
WARP_MU_MIN = 0.02
#: Blender-roughness nodes of :data:`GGX_WARP_TABLE`.
WARP_R = np.linspace(0.0, 1.0, 21)
#: warped lobes of the GGX view slice: a row of round lobes along the plane of incidence
#: makes its elongated shape (two: the r 0.5 rim 30-40 % dark; docs/measurements.md)
GGX_WARP_LOBES = 4
#: weight of the slice's moments in the fit (energy, centroid, second moments; relative to
#: the slice's L2 norm): under smooth light the centroid matters more than the L2 shape
WARP_MOMENT_WEIGHT = 5.0
#: weight of the pull toward the node a fit continues (relative to the slice's norm): pins
#: a lobe where it does not matter, so the table stays continuous.
WARP_RIDGE = 1e-3
#: (tilt, log-sharpness) tried for a lobe the fit left without amplitude (its gradient is 0)
_WARP_SEEDS = tuple((d, l) for d in (-0.9, -0.6, -0.3, 0.0, 0.3) for l in (-1.0, 0.0, 1.0, 2.0))


def _warp_quadrature(a, mu_o, per_panel=8, nphi=48):
    """Light directions ``i`` (N, 3) and their solid angles for the slice at view
    ``o = (sqrt(1 - mu_o^2), 0, mu_o)`` (normal +z): a graded quadrature of the half vector
    (:func:`_graded_theta_quadrature`, half the azimuths: the slice is symmetric about the
    plane of incidence, weights doubled) mapped by ``i = 2 (o.h) h - o``,
    ``d i = 4 (o.h) d h``; directions below the horizon dropped."""
    th, wt = _graded_theta_quadrature(a, per_panel)
    ph = (np.arange(nphi) + 0.5) * (math.pi / nphi)
    T, PH = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], -1).reshape(-1, 3)
    wh = (wt[:, None] / (2.0 * nphi) * 2.0 + 0.0 * PH).reshape(-1)
    o = np.array([math.sqrt(max(1.0 - mu_o * mu_o, 0.0)), 0.0, mu_o])
    oh = h @ o
    i = 2.0 * oh[:, None] * h - o
    keep = (oh > 0.0) & (i[:, 2] > 0.0)
    return o, h[keep], i[keep], (wh * 4.0 * oh)[keep]


def _warp_sharpness(a, mu_o):
    """The plain warp's sharpness (eq. 18-21) of the NDF's nominal lobe ``2 / a^2``."""
    return np.minimum(2.0 / (a * a) / (4.0 * np.maximum(mu_o, WARP_MU_MIN)), LAMBDA_MAX)


class _Slice(NamedTuple):
    """Cycles' single-scattering GGX slice times the cosine on :func:`_warp_quadrature`'s
    points (``t``, times the square-root weights ``sw``) and its moments (``mom @ t``)."""

    a: float
    mu_o: float
    i: np.ndarray
    sw: np.ndarray
    t: np.ndarray
    tn: float
    mom: np.ndarray
    scale: float            # of the moment rows: WARP_MOMENT_WEIGHT |t| / |mom t|


def _ggx_slice(r, mu_o):
    a = max(float(r) ** 2, ALPHA_MIN)
    mu_o = max(float(mu_o), WARP_MU_MIN)
    _, h, i, wi = _warp_quadrature(a, mu_o)
    a2 = a * a
    g2 = 1.0 / (1.0 + _lambda_raw("GGX", a2, np.maximum(i[:, 2], COS_MIN))
                + _lambda_raw("GGX", a2, mu_o))
    sw = np.sqrt(wi)
    t = ndf_value("GGX", h, a) * g2 / (4.0 * mu_o) * sw
    # moments: energy, centroid (i_y's is 0: the slice is symmetric about the plane of
    # incidence), second moments
    mom = np.stack([np.ones_like(sw), i[:, 0], i[:, 2], i[:, 0] ** 2, i[:, 1] ** 2,
                    i[:, 0] * i[:, 2]]) * sw
    tn = float(np.linalg.norm(t))
    return _Slice(a, mu_o, i, sw, t, tn, mom,
                  WARP_MOMENT_WEIGHT * tn / max(float(np.linalg.norm(mom @ t)), 1e-300))


def _slice_lobes(S, x):
    """The lobes ``x = (d_1..d_K, l_1..l_K)`` times the cosine on ``S``'s points (N, K)."""
    K = len(x) // 2
    el = np.clip(math.acos(S.mu_o) + x[:K], -0.5 * math.pi, 0.5 * math.pi)  # above the horizon
    ax = np.stack([-np.sin(el), np.zeros(K), np.cos(el)], 1)
    lam = np.minimum(_warp_sharpness(S.a, S.mu_o) * np.exp(np.minimum(x[K:], 30.0)), LAMBDA_MAX)
    return np.exp(lam * (S.i @ ax.T - 1.0)) * (S.i[:, 2] * S.sw)[:, None]


def _slice_misfit(S, g):
    """Relative misfit of ``g`` (the lobes' sum times the cosine on ``S``'s points): its
    difference from the slice and that of its moments."""
    return np.concatenate([g - S.t, S.scale * (S.mom @ (g - S.t))]) / S.tn


def fit_ggx_warp(r, mu_o, x0=None, lobes=GGX_WARP_LOBES, neighbours=(), iterations=80):
    """Least-squares fit of the GGX view slice of Blender roughness ``r`` at view cosine
    ``mu_o`` by ``lobes`` isotropic SG lobes (Wang et al. 2009 fit anisotropic NDFs by
    several isotropic lobes, §4.2): lobe ``k``'s axis is the mirror direction tilted by
    ``d_k`` (radians, in the plane of incidence, away from the normal for ``d_k > 0``, kept
    above the horizon), its sharpness the plain warp's ``2 / (4 a^2 n.o)`` (eq. 18-21)
    times ``exp(l_k)``, its amplitude free and non-negative.  Minimises
    ``int_{n.i>0} (sum_k G_k(i) (n.i) - D(h) G2(i, o) / (4 n.o))^2 di`` against Cycles'
    single-scattering GGX slice times the cosine (Fresnel 1) plus the squared misfit of
    its moments (energy, centroid, second moments; weight :data:`WARP_MOMENT_WEIGHT`: under
    smooth light they matter more than the shape), amplitudes by non-negative least
    squares, ``(d_k, l_k)`` by Levenberg-Marquardt from ``x0`` (pulled toward it by
    :data:`WARP_RIDGE`; None: coaxial lobes of :func:`fit_coaxial_ndf`).  ``neighbours``:
    table nodes ``(r, mu_o, params)``; the mean of these lobes and each neighbour's, scaled
    to the slice's energy, is fitted alike to the slice half-way (so the table's bilinear
    interpolation is a fit too).  A lobe left without amplitude is re-seeded
    (:data:`_WARP_SEEDS`) where that helps.  The isotropic warp of §4.3 cannot follow the
    slice at oblique views (Wang et al. 2009 say so): it is broad in the plane of incidence
    and narrow across it, its peak off the mirror direction and cut by the horizon.
    Returns ``(params (3 K,) = (d_1..d_K, l_1..l_K, f_1..f_K), rel_error, rel_error of the
    plain warp of the two NDF lobes scaled to the slice's energy)`` with ``f_k`` the lobes'
    shares of the amplitude (the slice is scaled to Cycles' ``E`` where it is used,
    :func:`_ggx_normalisation`)."""
    from .fitting import nonnegative_least_squares
    K = int(lobes)
    S = _ggx_slice(r, mu_o)
    mids = [(_ggx_slice(0.5 * (r + rn), 0.5 * (S.mu_o + max(float(mn), WARP_MU_MIN))),
             np.asarray(qn, dtype=np.float64)) for rn, mn, qn in neighbours]

    def solve(x):
        B = _slice_lobes(S, x)
        amp = nonnegative_least_squares(np.vstack([B, S.scale * (S.mom @ B)]),
                                        np.concatenate([S.t, S.scale * (S.mom @ S.t)]))
        return B, amp

    if x0 is None:
        lam, _, _ = fit_coaxial_ndf("GGX", S.a, K)
        x0 = np.concatenate([np.zeros(K), np.log(np.maximum(lam * S.a * S.a / 2.0, 1e-6))])
    prior = np.array(x0[:2 * K], dtype=np.float64)

    def resid(x):
        B, amp = solve(x)
        out = [_slice_misfit(S, B @ amp)]
        f = amp / max(float(np.sum(amp)), 1e-300)
        for Sm, qn in mids:
            g = _slice_lobes(Sm, 0.5 * (x + qn[:2 * K])) @ (0.5 * (f + qn[2 * K:]))
            e = float(np.sum(g * Sm.sw))
            out.append(_slice_misfit(Sm, g * (float(np.sum(Sm.t * Sm.sw)) / e if e > 0 else 0.0)))
        return np.concatenate(out + [WARP_RIDGE * (x - prior)])

    def descend(x):
        x, res = levenberg_marquardt(resid, x, iterations,
                                     fd_step=lambda v: 1e-6 * max(1.0, abs(v)), min_gain=1e-10)
        return x, float(res @ res)

    x, cost = descend(prior.copy())
    for _ in range(K):                       # a lobe without amplitude has no gradient: re-seed
        amp = solve(x)[1]
        dead = np.flatnonzero(amp <= 1e-9 * max(float(amp.max()), 1e-300))
        if not dead.size:
            break
        trials = []
        for d, l in _WARP_SEEDS:
            y = x.copy()
            y[dead[0]], y[K + dead[0]] = d, l
            res = resid(y)
            trials.append((float(res @ res), tuple(y)))
        y, c = descend(np.array(min(trials)[1]))
        if c >= cost * (1.0 - 1e-6):
            break
        x, cost = y, c
    el0 = math.acos(S.mu_o)
    x[:K] = np.clip(el0 + x[:K], -0.5 * math.pi, 0.5 * math.pi) - el0
    B, amp = solve(x)
    err = float(np.linalg.norm(B @ amp - S.t)) / S.tn
    # the plain warp of the NDF's two lobes, normalised to the slice's energy (E, not fitted)
    lam_d, mu_d = iso_ndf_lobes("GGX", S.a)
    ax0 = np.array([-math.sin(el0), 0.0, math.cos(el0)])
    B0 = np.exp(np.minimum(lam_d / (4.0 * S.mu_o), LAMBDA_MAX) * (S.i @ ax0 - 1.0)[:, None]) @ mu_d
    B0 = B0 * S.i[:, 2] * S.sw
    scale = float(np.sum(B0 * S.sw)) and float(np.sum(S.t * S.sw)) / float(np.sum(B0 * S.sw))
    err0 = float(np.linalg.norm(B0 * scale - S.t)) / S.tn
    return np.concatenate([x, amp / max(float(np.sum(amp)), 1e-300)]), err, err0


def ggx_warp_error(r, mu_o, params):
    """Relative L2 error of the lobes ``params`` (:func:`fit_ggx_warp`'s, e.g. the table's
    at or between nodes), scaled to the slice's energy, against the slice times the cosine."""
    S = _ggx_slice(r, mu_o)
    q = np.asarray(params, dtype=np.float64)
    K = len(q) // 3
    g = _slice_lobes(S, q[:2 * K]) @ np.maximum(q[2 * K:], 0.0)
    e = float(np.sum(g * S.sw))
    g = g * (float(np.sum(S.t * S.sw)) / e if e > 0 else 0.0)
    return float(np.linalg.norm(g - S.t)) / S.tn


#: the column of :data:`GGX_WARP_TABLE` fitted first (r 0.5), the others continued from it
WARP_SEED_COLUMN = 10


def ggx_warp_neighbours(table, ir, j):
    """The fitted nodes ``(r, mu_o, params)`` that the fit of ``table[ir, j]`` continues in
    :func:`ggx_warp_table_fit`: first the neighbour toward :data:`WARP_SEED_COLUMN` in r
    (its start), then the next n.o node up (empty at ``(WARP_SEED_COLUMN, n.o = 1)``)."""
    out = []
    if ir != WARP_SEED_COLUMN:
        k = ir - 1 if ir > WARP_SEED_COLUMN else ir + 1
        out.append((WARP_R[k], WARP_MU[j], table[k, j]))
    if j + 1 < len(WARP_MU):
        out.append((WARP_R[ir], WARP_MU[j + 1], table[ir, j + 1]))
    return out


def ggx_warp_table_fit(lobes=GGX_WARP_LOBES, log=None):
    """``(len(WARP_R), len(WARP_MU), 3 lobes)`` lobes :func:`fit_ggx_warp` at the nodes
    :data:`WARP_R` x :data:`WARP_MU`, each continued from its fitted neighbours
    (:func:`ggx_warp_neighbours`: the r 0.5 column from ``n.o = 1`` down, then column by
    column outward in r), so that neighbouring nodes hold the same lobes and the bilinear
    interpolation between them fits too.  How :data:`GGX_WARP_TABLE` was made (minutes)."""
    out = np.zeros((len(WARP_R), len(WARP_MU), 3 * lobes))
    order = [WARP_SEED_COLUMN] + list(range(WARP_SEED_COLUMN + 1, len(WARP_R))) + \
        list(range(WARP_SEED_COLUMN - 1, -1, -1))
    for ir in order:
        for j in range(len(WARP_MU) - 1, -1, -1):
            nb = ggx_warp_neighbours(out, ir, j)
            out[ir, j], err, _ = fit_ggx_warp(WARP_R[ir], WARP_MU[j], nb[0][2] if nb else None,
                                              lobes, nb)
            if log is not None:
                log(ir, j, err)
    return out


def ggx_warp_params(r, cos_o, table=None):
    """The lobes (..., 3 K) of :data:`GGX_WARP_TABLE` (or ``table``) at Blender roughness
    ``r`` and view cosine ``cos_o`` (bilinear; shapes broadcast)."""
    r, c = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(cos_o, dtype=np.float64))
    if table is None:
        from .sg_warp_table import GGX_WARP_TABLE as table
    x = np.clip(r, 0.0, 1.0) * (len(WARP_R) - 1)
    y = np.clip(c, 0.0, 1.0) * (len(WARP_MU) - 1)
    i = np.minimum(x.astype(np.int64), len(WARP_R) - 2)
    j = np.minimum(y.astype(np.int64), len(WARP_MU) - 2)
    fx, fy = (x - i)[..., None], (y - j)[..., None]
    return ((1 - fx) * ((1 - fy) * table[i, j] + fy * table[i, j + 1])
            + fx * ((1 - fy) * table[i + 1, j] + fy * table[i + 1, j + 1]))


def ggx_warp_correct(roughness, n, o, P, table=None):
    """The fitted GGX view-slice lobes (:func:`fit_ggx_warp` by :func:`ggx_warp_params` at
    the point's roughness and ``n.o``): axes (P, K, 3), the mirror direction tilted in the
    plane of ``n`` and ``o``; sharpness (P, K); shares of the amplitude (P, K) (the slice
    is normalised to Cycles' ``E`` afterwards)."""
    cos_o = np.clip(np.sum(n * o, axis=1), 0.0, 1.0)
    alpha = np.clip(_per_point(roughness, P), 0.0, 1.0)
    q = ggx_warp_params(np.sqrt(alpha), cos_o, table)                 # (P, 3 K)
    K = q.shape[-1] // 3
    u = cos_o[:, None] * n - o                     # the mirror direction's tangential part
    un = np.linalg.norm(u, axis=-1, keepdims=True)
    fallback, _ = orthonormal_frame(n)
    u = np.where(un > 1e-9, u / np.maximum(un, 1e-300), fallback)
    el = np.arccos(cos_o)[:, None] + q[:, :K]
    axes = np.cos(el)[..., None] * n[:, None, :] + np.sin(el)[..., None] * u[:, None, :]
    lam_w = _warp_sharpness(np.maximum(alpha, ALPHA_MIN), cos_o)[:, None]
    lam = np.minimum(lam_w * np.exp(q[:, K:2 * K]), LAMBDA_MAX)
    return axes, lam, np.maximum(q[:, 2 * K:], 0.0)


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
    a = np.maximum(np.asarray(roughness, dtype=np.float64), ALPHA_MIN)[..., None]
    c_lam, c_mu = GGX_NDF_TABLE
    x = np.clip(a, 0.0, 1.0) * (len(c_lam) - 1)
    i = np.minimum(x.astype(np.int64), len(c_lam) - 2)
    t = x - i
    k = np.arange(c_lam.shape[1])
    lam = ((1.0 - t) * c_lam[i, k] + t * c_lam[i + 1, k]) * 2.0 / (a * a)
    mu = ((1.0 - t) * c_mu[i, k] + t * c_mu[i + 1, k]) / (math.pi * a * a)
    return np.maximum(lam, 1e-4), mu


def iso_ndf_sg(model, roughness):
    """Single-lobe SG of an isotropic NDF from the correction table:
    ``(lam, mu)`` arrays of the shape of ``roughness`` (floored at ALPHA_MIN).
    GGX has several lobes: :func:`iso_ndf_lobes`."""
    if model == "GGX":
        raise ValueError("GGX is fitted by several lobes: use iso_ndf_lobes")
    a = np.maximum(np.asarray(roughness, dtype=np.float64), ALPHA_MIN)
    c_lam, c_mu = ISO_NDF_TABLE[model]
    lam = _table_lookup(c_lam, a) * 2.0 / (a * a)
    mu = _table_lookup(c_mu, a) / (math.pi * a * a)
    return np.maximum(lam, 1e-4), mu


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
