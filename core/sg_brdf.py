# SPDX-License-Identifier: GPL-3.0-or-later
r"""Microfacet BRDFs as spherical-Gaussian mixtures (Wang et al. 2009, §4).

Equation numbers are that paper's.  Every SG lobe is
``G(i; axis, lam, mu) = mu * exp(lam * (i . axis - 1))`` (eq. 2, :mod:`.sg`).

The split of eq. 8
------------------
The BRDF is ``rho(o, i) = kd + ks rho_s(o, i)`` (eq. 8).  Here

* ``kd = diffuse_albedo(material) / pi`` (a Lambert term; :func:`diffuse_albedo`
  returns the *albedo*, so the diffuse radiance is ``albedo / pi * R_d`` with the
  ``R_d`` of eq. 37), and
* ``ks rho_s(o, i)`` is returned by :func:`specular_lobes` as an SG mixture in
  the light direction ``i`` for the given view ``o``: ``ks``, the Fresnel factor
  and the shadowing/masking are already inside the lobe amplitudes.  The cosine
  ``max(0, n . i)`` is *not* included (eq. 41 multiplies by the clamped-cosine SG
  of eq. 40).

Microfacet form (eq. 9): ``rho_s(o, i) = M_o(i) D(h)``, ``h = (o + i)/|o + i|``.
The NDF ``D`` is fitted by SGs once per parameter set (:func:`ndf_lobes`,
least squares against the analytic ``D``); the view slice is obtained by the
per-lobe spherical warp of eq. 17-21 (:func:`.sg.spherical_warp`) and ``M_o`` is
evaluated at each warped lobe centre (eq. 22).

Models (``SGMaterial.model``) and their parameters
--------------------------------------------------
With ``c = n . h`` (``theta`` its angle), ``cos_i = n . i``, ``cos_o = n . o``,
``phi`` the azimuth of ``h`` from the tangent ``t`` (``b = n x t``):

``COOK_TORRANCE`` (eq. 10-12; the NDF is the normalised Beckmann distribution,
  i.e. eq. 11's ``exp(-(theta/m)^2)`` with Beckmann's ``tan`` and normalisation,
  which is what Cycles evaluates):
  ``D = exp(-tan^2 theta / a^2) / (pi a^2 c^4)``, ``a = roughness``;
  ``M = F G2 / (4 cos_i cos_o)`` with the height-correlated Smith
  ``G2 = 1/(1 + Lambda(cos_i) + Lambda(cos_o))`` and Cycles' rational Beckmann
  ``Lambda`` (:func:`.brdf.smith_lambda`).  With ``F = 1`` and ``ks`` = colour this
  is Cycles' Glossy BSDF (Beckmann) exactly, up to the SG approximation.
``GGX`` (Cycles' GGX / Multiscatter GGX, Principled): ``D = a^2 / (pi c^4 (a^2 + tan^2 theta)^2)``
  as :data:`GGX_LOBES` coaxial SGs (:data:`GGX_NDF_TABLE`, :func:`fit_coaxial_ndf`), each
  warped like the one lobe of the other models.  ``M`` at the lobes' centre is replaced by
  the factor that gives the slice (Fresnel 1) Cycles' GGX albedo ``E(r, n.o)``
  (:func:`_ggx_normalisation`), the Fresnel is taken at each lobe's product with the
  cosine (:func:`_fresnel_cosine`), and Multiscatter GGX adds Cycles' energy factor per
  layer (:func:`multiscatter_factors`).  (:func:`_m_factor` has GGX's Smith ``Lambda`` for
  :func:`specular_brdf`.)
``BLINN_PHONG``: ``D = (e + 2)/(2 pi) c^e`` with exponent ``e = 2/a^2 - 2``
  (``a = roughness``, the Beckmann-equivalent slope), ``M`` as Cook-Torrance.
``WARD``: ``D = exp(-tan^2 theta / a^2) / (pi a^2)``, ``M = F / (4 sqrt(cos_i cos_o))``
  (Ward 1992).
``WARD_ANISO``: ``D = exp(-tan^2 theta (cos^2 phi / ax^2 + sin^2 phi / ay^2)) / (pi ax ay)``,
  ``ax = alpha_x``, ``ay = alpha_y``, ``M`` as Ward.
``ASHIKHMIN_SHIRLEY``: ``D = sqrt((nu+1)(nv+1))/(2 pi) c^(nu cos^2 phi + nv sin^2 phi)``,
  ``M = F / (4 (h . i) max(cos_i, cos_o))`` (Ashikhmin & Shirley 2000).

``roughness`` is floored at :data:`ALPHA_MIN` (NDF sharpness <= ~8e4, inside the
range where :mod:`.sg` is exact); the Blender slider is the Blender roughness
``r`` with ``a = r^2`` (:func:`sg_material_from_brdf`).

Fresnel (eq. 14 and Cycles' variants) -- ``F(c)`` with ``c = |i . h| = o . h``
taken at the lobe centre, always written as ``F = A + B_d F_eq14(c, eta) + B_s (1 - c)^5``
(:func:`fresnel_coefficients`; ``A, B_d, B_s`` RGB, ``ks`` folded in):

* ``"NONE"``: ``F = ks`` (Cycles Glossy BSDF: the colour is the reflectance);
* ``"SCHLICK"``: ``F = ks + (1 - ks)(1 - c)^5`` (``ks`` = F0);
* ``"DIELECTRIC"``: ``F = ks F_eq14(c, eta)``, eq. 14 with ``eta = ior``;
* ``"PRINCIPLED"``: Cycles' Principled v2 layering, linear in ``F_eq14``:
  ``(1 - m)(ks + (1 - ks)(F_eq14 - F0(eta))/(1 - F0(eta))) + m (base + (1 - base)(1 - c)^5)``
  with ``m = metallic``, ``base = diffuse`` (the metal F0) and ``ks`` the
  dielectric ``f0`` colour.

Isotropic NDFs are one SG lobe around ``n`` whose sharpness/amplitude are
``lam = c_lam(a) 2/a^2`` and ``mu = c_mu(a)/(pi a^2)``; the corrections
``c_lam, c_mu`` are tabulated on ``a = 0, 0.05, ..., 1`` (:data:`ISO_NDF_TABLE`,
linear interpolation; the same constants are in ``shaders/sg_common.glsl``) and
come from :func:`fit_isotropic_ndf` (a 1-D least-squares fit of the L2 error
over the hemisphere of ``h``; the amplitude is solved in closed form for each
trial sharpness, the sharpness by golden section on ``log lam``).

Anisotropic NDFs (``WARD_ANISO``, ``ASHIKHMIN_SHIRLEY``) follow §4.2: several
*isotropic* lobes with variable axes (in the local frame ``t, b, n``), fitted
by a non-linear least-squares solve per parameter set (:func:`fit_anisotropic_ndf`,
Levenberg-Marquardt with the amplitudes projected out; lobes placed
symmetrically along the wide axis: one on ``n`` and up to 3 mirrored pairs, so
K <= 7, the 7 lobes of Fig. 2 for ``nu = 75, nv = 1200``).  Each lobe is warped
separately (§4.3) into an isotropic lobe of the view slice.

What is approximated, and where it hurts: the isotropic warp at oblique views
(§4.3 says so; for GGX ``specular_lobes(fitted_warp=True)`` corrects each warped lobe's
tilt, sharpness and share by a least-squares table over (r, n.o), :func:`fit_ggx_warp`), ``M`` constant over each lobe (eq. 22), a rough GGX slice's shape (its
energy is Cycles' by construction) and the F82 tint of Cycles' metal lobe (Schlick here).
GGX lobes drawn as the Beckmann lobe of the same alpha without the multiscatter factor
(before 2026-12-02, ``sg_material_from_brdf(ggx=False)``) were 14-20 % off on a rough
metal: docs/measurements.md "SG lobes of a rough metal".  Measured errors:
``tests/test_sg_brdf.py``, docs/measurements.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import brdf as core_brdf
from . import sg
from .cache import memo
from .directions import orthonormal_frame
from .fitting import levenberg_marquardt
from .brdf_tables import ggx_E, ggx_E_avg
from .microfacet import _lambda_raw, F0_from_ior, fresnel_dielectric_Fss

__all__ = [
    "MODELS", "ISOTROPIC_MODELS", "FRESNEL_MODES", "MAX_LOBES", "ALPHA_MIN",
    "SGMaterial", "NDFLobes", "ndf_value", "ndf_lobes", "fit_isotropic_ndf",
    "fit_anisotropic_ndf", "iso_ndf_sg", "specular_lobes", "specular_brdf",
    "fresnel_coefficients", "fresnel_eq14", "diffuse_albedo", "diffuse_view_weight",
    "sg_material_from_brdf", "ISO_TABLE_ALPHA", "ISO_NDF_TABLE", "iso_table_fit",
    "MODEL_INDEX", "FRESNEL_INDEX",
]

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


# --------------------------------------------------------------------------- material

def _rgb_array(v, name):
    a = np.asarray(v, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"{name} must have 3 components in its last axis, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN/Inf values")
    return a


def _positive_array(v, name, floor):
    a = np.asarray(v, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN/Inf values")
    return np.maximum(a, floor)


@dataclass
class SGMaterial:
    """Parameters of one SG-represented BRDF (eq. 8 with a microfacet ``rho_s``, eq. 9).

    Per-point (textured) values may be arrays broadcastable to ``(P,)`` for
    scalars and ``(P, 3)`` for colours.

    model:      one of :data:`MODELS`.
    diffuse:    Lambert albedo (``kd = diffuse / pi``); for ``fresnel="PRINCIPLED"``
                the Principled base colour (also the metal F0).
    specular:   ``ks`` (colour of the specular lobe; F0 for ``"SCHLICK"``, the
                dielectric ``f0`` colour for ``"PRINCIPLED"``).
    roughness:  slope ``a`` of the isotropic models (module docstring).
    alpha_x, alpha_y:  ``WARD_ANISO`` slopes along the tangent / bitangent.
    nu, nv:     ``ASHIKHMIN_SHIRLEY`` exponents along the tangent / bitangent.
    fresnel:    one of :data:`FRESNEL_MODES`.
    ior:        relative index of refraction ``eta`` of eq. 14.
    metallic:   ``"PRINCIPLED"`` metal weight.
    multiscatter: scale the lobes by Cycles' multiple-scattering energy compensation
                (Multiscatter GGX): :func:`multiscatter_factors`.
    """

    model: str = "COOK_TORRANCE"
    diffuse: object = (0.8, 0.8, 0.8)
    specular: object = (0.04, 0.04, 0.04)
    roughness: object = 0.3
    alpha_x: float = 0.3
    alpha_y: float = 0.1
    nu: float = 75.0
    nv: float = 1200.0
    fresnel: str = "NONE"
    ior: object = 1.5
    metallic: object = 0.0
    multiscatter: bool = False

    def __post_init__(self):
        self.model = str(self.model).upper()
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        self.fresnel = str(self.fresnel).upper()
        if self.fresnel not in FRESNEL_MODES:
            raise ValueError(f"fresnel must be one of {FRESNEL_MODES}, got {self.fresnel!r}")
        self.diffuse = np.maximum(_rgb_array(self.diffuse, "diffuse"), 0.0)
        self.specular = np.maximum(_rgb_array(self.specular, "specular"), 0.0)
        self.roughness = _positive_array(self.roughness, "roughness", ALPHA_MIN)
        self.alpha_x = float(_positive_array(self.alpha_x, "alpha_x", ALPHA_MIN))
        self.alpha_y = float(_positive_array(self.alpha_y, "alpha_y", ALPHA_MIN))
        self.nu = float(_positive_array(self.nu, "nu", 0.0))
        self.nv = float(_positive_array(self.nv, "nv", 0.0))
        self.ior = _positive_array(self.ior, "ior", 1e-3)
        self.metallic = np.clip(_positive_array(self.metallic, "metallic", 0.0), 0.0, 1.0)
        self.multiscatter = bool(self.multiscatter)

    @property
    def is_anisotropic(self) -> bool:
        return self.model in ("WARD_ANISO", "ASHIKHMIN_SHIRLEY")

    def aniso_params(self):
        """``(a, b)``: (alpha_x, alpha_y) or (nu, nv)."""
        if self.model == "WARD_ANISO":
            return self.alpha_x, self.alpha_y
        return self.nu, self.nv


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
    th, wt = _hemi_theta_quadrature(_iso_support_cos(model, a) if a < 0.3 else 0.0)
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
    e2, mu = cost(ll)
    return math.exp(ll), mu, math.sqrt(max(e2, 0.0) / dd)


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
    coef, r = solve(x)
    order = np.argsort(-x)
    lam = np.exp(x)
    return lam[order], np.maximum(coef[order], 0.0), math.sqrt(float(r @ r) / float(np.sum(wt * d * d)))


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

# Generated by iso_table_fit(model) (rounded to 7 digits); tests refit and compare.
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

# Generated by ggx_table_fit() (7 digits, below 1e-6 written 0); tests refit and compare.
# Also in shaders/sg_common.glsl.
GGX_NDF_TABLE = (
    np.array([[1.992838, 0.3828076], [1.98416, 0.3794611], [1.957449, 0.3691366], [1.911287, 0.3512051], [1.84205, 0.3240784], [1.740421, 0.2836717], [1.611464, 0.2315964], [1.535449, 0.2018369], [1.501452, 0.1891955], [1.478714, 0.1796236], [1.456021, 0.1679977], [1.427885, 0.1521422], [1.390106, 0.130881], [1.338649, 0.1035195], [1.269413, 0.06974741], [1.178129, 0.02971582], [1.099019, 0], [1.08185, 0], [1.055609, 0], [1.019339, 0], [1.541843, 0]]),
    np.array([[0.7645672, 0.2045907], [0.7653469, 0.2035765], [0.7678104, 0.2003622], [0.7723066, 0.1944554], [0.7796551, 0.1846765], [0.7918028, 0.1680978], [0.8071456, 0.1459605], [0.8093663, 0.1417465], [0.8011657, 0.1528181], [0.7880022, 0.1708359], [0.7715373, 0.1929814], [0.7523974, 0.2180762], [0.7309676, 0.2453626], [0.7076121, 0.2741905], [0.6827244, 0.3039604], [0.6567133, 0.3341347], [0.6114557, 0.3842979], [0.5127084, 0.4888012], [0.3841785, 0.6200544], [0.217368, 0.7863972], [0, 1]]))

#: view-cosine nodes of :data:`GGX_WARP_TABLE` (node 0 is fitted at ``n.o = WARP_MU_MIN``).
WARP_MU = np.linspace(0.0, 1.0, 21)
WARP_MU_MIN = 0.02
#: Blender-roughness nodes of :data:`GGX_WARP_TABLE`.
WARP_R = np.linspace(0.0, 1.0, 21)
#: weight of the pull of the corrections toward none (relative to the slice's norm): pins a
#: lobe's tilt where it does not matter (the constant lobe), so the table stays continuous.
WARP_RIDGE = 1e-3


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


def fit_ggx_warp(r, mu_o, x0=None, iterations=60):
    """Least-squares correction of the two warped GGX lobes (eq. 17-21) of Blender roughness
    ``r`` at view cosine ``mu_o``: each lobe's axis tilted by ``d_k`` (radians, in the plane
    of incidence, away from the normal for ``d_k > 0``), its sharpness scaled by
    ``exp(l_k)`` and its amplitude free, minimising
    ``int_{n.i>0} (sum_k G_k(i) (n.i) - D(h) G2(i, o) / (4 n.o))^2 di`` against Cycles'
    single-scattering GGX slice times the cosine (Fresnel 1), with the amplitudes solved by
    linear least squares (kept non-negative) and ``(d_k, l_k)`` by Levenberg-Marquardt from
    ``x0`` (plus the small pull :data:`WARP_RIDGE` toward none).  The isotropic warp of
    §4.3 cannot follow the slice at oblique views (Wang et al. 2009 say so): it is broad in
    the plane of incidence and narrow across it, its peak off the mirror direction and cut
    by the horizon.  The axes stay above the horizon (eq. 40's cosine lobe, which
    normalises the slice, is poor below).  Returns ``(params (6,) = (d_1, l_1, d_2, l_2,
    f_1, f_2), rel_error, rel_error of the plain warp scaled to the slice's energy)`` with
    ``f_k`` the lobes' shares of the amplitude (the slice is scaled to Cycles' ``E`` where
    it is used, :func:`_ggx_normalisation`)."""
    a = max(float(r) ** 2, ALPHA_MIN)
    mu_o = max(float(mu_o), WARP_MU_MIN)
    o, h, i, wi = _warp_quadrature(a, mu_o)
    a2 = a * a
    g2 = 1.0 / (1.0 + _lambda_raw("GGX", a2, np.maximum(i[:, 2], COS_MIN)) + _lambda_raw("GGX", a2, mu_o))
    sw = np.sqrt(wi)
    t = ndf_value("GGX", h, a) * g2 / (4.0 * mu_o) * sw
    tn = float(np.linalg.norm(t))
    lam_d, mu_d = iso_ndf_lobes("GGX", a)
    lam_w = np.minimum(lam_d / (4.0 * mu_o), LAMBDA_MAX)
    el0 = math.acos(mu_o)
    cosi = i[:, 2] * sw

    def basis(x):
        cols = []
        for k in range(2):
            el = min(max(el0 + x[2 * k], -0.5 * math.pi), 0.5 * math.pi)   # axis above the horizon
            ax = np.array([-math.sin(el), 0.0, math.cos(el)])
            lam = min(lam_w[k] * math.exp(min(x[2 * k + 1], 30.0)), LAMBDA_MAX)
            cols.append(np.exp(lam * (i @ ax - 1.0)) * cosi)
        return np.stack(cols, 1)

    def amps(B):
        amp, *_ = np.linalg.lstsq(B, t, rcond=None)
        if np.all(amp >= 0.0):
            return amp
        best = None                         # non-negative: the better lobe alone
        for k in range(2):
            a_k = max(float(B[:, k] @ t) / max(float(B[:, k] @ B[:, k]), 1e-300), 0.0)
            trial = np.zeros(2)
            trial[k] = a_k
            c = float(np.linalg.norm(B @ trial - t))
            if best is None or c < best[0]:
                best = (c, trial)
        return best[1]

    def resid(x):
        B = basis(x)
        return np.concatenate([B @ amps(B) - t, WARP_RIDGE * tn * x])

    B0 = basis(np.zeros(4)) @ mu_d
    # the plain warp normalised to the slice's energy as specular_lobes does (E, not fitted)
    scale = float(np.sum(B0 * sw)) and float(np.sum(t * sw)) / float(np.sum(B0 * sw))
    err0 = float(np.linalg.norm(B0 * scale - t)) / tn
    x = np.zeros(4) if x0 is None else np.array(x0[:4], dtype=np.float64)
    x, _ = levenberg_marquardt(resid, x, iterations, fd_step=lambda v: 1e-6 * max(1.0, abs(v)),
                               min_gain=1e-10)
    x[0::2] = np.clip(el0 + x[0::2], -0.5 * math.pi, 0.5 * math.pi) - el0
    B = basis(x)
    amp = amps(B)
    err = float(np.linalg.norm(B @ amp - t)) / tn
    return np.concatenate([x, amp / max(float(np.sum(amp)), 1e-300)]), err, err0


def ggx_warp_table_fit(r_nodes=None):
    """``(len(r_nodes), len(WARP_MU), 6)`` corrections :func:`fit_ggx_warp` at the nodes
    ``WARP_R[r_nodes]`` (all when None) and :data:`WARP_MU`, each column continued from
    ``n.o = 1`` (start: no correction) down to grazing.  How :data:`GGX_WARP_TABLE` was made."""
    idx = range(len(WARP_R)) if r_nodes is None else r_nodes
    out = np.zeros((len(idx), len(WARP_MU), 6))
    for a, ir in enumerate(idx):
        x = None
        for j in range(len(WARP_MU) - 1, -1, -1):
            x, _, _ = fit_ggx_warp(WARP_R[ir], WARP_MU[j], x)
            out[a, j] = x
    return out


def ggx_warp_params(r, cos_o):
    """The corrections (..., 6) of :data:`GGX_WARP_TABLE` at Blender roughness ``r`` and view
    cosine ``cos_o`` (bilinear; shapes broadcast)."""
    r, c = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(cos_o, dtype=np.float64))
    x = np.clip(r, 0.0, 1.0) * (len(WARP_R) - 1)
    y = np.clip(c, 0.0, 1.0) * (len(WARP_MU) - 1)
    i = np.minimum(x.astype(np.int64), len(WARP_R) - 2)
    j = np.minimum(y.astype(np.int64), len(WARP_MU) - 2)
    fx, fy = (x - i)[..., None], (y - j)[..., None]
    from .sg_warp_table import GGX_WARP_TABLE as tb
    return ((1 - fx) * ((1 - fy) * tb[i, j] + fy * tb[i, j + 1])
            + fx * ((1 - fy) * tb[i + 1, j] + fy * tb[i + 1, j + 1]))


def ggx_warp_correct(roughness, n, o, pw, lam_d, mu_d, P):
    """The warped GGX lobes (axes (P, K, 3), sharpness (P, K)) and NDF amplitudes (P, K)
    corrected by :func:`ggx_warp_params` at the point's roughness and ``n.o``: axis tilted in
    the plane of ``n`` and the mirror direction, sharpness scaled, amplitudes the fitted
    shares (the slice is normalised to Cycles' ``E`` afterwards, as without the correction)."""
    cos_o = np.clip(np.sum(n * o, axis=1), 0.0, 1.0)
    r = np.sqrt(np.clip(_per_point(roughness, P), 0.0, 1.0))
    q = ggx_warp_params(r, cos_o)                                      # (P, 6)
    u = pw - np.sum(pw * n[:, None, :], -1, keepdims=True) * n[:, None, :]
    un = np.linalg.norm(u, axis=-1, keepdims=True)
    fallback, _ = orthonormal_frame(n)
    u = np.where(un > 1e-9, u / np.maximum(un, 1e-300), fallback[:, None, :])
    el = np.arccos(np.clip(cos_o, -1.0, 1.0))[:, None] + q[:, [0, 2]]
    axes = np.cos(el)[..., None] * n[:, None, :] + np.sin(el)[..., None] * u
    lam_w = np.broadcast_to(lam_d, (P, lam_d.shape[-1])) / (4.0 * np.maximum(cos_o, WARP_MU_MIN))[:, None]
    lam2 = np.minimum(np.minimum(lam_w, LAMBDA_MAX) * np.exp(q[:, [1, 3]]), LAMBDA_MAX)
    return axes, lam2, np.maximum(q[:, 4:6], 0.0)


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


def ndf_lobes(material: SGMaterial) -> NDFLobes:
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
    if model == "GGX":
        th, wt = _graded_theta_quadrature(a)
    else:
        th, wt = _hemi_theta_quadrature(_iso_support_cos(model, a) if a < 0.3 else 0.0)
    h = np.stack([np.sin(th), 0 * th, np.cos(th)], axis=1)
    d = ndf_value(model, h, a)
    g = np.sum(mu[None, :] * np.exp(-lam[None, :] * 2.0 * np.sin(0.5 * th)[:, None] ** 2), axis=1)
    err = math.sqrt(float(np.sum(wt * (g - d) ** 2)) / float(np.sum(wt * d * d)))
    return NDFLobes(np.tile([0.0, 0.0, 1.0], (len(lam), 1)), lam, mu, err)


# --------------------------------------------------------------------------- Fresnel

def fresnel_eq14(c, eta):
    """Eq. 14 (Cook & Torrance 1981): ``F = (g-c)^2/(2(g+c)^2) (1 + ((c(g+c)-1)/(c(g-c)+1))^2)``,
    ``g = sqrt(eta^2 + c^2 - 1)``, ``c = |i . h|``; 1 under total internal reflection."""
    c = np.abs(np.asarray(c, dtype=np.float64))
    eta = np.asarray(eta, dtype=np.float64)
    g2 = eta * eta + c * c - 1.0
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0.0, np.nan_to_num(f, nan=1.0), 1.0)


