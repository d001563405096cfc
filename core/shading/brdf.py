# SPDX-License-Identifier: GPL-3.0-or-later
r"""Vectorised BRDFs matching Cycles' direct lighting (pure numpy, no ``bpy``).

Conventions
-----------
* World space is Z-up; every direction is a unit vector pointing **away** from
  the surface: ``wo`` towards the viewer, ``wi`` towards the light.
* ``normals`` and ``views`` are ``(P, 3)`` (one row per shading point/vertex),
  ``dirs`` is ``(D, 3)`` (the light/quadrature directions ``wi``, shared by all
  points).  Results are ``(P, D)`` or ``(P, D, 3)`` ``float32`` arrays.
* Memory: internally the scalar terms are ``float64`` ``(P, D)`` arrays (no
  ``(P, D, 3)`` float64 temporaries); peak use is roughly 90 bytes per
  ``(P, D)`` entry, e.g. ~180 MB for a ``P * D = 2e6`` chunk.
* Everything returned is "BRDF times cosine", i.e. the integrand of the
  rendering equation without the incident radiance:

  .. math::  L_o(w_o) = \int_{\Omega} f(w_i, w_o)\,\max(0, n\cdot w_i)\,L_i(w_i)\,dw_i

Models
------
Diffuse (Cycles ``bsdf_diffuse_eval``: ``fmaxf(dot(N, wo), 0) * M_1_PI_F``, no
test on the view side)::

    f_d = rho / pi,          rho = Material.diffuse_albedo (RGB)

Glossy (Cycles ``bsdf_microfacet_eval`` for a purely reflective closure)::

    f_s(wi, wo) = F * D(h) * G2(wi, wo) / (4 cos_i cos_o)
    h  = (wi + wo) / |wi + wo|,   cos_i = n.wi,  cos_o = n.wo
    G2 = 1 / (1 + Lambda(cos_i) + Lambda(cos_o))       (height-correlated Smith)

so that ``f_s * cos_i = F * D * G2 / (4 cos_o)`` -- exactly Cycles'
``common = D / cos_NI * 0.25f; eval = F * common / (1 + lambdaO + lambdaI)``
(Cycles names the *view* direction ``wi`` and the light direction ``wo``; its
``eval`` already contains the light cosine.)

Normal distribution functions (isotropic, ``a2 = alpha**2``, ``c = n.m``),
normalised so that ``integral D(m) (n.m) dm = 1``::

    Beckmann: D = exp(-(1 - c^2) / (c^2 a2)) / (pi a2 c^4)
    GGX:      D = a2 / (pi ((1 - c^2) + a2 c^2)^2)

Smith Lambda (Heitz 2014, "Understanding the Masking-Shadowing Function")
with ``t2 = a2 * tan^2(theta) = a2 * max(1/c^2 - 1, 0)``::

    GGX (exact, Heitz eq. 72):   Lambda = (sqrt(1 + t2) - 1) / 2
    Beckmann (Walter et al. 2007 rational approximation, below Heitz eq. 69),
        with a = 1/sqrt(t2) = 1/(alpha tan theta):
        Lambda = (1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2)   if a < 1.6
        Lambda = 0                                                   otherwise
        (Cycles tests ``t2 < 0.39`` which is ``a > 1/sqrt(0.39) = 1.601``.)

Fresnel (``Material.fresnel``)
  * ``"NONE"`` -- Cycles' Glossy BSDF node: ``F = 1``, the node colour is the
    closure weight, so the lobe is ``specular_color * f_s``.
  * ``"SCHLICK"`` -- ``F = F0 + (1 - F0) (1 - h.wi)^5`` with
    ``F0 = specular_color`` (``h.wi = h.wo = sqrt((1 + wi.wo) / 2)``).  This is
    Cycles' generalized-Schlick Fresnel with exponent 5 and ``F90 = 1``; kept
    for callers that want it, the Principled BSDF uses ``"DIELECTRIC"``.
  * ``"DIELECTRIC"`` -- Cycles' Principled BSDF v2 (Blender 4.x/5.x), see
    "Principled BSDF" below: the real dielectric Fresnel of ``Material.ior``
    remapped from ``[F0_real, 1]`` to ``[specular_color, 1]``, layered over the
    Lambert base, plus an optional F82-tint metal lobe (``Material.metallic``).
  * ``"F82"`` -- a conductor lobe with Cycles' F82-tint Fresnel
    (``F0 = specular_color``, tint ``Material.f82_tint``); the diffuse lobe, if
    any, is simply added.

Roughness mapping: Blender's roughness ``r`` is clamped to ``[0, 1]`` and
``alpha = r * r`` (``svm_node_closure_bsdf``: ``roughness = sqr(saturatef(param1))``),
then ``alpha`` is clamped to ``>= MICROFACET_ALPHA_MIN`` here (see below).

What this module follows in Cycles
----------------------------------
``intern/cycles/kernel/closure/bsdf_microfacet.h`` (Blender 4.x/5.x version,
the one with ``MicrofacetFresnel::F82_TINT`` and ``energy_scale``):
``bsdf_lambda_from_sqr_alpha_tan_n`` (Lambda, incl. the ``0.39`` cut and the
``((0.396a - 1.259)a + 1) / ((2.181a + 3.535)a)`` form), ``bsdf_lambda``,
``bsdf_G``, ``bsdf_D`` (both NDFs as written above), ``bsdf_microfacet_eval``
(rejects ``cos_NI <= 0`` i.e. view below the shading normal, rejects light
below the normal as "transmission", ``common = D / cos_NI * 0.25``,
``eval = F * common / (1 + lambdaO + lambdaI)``) and
``bsdf_microfacet_ggx_eval`` (multiplies by ``energy_scale``, see below).
``intern/cycles/kernel/svm/closure.h`` (Glossy node: ``alpha = sqr(saturatef(roughness))``,
``bsdf->N = maybe_ensure_valid_specular_reflection(sd, N)``).
``intern/cycles/kernel/closure/bsdf_diffuse.h`` (Lambert ``cos / pi``).

Multiscatter GGX (``distribution="MULTI_GGX"``)
------------------------------------------------
Cycles 4.x/5.x (``bsdf_microfacet.h``: ``microfacet_ggx_preserve_energy``,
Kulla & Conty 2017) draws "Multiscatter GGX" as the single-scatter GGX lobe
times a per-view, per-channel factor::

    E     = E(r, mu = n.wo)      single-scatter directional albedo of GGX (F = 1)
    E_avg = 2 int_0^1 E(r, mu) mu dmu
    Fms   = Fss E_avg / (1 - Fss (1 - E_avg))       Fss: the lobe's average Fresnel
    f_ms  = f_ss * F * (1 + Fms (1 - E) / E)

(``energy_scale = 1/E`` times the ``darkening`` weight).  ``Fss`` is the node
colour for the Glossy BSDF (``bsdf_microfacet_setup_fresnel_constant``),
``mix(f0, 1, s_avg)`` with ``s_avg = (Fss_diel(eta) - F0_real) / (1 - F0_real)``
for the Principled dielectric layer (``..._generalized_schlick`` with a negative
exponent; ``Fss_diel`` is Cycles' ``fresnel_dielectric_Fss`` fit) and
``mix(F0, 1, 1/21) - B/126`` for F82 (``fresnel_f82_Fss``).  Cycles reads ``E``
and ``E_avg`` from 32 x 32 / 32 tables (``scene/shader.tables``) with
node-aligned linear interpolation (``lookup_table_read_2D``; grid value =
index / 31, roughness ``r`` on x, ``mu`` on y).  We build the *same grids* from
our own quadrature of the GGX lobe (:func:`.brdf_tables.ggx_E_table_column`, lazily, cached
per roughness node) and interpolate the same way, so the tables are never
copied; the tests compare them against Cycles' values.

Principled BSDF (``fresnel="DIELECTRIC"``)
-----------------------------------------
``intern/cycles/kernel/svm/closure.h``, ``svm_node_closure_bsdf``,
``CLOSURE_BSDF_PRINCIPLED_ID`` (no sheen/coat/transmission/subsurface)::

    weight  = 1
    metal   : metallic * GGX lobe with F82-tint Fresnel, F0 = clamp(base, 0, 1),
              F82 tint = min(specular_tint, 1)          ; weight *= 1 - metallic
    eta     = IOR; f0 = F0_from_ior(eta) = ((eta-1)/(eta+1))^2
              if specular_ior_level != 0.5: f0 *= 2 level; eta = ior_from_F0(f0)
    spec    : weight * GGX lobe, F = mix(f0 * specular_tint, 1, s(h.wi)),
              s = saturate((F_diel(h.wi, eta) - f0) / (1 - f0))
              (bsdf_microfacet_setup_fresnel_generalized_schlick, exponent -eta)
              ; weight = closure_layering_weight(bsdf_albedo(spec), weight)
    diffuse : base_color * weight * Lambert

``closure_layering_weight`` (``bsdf_util.h``) is
``weight * saturate(1 - max_c(albedo_c / weight_c))`` and the albedo of the
specular closure is ``sc->weight * bsdf_microfacet_estimate_albedo`` where
``sc->weight`` already carries the multiscatter ``darkening`` factor
``(1 + Fms (1-E)/E) / (1 + (1-E)/E)`` and the estimate is
``mix(f0, 1, S(r, mu, z))`` from the 16^3 table ``ggx_gen_schlick_ior_s``
(``z = sqrt(|(eta-1)/(eta+1)|)``; generated by ``app/cycles_precompute.cpp``
as the mean over VNDF samples of ``s(h.wi)``, 0 for samples reflected below
the horizon).  So the Lambert base is scaled by the *view-dependent*
:func:`diffuse_view_weight`::

    (1 - metallic) * saturate(1 - max_c darkening_c * mix(f0_c, 1, S(r, mu, z)))

which darkens the base at grazing views: 0.963 from straight above and 0.914
at 66 deg from the normal for the default grey surface (the specular lobe
gains about what the base loses, so a white furnace stays at ~0.81).  ``S``
is again our own quadrature on Cycles' grid with Cycles' trilinear
interpolation.  The Cycles default surface (no material,
``scene/shader.cpp`` ``ShaderManager::add_default``) is a Principled BSDF with
the node defaults: base 0.8, metallic 0, roughness 0.5, IOR 1.5, specular IOR
level 0.5, specular tint 1, Multiscatter GGX.

Differences from Cycles that callers should know about
------------------------------------------------------
* **Near-mirror lobes.**  Cycles treats ``alpha^2 <= 2e-10``
  (``BSDF_ROUGHNESS_SQ_THRESH``, roughness <~ 0.0038) as a singular (delta)
  reflection that cannot be evaluated at all.  We clamp
  ``alpha >= MICROFACET_ALPHA_MIN = 1e-3`` (roughness ~0.032) instead, so very smooth
  materials become a narrow but finite lobe.  The NDF peak is then
  ``1 / (pi alpha^2) ~ 3e5``; callers integrating such lobes with a fixed
  direction set will under-sample them.
* **Grazing / back-facing views.**  Cycles returns zero glossy reflection for
  ``n.wo <= 0`` but it first bends the shading normal towards the viewer
  (``maybe_ensure_valid_specular_reflection``) so the silhouette stays lit.
  Per-vertex normals cannot do that, so here the view is *bent* instead: when
  ``n.wo < COS_VIEW_MIN = 1e-4`` we replace ``wo`` by the unit vector
  ``normalize(wo + (COS_VIEW_MIN - n.wo) n)``, i.e. the view direction with
  its normal component raised to (about) ``COS_VIEW_MIN``, keeping its
  azimuth.  Because ``G2 / cos_o`` stays bounded as ``cos_o -> 0`` (Lambda
  grows like ``1 / cos_o``), the result is continuous across ``n.wo = 0``
  and finite everywhere.  The diffuse lobe ignores the view, as in Cycles,
  except for the Principled layering weight (:func:`diffuse_view_weight`),
  which uses the bent ``n.wo``.
* Tables: our ``E``/``E_avg``/``S`` come from deterministic quadrature (a
  256 x 256 grid over Cycles' own GGX VNDF sample mapping) instead of Cycles'
  Monte-Carlo tables; they agree to ~1e-3 (tests).  Interpolation between
  grid nodes is Cycles'.
* Not modelled (the exporter warns): sheen, coat, transmission, subsurface,
  emission, thin film, alpha, anisotropy, Oren-Nayar diffuse roughness, the
  Ashikhmin-Shirley distribution, Beckmann multiscatter (Cycles has none
  either) and the legacy clearcoat GTR1 lobe.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .brdf_tables import dielectric_albedo_s, ggx_E, ggx_E_avg
from .microfacet import MICROFACET_ALPHA_MIN, F0_from_ior, check_distribution, dielectric_s, f82_tint_B, fresnel_dielectric, fresnel_dielectric_Fss, fresnel_f82, ior_from_F0, microfacet_D, roughness_to_alpha, smith_G1, smith_lambda
from .materials import Material

__all__ = [
    "MICROFACET_ALPHA_MIN",
    "COS_VIEW_MIN",
    "roughness_to_alpha",
    "microfacet_D",
    "smith_lambda",
    "smith_G1",
    "specular_cosine",
    "specular_terms",
    "reflectance_cosine",
    "diffuse_view_weight",
    "fresnel_dielectric",
    "fresnel_dielectric_Fss",
    "F0_from_ior",
    "ior_from_F0",
    "f82_tint_B",
    "fresnel_f82",
    "ggx_E",
    "ggx_E_avg",
    "dielectric_albedo_s",
    "multiscatter_factor",
    "specular_albedo_estimate",
    "sharp_alpha_limit",
    "is_sharp",
    "with_sharp_lobe",
    "sharp_lobes",
]

#: Views with ``n.wo`` below this are bent up to (about) this cosine.
COS_VIEW_MIN = 1e-4

# Threshold on |wi + wo|^2 under which the half vector is undefined (wi = -wo).
HALF_LEN2_FLOOR = 1e-20


# --------------------------------------------------------------------------- #
# Lobes too narrow for the cubemap: drawn per pixel
# --------------------------------------------------------------------------- #

#: a glossy lobe is resolved by a 6 N^2 cubemap when its solid angle (~4 pi alpha^2 for
#: the reflected GGX/Beckmann lobe) spans at least this many texels (~4 pi / (6 N^2) each)
SHARP_LOBE_TEXELS = 8.0


def sharp_alpha_limit(resolution: int) -> float:
    """Microfacet alpha below which a lobe is narrower than :data:`SHARP_LOBE_TEXELS`
    texels of the 6 N^2 cubemap: 0.036 at N = 32, 0.018 at 64, 0.009 at 128."""
    return float(np.sqrt(SHARP_LOBE_TEXELS / 6.0) / max(int(resolution), 1))


def is_sharp(material: Material, resolution: int) -> bool:
    """Whether ``material`` has a glossy lobe the cubemap's texels cannot integrate
    (sampled at texel centres it renders black with a few bright blobs)."""
    probe = replace(material, per_pixel_lobe=False)
    r = material.table_roughness
    return not probe.is_diffuse_only and r * r < sharp_alpha_limit(resolution)


def with_sharp_lobe(material: Material, resolution: int) -> Material:
    """``material`` with :attr:`Material.per_pixel_lobe` set when :func:`is_sharp`."""
    if material.per_pixel_lobe or not is_sharp(material, resolution):
        return material
    return replace(material, per_pixel_lobe=True)


#: Fresnel kinds of :func:`sharp_lobes` (the GLSL of ``shaders/passes/sharp_lobe_frag.glsl``)
SHARP_CONSTANT, SHARP_SCHLICK, SHARP_DIELECTRIC, SHARP_F82 = 0, 1, 2, 3


def sharp_lobes(material: Material) -> list:
    """The glossy lobes of ``material`` for per-pixel drawing, as in
    :func:`specular_terms`: ``[(kind, weight, f0 (3,), B (3,), eta), ...]``, each lobe
    ``weight * F(h.wi) * D G2 / (4 cos_o)`` with ``F`` = ``f0`` (``SHARP_CONSTANT``),
    Schlick to 1, the Principled dielectric remap of ``eta`` or F82-tint (``B``).
    The microfacet alpha is the unclamped ``clamp(r, 0, 1)^2`` (0: a mirror)."""
    m = material
    zero = (0.0, 0.0, 0.0)
    col = tuple(float(c) for c in m.specular_color)
    if m.fresnel == "NONE":
        return [(SHARP_CONSTANT, 1.0, tuple(max(c, 0.0) for c in col), zero, 1.0)]
    if m.fresnel == "SCHLICK":
        return [(SHARP_SCHLICK, 1.0, col, zero, 1.0)]
    if m.fresnel == "F82":
        f0 = np.clip(col, 0.0, 1.0)
        return [(SHARP_F82, 1.0, tuple(f0), tuple(metal_B(f0, m.f82_tint)), 1.0)]
    lobes = []
    if m.metallic > 0.0:
        f0 = np.clip(np.asarray(m.diffuse_albedo, dtype=np.float64), 0.0, 1.0)
        lobes.append((SHARP_F82, m.metallic, tuple(f0), tuple(metal_B(f0, m.f82_tint)), 1.0))
    if m._has_dielectric_lobe:
        lobes.append((SHARP_DIELECTRIC, 1.0 - m.metallic, tuple(np.clip(col, 0.0, 1.0)), zero,
                      m.ior))
    return lobes


# --------------------------------------------------------------------------- #
# Per-view weights
# --------------------------------------------------------------------------- #

def _lobe_Fss(material: Material, which: str) -> np.ndarray:
    """Average single-scattering Fresnel of a lobe (RGB), as Cycles passes it to
    ``microfacet_ggx_preserve_energy``."""
    f0 = np.asarray(material.specular_color, dtype=np.float64)
    if which == "metal":
        f0m = np.clip(np.asarray(material.diffuse_albedo, dtype=np.float64), 0.0, 1.0)
        B = metal_B(f0m, material.f82_tint)
        return f0m + (1.0 - f0m) / 21.0 - B / 126.0
    if material.fresnel == "NONE":
        return np.maximum(f0, 0.0)
    if material.fresnel == "SCHLICK":
        return f0 + (1.0 - f0) / 21.0
    if material.fresnel == "F82":
        B = metal_B(f0, material.f82_tint)
        return f0 + (1.0 - f0) / 21.0 - B / 126.0
    eta = material.ior
    F0r = F0_from_ior(eta)
    s = min(max((fresnel_dielectric_Fss(eta) - F0r) / (1.0 - F0r), 0.0), 1.0) if F0r < 1.0 else 1.0
    f0 = np.clip(f0, 0.0, 1.0)
    return f0 + (1.0 - f0) * s


def metal_B(f0, tint) -> np.ndarray:
    tint = np.minimum(np.asarray(tint, dtype=np.float64), 1.0)
    if np.all(tint == 1.0):
        return np.zeros(3)
    return f82_tint_B(f0, tint)


def _ms_parts(material: Material, cos_o: np.ndarray):
    """``(missing (P,), E_avg)`` with ``missing = (1 - E) / E``."""
    r = material.table_roughness
    E = np.maximum(ggx_E(r, cos_o), 1e-6)
    return (1.0 - E) / E, ggx_E_avg(r)


def multiscatter_factor(material: Material, cos_o, which: str = "main") -> np.ndarray:
    """``(P, 3)`` factor ``1 + Fms (1 - E) / E`` of a MULTI_GGX lobe (ones otherwise).

    ``which="metal"`` selects the F82 metal lobe of a Principled material.
    """
    cos_o = np.atleast_1d(np.asarray(cos_o, dtype=np.float64))
    if material.distribution != "MULTI_GGX":
        return np.ones((len(cos_o), 3))
    missing, E_avg = _ms_parts(material, cos_o)
    Fss = _lobe_Fss(material, which)
    Fms = Fss * E_avg / np.maximum(1.0 - Fss * (1.0 - E_avg), 1e-12)
    return 1.0 + missing[:, None] * Fms[None, :]


def specular_albedo_estimate(material: Material, cos_o) -> np.ndarray:
    """``(P, 3)`` albedo of the Principled dielectric layer relative to its
    closure weight, as Cycles' ``closure_layering_weight`` sees it:
    ``darkening * mix(f0, 1, S(r, mu, z))`` (``darkening`` is the multiscatter
    weight factor divided by ``energy_scale``; 1 for plain GGX)."""
    cos_o = np.atleast_1d(np.asarray(cos_o, dtype=np.float64))
    f0 = np.clip(np.asarray(material.specular_color, dtype=np.float64), 0.0, 1.0)
    S = dielectric_albedo_s(material.table_roughness, cos_o, material.ior)
    est = f0[None, :] + (1.0 - f0[None, :]) * S[:, None]
    if material.distribution == "MULTI_GGX":
        Fss = _lobe_Fss(material, "main")
        if not np.all(Fss == 1.0):
            missing, E_avg = _ms_parts(material, cos_o)
            Fms = Fss * E_avg / np.maximum(1.0 - Fss * (1.0 - E_avg), 1e-12)
            est = est * (1.0 + missing[:, None] * Fms[None, :]) / (1.0 + missing[:, None])
    return est


def _view_cosines(normals, views) -> np.ndarray:
    n = unit_rows(normals, "normals")
    v = unit_rows(views, "views")
    if n.shape[0] != v.shape[0]:
        raise ValueError(f"normals {n.shape} and views {v.shape} must have the same length")
    return bend_views(n, v)[1]


def diffuse_view_weight(material: Material, normals, views) -> np.ndarray:
    r"""``(P, 3)`` float32 weight of the Lambert base for each view direction.

    1 except for ``fresnel="DIELECTRIC"`` (Principled), where it is Cycles'
    layering weight ``(1 - metallic) * saturate(1 - max_c albedo_c)`` with
    ``albedo`` from :func:`specular_albedo_estimate` at ``mu = n.wo`` (views
    below the horizon are bent as for the glossy lobe).  The diffuse radiance
    is ``irradiance * diffuse_albedo / pi * diffuse_view_weight``.
    """
    cos_o = _view_cosines(normals, views)
    P = len(cos_o)
    if material.fresnel != "DIELECTRIC":
        return np.ones((P, 3), dtype=np.float32)
    w = np.full(P, 1.0 - material.metallic)
    if material._has_dielectric_lobe:
        est = specular_albedo_estimate(material, cos_o)
        w *= np.clip(1.0 - est.max(axis=1), 0.0, 1.0)
    return np.repeat(w[:, None], 3, axis=1).astype(np.float32)


# --------------------------------------------------------------------------- #
# Geometry helpers
# --------------------------------------------------------------------------- #

def unit_rows(v, name: str) -> np.ndarray:
    """``(N, 3)`` float64 copy with unit rows (zero rows stay zero, NaN -> 0)."""
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {np.shape(v)}")
    a = np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)
    n = np.sqrt(np.einsum("ij,ij->i", a, a))
    return a / np.where(n > 0.0, n, 1.0)[:, None]


def bend_views(n: np.ndarray, v: np.ndarray):
    """Raise views with ``n.wo < COS_VIEW_MIN`` to just above the horizon.

    ``wo' = normalize(wo + (COS_VIEW_MIN - n.wo) n)``; returns ``(wo', n.wo')``
    with ``n.wo'`` floored at ``COS_VIEW_MIN`` (guards the normalisation of
    the degenerate ``wo = -n`` case, which becomes ``wo' = n``).
    """
    cos_o = np.einsum("ij,ij->i", n, v)
    low = cos_o < COS_VIEW_MIN
    if np.any(low):
        v = v.copy()
        v[low] += (COS_VIEW_MIN - cos_o[low])[:, None] * n[low]
        ln = np.sqrt(np.einsum("ij,ij->i", v[low], v[low]))
        v[low] /= np.where(ln > 0.0, ln, 1.0)[:, None]
        cos_o = np.einsum("ij,ij->i", n, v)
    return v, np.clip(cos_o, COS_VIEW_MIN, 1.0)


def _prepare(normals, views, dirs):
    n = unit_rows(normals, "normals")
    v = unit_rows(views, "views")
    L = unit_rows(dirs, "dirs")
    if n.shape[0] != v.shape[0]:
        raise ValueError(f"normals {n.shape} and views {v.shape} must have the same length")
    return n, v, L


def _specular_terms(distribution: str, alpha: float, n, v, L, want_fresnel: bool):
    """Scalar glossy lobe ``D G2 / (4 cos_o)`` (P, D) float64 and, optionally,
    ``h.wi`` (P, D) float64, plus the (bent) ``cos_o`` (P,).

    Works from dot products only (no (P, D, 3) half-vector array)::

        |wi + wo|^2 = 2 + 2 wi.wo
        n.h  = (cos_i + cos_o) / |wi + wo|
        h.wi = sqrt((1 + wi.wo) / 2)
    """
    distribution = check_distribution(distribution)
    v, cos_o = bend_views(n, v)
    cos_i = n @ L.T                      # (P, D)
    dot_io = v @ L.T                     # (P, D)

    len2 = 2.0 + 2.0 * dot_io
    np.maximum(len2, 0.0, out=len2)
    valid = (cos_i > 0.0) & (len2 > HALF_LEN2_FLOOR)

    cos_h = cos_i + cos_o[:, None]
    cos_h /= np.sqrt(np.maximum(len2, HALF_LEN2_FLOOR))
    np.clip(cos_h, -1.0, 1.0, out=cos_h)

    val = microfacet_D(distribution, alpha, cos_h)
    del cos_h
    lam_i = smith_lambda(distribution, alpha, cos_i)
    lam_o = smith_lambda(distribution, alpha, cos_o)
    lam_i += 1.0
    lam_i += lam_o[:, None]              # 1 + Lambda_i + Lambda_o
    lam_i *= (4.0 * cos_o)[:, None]
    val /= lam_i
    del lam_i
    val[~valid] = 0.0

    h_wi = None
    if want_fresnel:
        h_wi = np.sqrt(np.clip(0.5 * (1.0 + dot_io), 0.0, 1.0))
    return val, h_wi, cos_o


def specular_terms(material: Material, normals, views, dirs) -> list:
    r"""The glossy part as a short sum of separable terms.

    Returns ``[(lobe_k, weight_k), ...]`` with ``lobe_k`` ``(P, D)`` float32
    and ``weight_k`` ``(P, 3)`` float32 such that the glossy BRDF times cosine
    is ``sum_k lobe_k[:, :, None] * weight_k[:, None, :]`` -- Fresnel, colour,
    layer weights and the multiscatter factor included.  Callers integrating
    against lighting can do one matrix product per term instead of
    materialising ``(P, D, 3)``.  Empty for :attr:`Material.is_diffuse_only`.
    """
    n, v, L = _prepare(normals, views, dirs)
    P = n.shape[0]
    if material.is_diffuse_only or P == 0:
        return []
    fres = material.fresnel
    need_h = fres != "NONE"
    val, h_wi, cos_o = _specular_terms(material.lobe_distribution, material.alpha, n, v, L, need_h)
    val = val.astype(np.float32)
    if h_wi is not None:
        h_wi = h_wi.astype(np.float32)
    terms = []

    def add(lobe, weight):
        terms.append((np.asarray(lobe, dtype=np.float32), np.asarray(weight, dtype=np.float32)))

    def f82_lobe(f0, tint, weight):
        f0 = np.clip(np.asarray(f0, dtype=np.float64), 0.0, 1.0)
        B = metal_B(f0, tint)
        if not np.any(B):           # plain Schlick to 1: linear, no clamp needed
            s5 = np.clip(np.float32(1.0) - h_wi, 0.0, 1.0) ** 5
            add(val, weight * f0[None, :])
            add(val * s5, weight * (1.0 - f0)[None, :])
            return
        for c in range(3):          # clamped F82: one term per channel
            F = fresnel_f82(h_wi, f0[c:c + 1], B[c:c + 1])[..., 0]
            onehot = np.zeros((P, 3))
            onehot[:, c] = weight[:, c]
            add(val * F, onehot)

    col = np.asarray(material.specular_color, dtype=np.float64)
    if fres == "NONE":
        add(val, multiscatter_factor(material, cos_o) * col[None, :])
    elif fres == "SCHLICK":
        k = multiscatter_factor(material, cos_o)
        add(val, k * col[None, :])
        add(val * (np.float32(1.0) - h_wi) ** 5, k * (1.0 - col)[None, :])
    elif fres == "F82":
        f82_lobe(col, material.f82_tint, multiscatter_factor(material, cos_o))
    else:                           # DIELECTRIC (Principled)
        if material.metallic > 0.0:
            k = material.metallic * multiscatter_factor(material, cos_o, "metal")
            f82_lobe(material.diffuse_albedo, material.f82_tint, k)
        if material._has_dielectric_lobe:
            f0 = np.clip(col, 0.0, 1.0)
            k = (1.0 - material.metallic) * multiscatter_factor(material, cos_o)
            add(val, k * f0[None, :])
            add(val * dielectric_s(h_wi, material.ior), k * (1.0 - f0)[None, :])
    return terms


def specular_cosine(material: Material, normals, views, dirs) -> np.ndarray:
    r"""Glossy lobe times cosine: ``f_s(wi, wo) max(0, n.wi)``.

    * ``fresnel == "NONE"`` with ``"BECKMANN"``/``"GGX"``: returns ``(P, D)``
      ``float32`` ``D(h) G2(wi, wo) / (4 cos_o)`` **without** the colour
      (multiply by ``material.specular_color`` yourself, or use
      :func:`reflectance_cosine`).
    * every other case (Fresnel modes, ``"MULTI_GGX"``): ``(P, D, 3)``
      ``float32`` including colour/Fresnel, layer weights and the multiscatter
      factor (the sum of :func:`specular_terms`).

    Zero where ``n.wi <= 0``; views with ``n.wo < COS_VIEW_MIN`` are bent up to
    the horizon (module docstring), so the output is finite for any input.
    A diffuse-only material returns zeros.
    """
    n, v, L = _prepare(normals, views, dirs)
    P, D = n.shape[0], L.shape[0]
    scalar = material.fresnel == "NONE" and material.distribution != "MULTI_GGX"
    if material.is_diffuse_only:
        return np.zeros((P, D) if scalar else (P, D, 3), dtype=np.float32)
    if scalar:
        val, _, _ = _specular_terms(material.distribution, material.alpha, n, v, L, False)
        return val.astype(np.float32)
    out = np.zeros((P, D, 3), dtype=np.float32)
    for lobe, w in specular_terms(material, n, v, L):
        out += lobe[:, :, None] * w[:, None, :]
    return out


def reflectance_cosine(material: Material, normals, views, dirs) -> np.ndarray:
    r"""Full BRDF times cosine, ``(P, D, 3)`` ``float32``::

        rho / pi * diffuse_view_weight * max(0, n.wi)  +  glossy (specular_cosine)

    The diffuse part ignores the view, as Cycles' Lambert closure does, except
    for the Principled layering weight (:func:`diffuse_view_weight`).
    """
    n, v, L = _prepare(normals, views, dirs)
    P, D = n.shape[0], L.shape[0]
    out = np.zeros((P, D, 3), dtype=np.float32)
    if material.has_diffuse:
        cos_plus = (n @ L.T).astype(np.float32)
        np.maximum(cos_plus, 0.0, out=cos_plus)
        if material.fresnel == "DIELECTRIC":
            w = diffuse_view_weight(material, n, v)
        else:
            w = None
        for c, rho in enumerate(material.diffuse_albedo):
            np.multiply(cos_plus, np.float32(rho / np.pi), out=out[..., c])
            if w is not None:
                out[..., c] *= w[:, c:c + 1]
        del cos_plus
    if material.is_diffuse_only:
        return out
    if material.fresnel == "NONE" and material.distribution != "MULTI_GGX":
        val, _, _ = _specular_terms(material.distribution, material.alpha, n, v, L, False)
        val32 = val.astype(np.float32)
        del val
        for c, col in enumerate(material.specular_color):
            if col != 0.0:
                out[..., c] += val32 * np.float32(col)
        return out
    for lobe, w in specular_terms(material, n, v, L):
        out += lobe[:, :, None] * w[:, None, :]
    return out


