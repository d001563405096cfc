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
  as :data:`.sg_ndf.GGX_LOBES` coaxial SGs (:data:`.sg_ndf.GGX_NDF_TABLE`, :func:`.sg_ndf.fit_coaxial_ndf`), each
  warped like the one lobe of the other models (``fitted_warp=False``); by default the view
  slice is :data:`.sg_ndf.GGX_WARP_LOBES` lobes along the plane of incidence fitted to it
  (:data:`GGX_WARP_TABLE`, :func:`.sg_ndf.fit_ggx_warp`).  ``M`` at the lobes' centre is replaced by
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

``roughness`` is floored at :data:`SG_ALPHA_MIN` (NDF sharpness <= ~8e4, inside the
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
linear interpolation; ``shaders/lib/constants.glsl`` is generated from them) and
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
(§4.3 says so; for GGX ``specular_lobes(fitted_warp=True)`` draws the slice as lobes with
their own tilt, sharpness and share by a least-squares table over (r, n.o),
:func:`fit_ggx_warp`), ``M`` constant over each lobe (eq. 22), a rough GGX slice's shape
(its energy is Cycles' by construction) and the F82 tint of Cycles' metal lobe (Schlick here).
GGX lobes drawn as the Beckmann lobe of the same alpha without the multiscatter factor
(before 2026-12-02, ``sg_material_from_brdf(ggx=False)``) were 14-20 % off on a rough
metal: docs/measurements.md "SG lobes of a rough metal".  Measured errors:
``tests/core/sg/test_brdf.py``, docs/measurements.md.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..shading import brdf as core_brdf
from ..shading import materials
from . import algebra as sg
from ..sphere.directions import orthonormal_frame
from ..shading.microfacet import lambda_raw
# the NDFs as SG lobes, their fits and tables, and the model constants
from .ndf import SG_ALPHA_MIN, COS_MIN, COS_MIN_SINGULAR, FRESNEL_INDEX, FRESNEL_MODES, ISO_NDF_TABLE, ISO_TABLE_ALPHA, ISOTROPIC_MODELS, LAMBDA_MAX, MAX_LOBES, MODEL_INDEX, MODELS, NDFLobes, fit_anisotropic_ndf, fit_isotropic_ndf, iso_ndf_lobes, iso_ndf_sg, iso_table_fit, ndf_lobes, ndf_value
from .ggx_warp import ggx_warp_correct
from .reflectance import SGMaterial
from .albedo import metal_fresnel, ggx_albedo, multiscatter_factors

__all__ = [
    "MODELS", "ISOTROPIC_MODELS", "FRESNEL_MODES", "MAX_LOBES", "SG_ALPHA_MIN",
    "SGMaterial", "NDFLobes", "ndf_value", "ndf_lobes", "fit_isotropic_ndf",
    "fit_anisotropic_ndf", "iso_ndf_sg", "specular_lobes", "specular_brdf",
    "fresnel_coefficients", "fresnel_eq14",
    "sg_material_from_brdf", "ISO_TABLE_ALPHA", "ISO_NDF_TABLE", "iso_table_fit",
    "MODEL_INDEX", "FRESNEL_INDEX",
]

# --------------------------------------------------------------------------- material


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


def ks_fresnel(material, c):
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
        a2 = np.maximum(np.asarray(roughness, dtype=np.float64), SG_ALPHA_MIN) ** 2
        dist = "GGX" if model == "GGX" else "BECKMANN"
        li = lambda_raw(dist, a2, ci)
        lo = lambda_raw(dist, a2, co)
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


def specular_lobes(material: SGMaterial, normals, views, tangents=None, fitted_warp=True,
                   cosine=None, cosine_frame=None, horizon=False):
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
      ``fitted_warp``: the slice as the fitted lobes of :data:`GGX_WARP_TABLE`
      (:func:`ggx_warp_correct`, as ``shaders/methods/ssdf_sg_frag.glsl``; False: the plain warp of
      the NDF's lobes);
      ``cosine`` is the clamped-cosine SG mixture the slice will be shaded with
      (``directions`` (M, 3) local to ``cosine_frame = (t, b)``, default the lobes' frame;
      ``amplitudes``, ``sharpness``: a :class:`.ssdf_sg.CosineLobes`), default eq. 40's
      single lobe: ``E`` is the slice's integral against it; ``horizon``: each product of
      that integral weighted by the visibility factor (``fh_hat``) of the open hemisphere
      over ``n``, as the renderer draws it for a flat open surface.

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
        pw, lam, mu_d = ggx_warp_correct(material.roughness, n, o, P)
        K = lam.shape[1]                 # the fitted lobes replace the NDF's: o.n for o.h
        c = np.broadcast_to(cos_o, (P, K))
    cos_i = np.sum(n[:, None, :] * pw, axis=-1)
    rough = material.roughness
    rough = rough[:, None] if np.ndim(rough) and np.size(rough) == P and P > 1 else rough
    if material.model == "GGX":
        m = _ggx_normalisation(material, n, pw, lam, mu_d, cos_o[:, 0], P, cosine,
                               (t, b) if cosine_frame is None else cosine_frame, horizon)
        keep_energy = 1.0
    else:
        m = _m_factor(material.model, rough, cos_i, cos_o, c)
    mat = material
    cf = _fresnel_cosine(n, o, pw, lam) if material.model == "GGX" else c
    if any(np.ndim(v) >= 1 and np.shape(v)[0] == P and P > 1
           for v in (mat.ior, mat.metallic)) or mat.diffuse.ndim == 2 or mat.specular.ndim == 2:
        fres = _fresnel_pointwise(mat, cf, P)
    else:
        fres = ks_fresnel(mat, cf)
    if mat.multiscatter:
        k_main, k_metal = multiscatter_factors(mat, cos_o[:, 0], P)
        fres = fres * k_main[:, None, :]
        if mat.fresnel == "PRINCIPLED":
            fres = fres + metal_fresnel(mat, cf, P) * (k_metal - k_main)[:, None, :]
    mu = np.broadcast_to(mu_d, (P, K))[..., None] * (m * (c > 0.0) * keep_energy)[..., None] * fres
    return pw, lam, mu


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


def _ggx_normalisation(material, n, pw, lam, mu_d, cos_o, P, cosine=None, frame=None,
                       horizon=False):
    """``M_o`` of the GGX lobes (P, 1): the factor that gives the warped slice (Fresnel 1)
    Cycles' single-scattering albedo, ``E(r, n.o) / sum_k mu_k <G_k, C>`` with ``C`` the
    clamped-cosine mixture the slice is shaded with (inner products eq. 4; eq. 40's ``C*``
    when ``cosine`` is None).  It stands in for eq. 22's ``M`` at the lobe centre (shared by
    the coaxial lobes): the warp and ``M`` at the centre lose 9-23 % of a rough GGX slice's
    energy at a normal view, and the broad tail lobe of ``a > 0.8`` gains more than that at
    grazing ones.  Against the same mixture, a white unoccluded sky returns ``E`` exactly
    (against ``C*`` while shading with a 7-lobe mixture, 0.90-1.21 ``E`` at r 0.3).
    ``horizon``: each product ``G_k C_m`` (eq. 5) also weighted by eq. 46's ``fh_hat`` at
    its axis's elevation over ``n``'s horizon (the SSDF of an open hemisphere, core.methods.ssdf_sg.ssdf),
    as eq. 41 draws a flat open surface: the part of a broad lobe's product below the
    horizon, which the visibility removes, no longer counts toward ``E`` (it was 2-3.5 % of
    ``E`` at r >= 0.7, up to 22 % at grazing views of r 0.3: tests/core/sg/test_brdf.py)."""
    if cosine is None:
        lam_c, mu_c = sg.clamped_cosine_sg()
        lobes = [(n, lam_c, mu_c)]
    else:
        t, b = frame
        d = np.asarray(cosine.directions, np.float64)
        lobes = [(d[m, 0] * t + d[m, 1] * b + d[m, 2] * n, float(cosine.sharpness), float(w))
                 for m, w in enumerate(cosine.amplitudes)]
    cos_lobe = 0.0
    for axis, lam_m, w in lobes:
        if not horizon:
            cos_lobe = cos_lobe + sg.inner_product(pw, lam, 1.0, axis[:, None, :], lam_m, w)
            continue
        p, lam_p, amp = sg.product(np.broadcast_to(axis[:, None, :], pw.shape), lam_m, w,
                                   pw, lam, 1.0)
        elev = np.arcsin(np.clip(np.sum(p * n[:, None, :], -1), -1.0, 1.0))
        cos_lobe = cos_lobe + amp * sg.integral(lam_p) * sg.fh_hat_approx(elev, lam_p)
    a_sg = np.sum(np.broadcast_to(mu_d, cos_lobe.shape) * cos_lobe, axis=1)
    e, _ = ggx_albedo(material, cos_o, P)
    return (e / np.maximum(a_sg, 1e-300))[:, None]


def _bend_view(n, o):
    """Views with ``n.o < COS_VIEW_MIN`` raised to just above the horizon, as
    :func:`.brdf.bend_views` (Cycles bends the normal instead):
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
    return ks_fresnel(m, c)


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
        material.diffuse.ndim == 2 or material.specular.ndim == 2) else ks_fresnel(material, c)
    return (d * m * (cos_i > 0))[..., None] * fres


# --------------------------------------------------------------------------- diffuse part


# --------------------------------------------------------------------------- from core.shading.brdf

def sg_material_from_brdf(material: materials.Material, ggx: bool = True) -> SGMaterial:
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
    alpha = max(material.alpha, SG_ALPHA_MIN)
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
    """``material`` with its glossy lobes drawn elsewhere (per pixel, :func:`.brdf.is_sharp`):
    only its Lambert base is shaded from it, with the albedo it has there
    (:func:`diffuse_albedo`: a Principled base keeps its layering weight, and its view
    ratio :func:`diffuse_view_ratio`)."""
    return replace(material, lobes=False)