def fresnel_coefficients(material: SGMaterial):
    """``(A, B_d, B_s)`` RGB arrays (broadcast shape of the material's values + (3,))
    such that ``ks F(c) = A + B_d F_eq14(c, ior) + B_s (1 - c)^5`` (module docstring)."""
    ks = material.specular
    zero = np.zeros_like(ks)
    mode = material.fresnel
    if mode == "NONE":
        return ks, zero, zero
    if mode == "SCHLICK":
        return ks, zero, 1.0 - ks
    if mode == "DIELECTRIC":
        return zero, ks, zero
    eta = np.asarray(material.ior, dtype=np.float64)[..., None]
    f0r = np.minimum(((eta - 1.0) / (eta + 1.0)) ** 2, 1.0 - 1e-6)
    m = np.asarray(material.metallic, dtype=np.float64)[..., None]
    base = np.clip(material.diffuse, 0.0, 1.0)
    ks = np.clip(ks, 0.0, 1.0)
    a = (1.0 - m) * (ks - (1.0 - ks) * f0r / (1.0 - f0r)) + m * base
    bd = (1.0 - m) * (1.0 - ks) / (1.0 - f0r)
    bs = m * (1.0 - base)
    return a, bd, bs


def _fresnel(material, c):
    """``ks F(c)`` (..., 3) for cosines ``c`` (...,)."""
    a, bd, bs = fresnel_coefficients(material)
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    out = a + 0.0 * c[..., None]
    if np.any(bd):
        eta = np.asarray(material.ior, dtype=np.float64)
        out = out + bd * fresnel_eq14(c, eta)[..., None]
    if np.any(bs):
        out = out + bs * ((1.0 - c) ** 5)[..., None]
    if material.fresnel == "PRINCIPLED":
        out = np.clip(out, 0.0, None)
    return out


# --------------------------------------------------------------------------- M_o and the view slice

def _m_factor(model, roughness, cos_i, cos_o, h_dot_i):
    """Scalar part of ``M_o(i)`` (without Fresnel) per model (module docstring)."""
    if model in ("COOK_TORRANCE", "BLINN_PHONG", "GGX"):
        ci = np.maximum(cos_i, COS_MIN)
        co = np.maximum(cos_o, COS_MIN)
        a2 = np.maximum(np.asarray(roughness, dtype=np.float64), ALPHA_MIN) ** 2
        dist = "GGX" if model == "GGX" else "BECKMANN"
        li = _lambda_raw(dist, a2, ci)
        lo = _lambda_raw(dist, a2, co)
        return 1.0 / ((1.0 + li + lo) * 4.0 * ci * co)
    if model in ("WARD", "WARD_ANISO"):
        ci = np.maximum(cos_i, COS_MIN_SINGULAR)
        co = np.maximum(cos_o, COS_MIN_SINGULAR)
        return 1.0 / (4.0 * np.sqrt(ci * co))
    ci = np.maximum(cos_i, COS_MIN_SINGULAR)
    co = np.maximum(cos_o, COS_MIN_SINGULAR)
    return 1.0 / (4.0 * np.maximum(h_dot_i, COS_MIN_SINGULAR) * np.maximum(ci, co))


def _unit(v, name):
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (P, 3), got {np.shape(v)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN/Inf values")
    n = np.linalg.norm(a, axis=1, keepdims=True)
    return a / np.where(n > 0, n, 1.0)


def _frames(normals, tangents):
    n = _unit(normals, "normals")
    if tangents is None:
        t, _ = orthonormal_frame(n)
    else:
        t = _unit(tangents, "tangents")
        if t.shape != n.shape:
            raise ValueError(f"tangents {t.shape} must match normals {n.shape}")
        t = t - np.sum(t * n, axis=1, keepdims=True) * n
        ln = np.linalg.norm(t, axis=1, keepdims=True)
        fallback, _ = orthonormal_frame(n)
        t = np.where(ln > 1e-8, t / np.where(ln > 0, ln, 1.0), fallback)
    b = np.cross(n, t)
    return n, t, b


def _local_ndf_lobes(material, P):
    """NDF lobes per point: axes_local (P|1, K, 3), lam (P|1, K), mu (P|1, K)."""
    if material.is_anisotropic:
        f = ndf_lobes(material)
        return f.axes[None], f.lam[None], f.mu[None]
    lam, mu = iso_ndf_lobes(material.model, material.roughness)
    K = lam.shape[-1]
    lam, mu = lam.reshape(-1, K), mu.reshape(-1, K)
    if lam.shape[0] not in (1, P):
        raise ValueError(f"roughness has {lam.shape[0]} values for {P} points")
    return np.tile([0.0, 0.0, 1.0], (1, K, 1)), lam, mu


def specular_lobes(material: SGMaterial, normals, views, tangents=None, fitted_warp=True):
    """The view slice ``ks rho_s(o, i)`` of the specular BRDF as an SG mixture in
    ``i`` (eq. 15-22), without the cosine ``n . i``.

    For each NDF lobe (:func:`ndf_lobes`, placed in the frame (t, b, n); ``t`` is
    ``tangents`` made orthogonal to ``n``, or the branchless
    :func:`.directions.orthonormal_frame` tangent when None):

    * warp (eq. 18-21): ``p_W = 2 (o.p) p - o``, ``lam_W = lam_D / (4 |o.p|)``,
      ``mu_W = mu_D``; where ``lam_W`` exceeds :data:`LAMBDA_MAX` it is capped and
      ``mu_W`` scaled by ``LAMBDA_MAX / lam_W`` so the lobe keeps its integral;
    * views below the horizon (``n.o < 1e-4``) are bent up to it as in
      :func:`.brdf.reflectance_cosine`;
    * ``mu = mu_W ks F(o.p) M_o(p_W)`` (eq. 22) with ``M_o`` of the model
      (cosines floored at :data:`COS_MIN`, or :data:`COS_MIN_SINGULAR` for the
      ``1/sqrt(cos)`` models) and the Fresnel of :func:`fresnel_coefficients`;
      lobes whose facet faces away from the view (``o.p <= 0``) get ``mu = 0``;
    * ``GGX``: ``M_o`` is the normalisation to Cycles' ``E(r, n.o)``, ``F`` at each lobe's
      product with the cosine, times the multiscatter factor (module docstring);
      ``fitted_warp``: the warped lobes corrected by :data:`GGX_WARP_TABLE`
      (:func:`ggx_warp_correct`, as ``shaders/ssdf_sg_frag.glsl``; False: the plain warp).

    ``normals``, ``views`` (toward the viewer), ``tangents``: (P, 3).  Per-point
    material arrays broadcast over P.  Returns ``axes (P, K, 3)``, ``lam (P, K)``,
    ``mu (P, K, 3)`` (float64), ``K <= MAX_LOBES``.
    """
    n, t, b = _frames(normals, tangents)
    o = _unit(views, "views")
    if o.shape != n.shape:
        raise ValueError(f"views {o.shape} must match normals {n.shape}")
    P = n.shape[0]
    o = _bend_view(n, o)
    ax_l, lam_d, mu_d = _local_ndf_lobes(material, P)
    K = ax_l.shape[1]
    if K > MAX_LOBES:
        raise ValueError(f"{K} NDF lobes > MAX_LOBES = {MAX_LOBES}")
    p = (ax_l[..., 0:1] * t[:, None, :] + ax_l[..., 1:2] * b[:, None, :]
         + ax_l[..., 2:3] * n[:, None, :])                               # (P, K, 3)
    c = np.sum(o[:, None, :] * p, axis=-1)                               # o.h  (P, K)
    pw = 2.0 * c[..., None] * p - o[:, None, :]
    pw /= np.maximum(np.linalg.norm(pw, axis=-1, keepdims=True), 1e-300)
    tau = np.maximum(4.0 * np.abs(c), 4.0 * COS_MIN)
    lam_raw = np.broadcast_to(lam_d, (P, K)) / tau
    lam = np.minimum(lam_raw, LAMBDA_MAX)
    keep_energy = lam / lam_raw          # capped lobes keep their integral ~ mu / lam
    cos_o = np.sum(n * o, axis=1)[:, None]
    if material.model == "GGX" and fitted_warp:
        pw, lam, mu_d = ggx_warp_correct(material.roughness, n, o, pw, lam_d, mu_d, P)
    cos_i = np.sum(n[:, None, :] * pw, axis=-1)
    rough = material.roughness
    rough = rough[:, None] if np.ndim(rough) and np.size(rough) == P and P > 1 else rough
    if material.model == "GGX":
        m = _ggx_normalisation(material, n, pw, lam, mu_d, cos_o[:, 0], P)
        keep_energy = 1.0
    else:
        m = _m_factor(material.model, rough, cos_i, cos_o, c)
    mat = material
    cf = _fresnel_cosine(n, o, pw, lam) if material.model == "GGX" else c
    if any(np.ndim(v) >= 1 and np.shape(v)[0] == P and P > 1
           for v in (mat.ior, mat.metallic)) or mat.diffuse.ndim == 2 or mat.specular.ndim == 2:
        fres = _fresnel_pointwise(mat, cf, P)
    else:
        fres = _fresnel(mat, cf)
    if mat.multiscatter:
        k_main, k_metal = multiscatter_factors(mat, cos_o[:, 0], P)
        fres = fres * k_main[:, None, :]
        if mat.fresnel == "PRINCIPLED":
            fres = fres + _metal_fresnel(mat, cf, P) * (k_metal - k_main)[:, None, :]
    mu = np.broadcast_to(mu_d, (P, K))[..., None] * (m * (c > 0.0) * keep_energy)[..., None] * fres
    return pw, lam, mu


def _per_point(v, P, shape=()):
    return np.broadcast_to(np.asarray(v, dtype=np.float64), (P,) + shape)


def _fresnel_cosine(n, o, pw, lam):
    """``o . h`` (P, K) at the half vector of the view and the axis of each warped lobe's
    product with the clamped cosine (eq. 5 with eq. 40's ``C*``): where the lit part of a
    broad lobe is, rather than its centre (a rough dielectric's grazing Fresnel at the
    centre was 2-4 points of error at r >= 0.7; the same at sharp lobes)."""
    lam_c, _ = sg.clamped_cosine_sg()
    d = lam[..., None] * pw + lam_c * n[:, None, :]
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    h = d + o[:, None, :]
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    return np.sum(h * o[:, None, :], axis=-1)


def ggx_albedo(material, cos_o, P):
    """Cycles' GGX single-scattering albedo ``E(r, n.o)`` and ``E_avg(r)`` per point (P,),
    ``r = sqrt(a)`` the Blender roughness."""
    cos_o = np.broadcast_to(np.asarray(cos_o, dtype=np.float64), (P,))
    r = np.sqrt(np.clip(_per_point(material.roughness, P), 0.0, 1.0))
    e, e_avg = np.zeros(P), np.zeros(P)
    for rv in np.unique(r):
        sel = r == rv
        e[sel] = ggx_E(float(rv), np.clip(cos_o[sel], 0.0, 1.0))
        e_avg[sel] = ggx_E_avg(float(rv))
    return e, e_avg


def _ggx_normalisation(material, n, pw, lam, mu_d, cos_o, P):
    """``M_o`` of the GGX lobes (P, 1): the factor that gives the warped slice (Fresnel 1)
    Cycles' single-scattering albedo, ``E(r, n.o) / sum_k mu_k <G_k, C*>`` with ``C*`` the
    clamped cosine of eq. 40 (inner product eq. 4).  It stands in for eq. 22's ``M`` at the
    lobe centre (shared by the coaxial lobes): the warp and ``M`` at the centre lose 9-23 %
    of a rough GGX slice's energy at a normal view, and the broad tail lobe of ``a > 0.8``
    gains more than that at grazing ones."""
    lam_c, mu_c = sg.clamped_cosine_sg()
    cos_lobe = sg.inner_product(pw, lam, 1.0, n[:, None, :], lam_c, mu_c)          # (P, K)
    a_sg = np.sum(np.broadcast_to(mu_d, cos_lobe.shape) * cos_lobe, axis=1)
    e, _ = ggx_albedo(material, cos_o, P)
    return (e / np.maximum(a_sg, 1e-300))[:, None]


def _metal_fresnel(material, c, P):
    """The Principled metal lobe's part of ``ks F`` (P, K, 3): ``m (base + (1 - base)(1 - c)^5)``."""
    m = _per_point(material.metallic, P)[:, None, None]
    base = np.clip(_per_point(material.diffuse, P, (3,)), 0.0, 1.0)[:, None, :]
    s5 = ((1.0 - np.clip(c, 0.0, 1.0)) ** 5)[..., None]
    return m * (base + (1.0 - base) * s5)


def multiscatter_factors(material: SGMaterial, cos_o, P):
    """``(k_main, k_metal)`` (P, 3): Cycles' Multiscatter GGX energy compensation
    ``1 + F_ms (1 - E) / E`` (Kulla & Conty 2017, as in :func:`.brdf.multiscatter_factor`),
    a factor of ``M_o`` (it depends on the view alone, eq. 22).  ``E = E(r, n.o)`` and
    ``E_avg(r)`` are Cycles' single-scattering albedo tables at the Blender roughness
    ``r = sqrt(a)``; ``F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg))`` with the lobe's mean
    Fresnel ``F_ss``: the main lobe's (the colour, Schlick, or the Principled dielectric
    layer) and the Principled metal lobe's (F0 = base colour, no F82 tint)."""
    e, e_avg = ggx_albedo(material, cos_o, P)
    missing = (1.0 - np.maximum(e, 1e-6)) / np.maximum(e, 1e-6)
    fms_main, fms_metal = multiscatter_fms(material, e_avg, P)
    return 1.0 + missing[:, None] * fms_main, 1.0 + missing[:, None] * fms_metal


def multiscatter_fss(material: SGMaterial, P):
    """``(F_ss main, F_ss metal)`` (P, 3): the lobes' mean Fresnel (Cycles' ``Fss``; linear
    in the base colour)."""
    ks = np.clip(_per_point(material.specular, P, (3,)), 0.0, None)
    mode = material.fresnel
    if mode == "NONE":
        fss = ks
    elif mode == "SCHLICK":
        fss = ks + (1.0 - ks) / 21.0
    elif mode == "DIELECTRIC":
        fss = ks * np.array([fresnel_dielectric_Fss(float(x)) for x in
                             _per_point(material.ior, P)])[:, None]
    else:
        eta = _per_point(material.ior, P)
        s = np.zeros(P)
        for ev in np.unique(eta):
            f0r = F0_from_ior(float(ev))
            s[eta == ev] = min(max((fresnel_dielectric_Fss(float(ev)) - f0r) / (1.0 - f0r), 0.0),
                               1.0) if f0r < 1.0 else 1.0
        f0 = np.clip(ks, 0.0, 1.0)
        fss = f0 + (1.0 - f0) * s[:, None]
    f0m = np.clip(_per_point(material.diffuse, P, (3,)), 0.0, 1.0)
    return fss, f0m + (1.0 - f0m) / 21.0


def multiscatter_fms(material: SGMaterial, e_avg, P):
    """``(F_ms main, F_ms metal)`` (P, 3) of :func:`multiscatter_factors` for ``E_avg`` (P,):
    ``F_ss E_avg / (1 - F_ss (1 - E_avg))``."""
    ea = np.broadcast_to(np.asarray(e_avg, dtype=np.float64), (P,))[:, None]
    return tuple(f * ea / np.maximum(1.0 - f * (1.0 - ea), 1e-12)
                 for f in multiscatter_fss(material, P))


def _bend_view(n, o):
    """Views with ``n.o < COS_VIEW_MIN`` raised to just above the horizon, as
    :func:`.brdf._bend_views` (Cycles bends the normal instead):
    ``o' = normalize(o + (COS_VIEW_MIN - n.o) n)``."""
    c = np.sum(n * o, axis=1)
    low = c < core_brdf.COS_VIEW_MIN
    if np.any(low):
        o = o.copy()
        o[low] += (core_brdf.COS_VIEW_MIN - c[low])[:, None] * n[low]
        ln = np.linalg.norm(o[low], axis=1, keepdims=True)
        o[low] /= np.where(ln > 0, ln, 1.0)
    return o


def _fresnel_pointwise(material, c, P):
    """Fresnel with per-point (P,) / (P, 3) material values against (P, K) cosines."""
    def col(v):
        v = np.asarray(v, dtype=np.float64)
        return np.broadcast_to(v, (P, 3))[:, None, :]

    def sca(v):
        v = np.asarray(v, dtype=np.float64)
        return np.broadcast_to(v, (P,))[:, None]

    m = SGMaterial.__new__(SGMaterial)
    m.__dict__.update(material.__dict__)
    m.specular = col(material.specular)
    m.diffuse = col(material.diffuse)
    m.ior = sca(material.ior)
    m.metallic = sca(material.metallic)
    return _fresnel(m, c)


def specular_brdf(material: SGMaterial, normals, views, dirs, tangents=None):
    """Analytic ``ks rho_s(o, i)`` (P, D, 3) for light directions ``dirs`` (D, 3):
    the function :func:`specular_lobes` approximates (exact NDF, ``M`` and
    Fresnel at each direction; zero for ``n.i <= 0``).  For tests/benches."""
    n, t, b = _frames(normals, tangents)
    o = _unit(views, "views")
    L = _unit(dirs, "dirs")
    h = o[:, None, :] + L[None, :, :]
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    hl = np.stack([np.sum(h * t[:, None], -1), np.sum(h * b[:, None], -1),
                   np.sum(h * n[:, None], -1)], axis=-1)
    rough = material.roughness
    rough = rough[:, None] if np.ndim(rough) and np.size(rough) == n.shape[0] and n.shape[0] > 1 else rough
    d = ndf_value(material.model, hl, rough, material.aniso_params())
    cos_i = L @ n.T
    cos_i = cos_i.T
    cos_o = np.sum(n * o, axis=1)[:, None]
    c = np.sum(h * L[None], -1)
    m = _m_factor(material.model, rough, cos_i, cos_o, c)
    fres = _fresnel_pointwise(material, c, n.shape[0]) if (
        material.diffuse.ndim == 2 or material.specular.ndim == 2) else _fresnel(material, c)
    return (d * m * (cos_i > 0))[..., None] * fres


# --------------------------------------------------------------------------- diffuse part

def diffuse_albedo(material: SGMaterial):
    """Lambert albedo ``rho_d`` of eq. 8 (``kd = rho_d / pi``), (3,) or (P, 3).

    ``fresnel="PRINCIPLED"``: Cycles scales the base colour by ``(1 - metallic)``
    and a view-dependent layering weight (:func:`.brdf.diffuse_view_weight`);
    here its cosine-weighted average over views ``2 int w(mu) mu dmu``, so that
    ``kd`` stays view independent (the weight varies by ~5 % between normal and
    grazing views at roughness 0.5).  Other modes: ``material.diffuse``.
    """
    if material.fresnel != "PRINCIPLED":
        return material.diffuse.copy()
    m = np.asarray(material.metallic, dtype=np.float64)[..., None]
    w = _principled_mean_layering(material)
    return material.diffuse * (1.0 - m) * w


def _principled_brdf_material(material, rough_r=None, f0=None):
    a = float(np.mean(material.roughness))
    r = math.sqrt(max(a, 0.0)) if rough_r is None else rough_r
    eta = float(np.mean(material.ior))
    ks = np.asarray(material.specular, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    return core_brdf.Material(diffuse_albedo=(1.0, 1.0, 1.0), specular_color=tuple(ks),
                              roughness=r, distribution="MULTI_GGX", fresnel="DIELECTRIC", ior=eta,
                              metallic=0.0)


def _principled_mean_layering(material):
    bm = _principled_brdf_material(material)
    x, w = np.polynomial.legendre.leggauss(16)
    mu = 0.5 * (x + 1.0)
    n = np.tile([0.0, 0.0, 1.0], (mu.size, 1))
    v = np.stack([np.sqrt(1.0 - mu * mu), 0 * mu, mu], axis=1)
    weight = core_brdf.diffuse_view_weight(bm, n, v)[:, 0].astype(np.float64)
    return float(np.sum(w * mu * weight))


def diffuse_view_weight(material: SGMaterial, normals, views):
    """(P,) exact per-view Principled layering weight (Cycles), 1 for other modes."""
    n = _unit(normals, "normals")
    if material.fresnel != "PRINCIPLED":
        return np.ones(n.shape[0])
    bm = _principled_brdf_material(material)
    return core_brdf.diffuse_view_weight(bm, n, _unit(views, "views"))[:, 0].astype(np.float64)


# --------------------------------------------------------------------------- from core.brdf

def sg_material_from_brdf(material: core_brdf.Material, ggx: bool = True) -> SGMaterial:
    """Closest SG model of a Cycles-like :class:`.brdf.Material`, ``alpha = max(r^2, ...)``:
    Beckmann lobes are ``COOK_TORRANCE``; GGX and Multiscatter GGX lobes are ``GGX`` (two
    coaxial SGs; Multiscatter GGX with ``multiscatter=True``), or with ``ggx=False``
    ``COOK_TORRANCE`` too (the Beckmann lobe of the same alpha drawn before 2026-12-02:
    docs/measurements.md "SG lobes of a rough metal").

    * Glossy BSDF (``fresnel="NONE"``): ``F = 1``, ``ks`` = node colour, diffuse
      albedo kept (0 for a pure Glossy BSDF).
    * ``"SCHLICK"`` / ``"F82"``: Schlick with ``F0 = specular_color`` (F82 tint dropped).
    * Principled (``"DIELECTRIC"``): ``fresnel="PRINCIPLED"`` with the base colour,
      metallic, the dielectric ``f0`` colour and ``eta`` (module docstring).
    """
    alpha = max(material.alpha, ALPHA_MIN)
    ggx = ggx and material.lobe_distribution == "GGX"
    common = dict(model="GGX" if ggx else "COOK_TORRANCE", roughness=alpha,
                  multiscatter=ggx and material.distribution == "MULTI_GGX")
    if material.fresnel == "NONE":
        return SGMaterial(diffuse=material.diffuse_albedo, specular=material.specular_color,
                          fresnel="NONE", **common)
    if material.fresnel in ("SCHLICK", "F82"):
        diffuse = material.diffuse_albedo if material.fresnel == "SCHLICK" else (0.0, 0.0, 0.0)
        return SGMaterial(diffuse=diffuse, specular=material.specular_color,
                          fresnel="SCHLICK", **common)
    spec = material.specular_color if material._has_dielectric_lobe else (0.0, 0.0, 0.0)
    return SGMaterial(diffuse=material.diffuse_albedo, specular=spec, fresnel="PRINCIPLED",
                      ior=material.ior if material.ior != 1.0 else 1.0 + 1e-6,
                      metallic=material.metallic, **common)


def without_glossy(material: SGMaterial) -> SGMaterial:
    """The Lambert part of ``material`` alone, with the albedo it has there
    (:func:`diffuse_albedo`: a Principled base keeps its layering weight): for slots
    whose glossy lobes are drawn elsewhere (per pixel, :func:`.brdf.is_sharp`)."""
    return SGMaterial(model="COOK_TORRANCE", diffuse=diffuse_albedo(material),
                      specular=(0.0, 0.0, 0.0), roughness=material.roughness, fresnel="NONE")
