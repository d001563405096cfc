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

Fresnel
  * ``"NONE"`` -- Cycles' Glossy BSDF node: ``F = 1``, the node colour is the
    closure weight, so the lobe is ``specular_color * f_s``.
  * ``"SCHLICK"`` -- ``F = F0 + (1 - F0) (1 - h.wi)^5`` with
    ``F0 = specular_color`` (``h.wi = h.wo = sqrt((1 + wi.wo) / 2)``).  This is
    Cycles' generalized-Schlick Fresnel with exponent 5 and ``F90 = 1``; note
    that the Principled BSDF does *not* use it (it remaps the real dielectric
    Fresnel curve between F0 and F90), so this mode is an approximation there.

Roughness mapping: Blender's roughness ``r`` is clamped to ``[0, 1]`` and
``alpha = r * r`` (``svm_node_closure_bsdf``: ``roughness = sqr(saturatef(param1))``),
then ``alpha`` is clamped to ``>= ALPHA_MIN`` here (see below).

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

Differences from Cycles that callers should know about
------------------------------------------------------
* **Multiscatter GGX is not modelled.**  Blender's Glossy BSDF defaults to the
  "Multiscatter GGX" distribution.  In Cycles 4.x/5.x this is the single-scatter
  GGX lobe above times a *view-dependent* energy-compensation factor
  (``microfacet_ggx_preserve_energy``, Kulla & Conty 2017)::

      E      = ggx_E LUT(r, mu = n.wo)      (single-scatter directional albedo)
      E_avg  = ggx_Eavg LUT(r)              (its cosine-weighted average)
      Fms    = C * E_avg / (1 - C (1 - E_avg))      C = node colour
      f_ms   = f_ss * (1 + Fms * (1 - E) / E)       (per colour channel)

  i.e. the energy lost by single scattering (``1 - E``, large for rough
  surfaces and grazing views) is added back with the lobe's own shape, and
  coloured glossy surfaces get an extra saturation from multi-bounce tinting.
  The factor does not depend on ``wi``, so a caller could apply it as a
  per-vertex multiplier on top of :func:`specular_cosine` if it tabulates
  ``E``; with ``distribution="GGX"`` this module matches Cycles' plain "GGX"
  option.
* **Near-mirror lobes.**  Cycles treats ``alpha^2 <= 2e-10``
  (``BSDF_ROUGHNESS_SQ_THRESH``, roughness <~ 0.0038) as a singular (delta)
  reflection that cannot be evaluated at all.  We clamp
  ``alpha >= ALPHA_MIN = 1e-3`` (roughness ~0.032) instead, so very smooth
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
  and finite everywhere.  The diffuse lobe, as in Cycles, ignores the view.
* Anisotropy, the Ashikhmin-Shirley distribution and the clearcoat GTR1 lobe
  are not modelled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "ALPHA_MIN",
    "COS_VIEW_MIN",
    "Material",
    "roughness_to_alpha",
    "microfacet_D",
    "smith_lambda",
    "smith_G1",
    "specular_cosine",
    "reflectance_cosine",
]

#: Smallest microfacet alpha used anywhere (roughness ~ 0.0316).
ALPHA_MIN = 1e-3
#: Views with ``n.wo`` below this are bent up to (about) this cosine.
COS_VIEW_MIN = 1e-4

_DISTRIBUTIONS = ("BECKMANN", "GGX")
_FRESNELS = ("NONE", "SCHLICK")
# Floor for cosines inside Lambda (keeps tan^2 finite: <= 1e24).
_COS_FLOOR = 1e-12
# Floor for cos^2 inside the Beckmann NDF (exp(-huge) -> 0, no 0/0).
_COS2_FLOOR = 1e-30
# Threshold on |wi + wo|^2 under which the half vector is undefined (wi = -wo).
_HALF_LEN2_FLOOR = 1e-20


@dataclass(frozen=True)
class Material:
    """A Lambert + microfacet-glossy material (both lobes added, as in a Cycles
    Add Shader of a Diffuse BSDF and a Glossy BSDF).

    Attributes
    ----------
    diffuse_albedo:
        RGB reflectance ``rho`` of the Lambert lobe; the BRDF is ``rho / pi``.
    specular_color:
        Glossy tint (``fresnel="NONE"``: the Glossy BSDF colour) or ``F0``
        (``fresnel="SCHLICK"``).  All zero disables the glossy lobe entirely
        in both Fresnel modes (see :attr:`is_diffuse_only`).
    roughness:
        Blender roughness ``r``; ``alpha = clamp(r, 0, 1)**2``, floored at
        :data:`ALPHA_MIN`.
    distribution:
        ``"BECKMANN"`` or ``"GGX"`` (single scattering; see module docstring
        for Multiscatter GGX).
    fresnel:
        ``"NONE"`` or ``"SCHLICK"``.
    """

    diffuse_albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    specular_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roughness: float = 0.5
    distribution: str = "BECKMANN"
    fresnel: str = "NONE"

    def __post_init__(self):
        dist = str(self.distribution).upper()
        fres = str(self.fresnel).upper()
        if dist not in _DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {_DISTRIBUTIONS}, got {self.distribution!r}")
        if fres not in _FRESNELS:
            raise ValueError(f"fresnel must be one of {_FRESNELS}, got {self.fresnel!r}")
        object.__setattr__(self, "distribution", dist)
        object.__setattr__(self, "fresnel", fres)
        object.__setattr__(self, "diffuse_albedo", tuple(float(x) for x in self.diffuse_albedo))
        object.__setattr__(self, "specular_color", tuple(float(x) for x in self.specular_color))
        if len(self.diffuse_albedo) != 3 or len(self.specular_color) != 3:
            raise ValueError("diffuse_albedo and specular_color must have 3 components")
        object.__setattr__(self, "roughness", float(self.roughness))

    @property
    def is_diffuse_only(self) -> bool:
        """True when ``specular_color`` is all zero (no glossy lobe at all)."""
        return not any(c != 0.0 for c in self.specular_color)

    @property
    def has_diffuse(self) -> bool:
        """True when any component of ``diffuse_albedo`` is non-zero."""
        return any(c != 0.0 for c in self.diffuse_albedo)

    @property
    def alpha(self) -> float:
        """Microfacet alpha actually used: ``max(clamp(r,0,1)^2, ALPHA_MIN)``."""
        return roughness_to_alpha(self.roughness)


def roughness_to_alpha(roughness: float) -> float:
    """Blender roughness -> microfacet alpha: ``max(clamp(r, 0, 1)**2, ALPHA_MIN)``."""
    r = float(roughness)
    if not np.isfinite(r):
        r = 0.0
    r = min(max(r, 0.0), 1.0)
    return max(r * r, ALPHA_MIN)


def _check_distribution(distribution: str) -> str:
    d = str(distribution).upper()
    if d not in _DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {_DISTRIBUTIONS}, got {distribution!r}")
    return d


def _clamp_alpha(alpha) -> np.ndarray:
    a = np.asarray(alpha, dtype=np.float64)
    return np.clip(np.nan_to_num(a, nan=ALPHA_MIN), ALPHA_MIN, None)


def microfacet_D(distribution, alpha, cos_theta_m) -> np.ndarray:
    r"""Normalised isotropic NDF ``D(m)`` evaluated at ``cos_theta_m = n.m``.

    ``integral_{hemisphere} D(m) (n.m) dm = 1``.  With ``a2 = alpha^2`` and
    ``c = cos_theta_m``::

        BECKMANN: D = exp(-(1 - c^2) / (c^2 a2)) / (pi a2 c^4)
        GGX:      D = a2 / (pi ((1 - c^2) + a2 c^2)^2)

    (Cycles ``bsdf_D``.)  ``alpha`` is floored at :data:`ALPHA_MIN`; ``D = 0``
    for ``c <= 0``.  Returns ``float64`` with the broadcast shape of the inputs.
    """
    dist = _check_distribution(distribution)
    a2 = _clamp_alpha(alpha) ** 2
    c = np.asarray(cos_theta_m, dtype=np.float64)
    c2 = np.clip(c * c, 0.0, 1.0)
    s2 = 1.0 - c2
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        if dist == "BECKMANN":
            c2s = np.maximum(c2, _COS2_FLOOR)
            d = np.exp(-s2 / (c2s * a2)) / (np.pi * a2 * c2s * c2s)
        else:
            den = s2 + a2 * c2
            d = a2 / (np.pi * den * den)
    return np.where(c > 0.0, d, 0.0)


def smith_lambda(distribution, alpha, cos_theta) -> np.ndarray:
    r"""Cycles' Smith ``Lambda`` for a direction at ``cos_theta = n.w``.

    With ``t2 = alpha^2 tan^2(theta)``::

        GGX:      Lambda = (sqrt(1 + t2) - 1) / 2                   (exact)
        BECKMANN: a = 1/sqrt(t2);
                  Lambda = (1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2)
                  if t2 >= 0.39 (a <~ 1.6), else 0                 (approximation)

    (Cycles ``bsdf_lambda`` / ``bsdf_lambda_from_sqr_alpha_tan_n``.)  The
    masking function is ``G1 = 1 / (1 + Lambda)``.  ``cos_theta`` is floored at
    ``1e-12`` (so directions at or below the horizon get a huge but finite
    Lambda, i.e. ``G1 ~ 0``).  Returns ``float64``.
    """
    dist = _check_distribution(distribution)
    a2 = _clamp_alpha(alpha) ** 2
    c = np.maximum(np.nan_to_num(np.asarray(cos_theta, dtype=np.float64), nan=0.0), _COS_FLOOR)
    c = np.minimum(c, 1.0)
    t2 = a2 * np.maximum(1.0 / (c * c) - 1.0, 0.0)
    if dist == "GGX":
        return 0.5 * (np.sqrt(1.0 + t2) - 1.0)
    a = 1.0 / np.sqrt(np.maximum(t2, 0.39))
    lam = ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a)
    return np.where(t2 < 0.39, 0.0, lam)


def smith_G1(distribution, alpha, cos_theta) -> np.ndarray:
    """Smith masking ``G1 = 1 / (1 + Lambda(cos_theta))`` (Cycles ``bsdf_G``, 2-arg form)."""
    return 1.0 / (1.0 + smith_lambda(distribution, alpha, cos_theta))


# --------------------------------------------------------------------------- #
# Geometry helpers
# --------------------------------------------------------------------------- #

def _unit_rows(v, name: str) -> np.ndarray:
    """``(N, 3)`` float64 copy with unit rows (zero rows stay zero, NaN -> 0)."""
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {np.shape(v)}")
    a = np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)
    n = np.sqrt(np.einsum("ij,ij->i", a, a))
    return a / np.where(n > 0.0, n, 1.0)[:, None]


def _bend_views(n: np.ndarray, v: np.ndarray):
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
    n = _unit_rows(normals, "normals")
    v = _unit_rows(views, "views")
    L = _unit_rows(dirs, "dirs")
    if n.shape[0] != v.shape[0]:
        raise ValueError(f"normals {n.shape} and views {v.shape} must have the same length")
    return n, v, L


def _specular_terms(distribution: str, alpha: float, n, v, L, want_fresnel: bool):
    """Scalar glossy lobe ``D G2 / (4 cos_o)`` (P, D) float64 and, optionally,
    the Schlick weight ``(1 - h.wi)^5`` (P, D) float64.

    Works from dot products only (no (P, D, 3) half-vector array)::

        |wi + wo|^2 = 2 + 2 wi.wo
        n.h  = (cos_i + cos_o) / |wi + wo|
        h.wi = sqrt((1 + wi.wo) / 2)
    """
    v, cos_o = _bend_views(n, v)
    cos_i = n @ L.T                      # (P, D)
    dot_io = v @ L.T                     # (P, D)

    len2 = 2.0 + 2.0 * dot_io
    np.maximum(len2, 0.0, out=len2)
    valid = (cos_i > 0.0) & (len2 > _HALF_LEN2_FLOOR)

    cos_h = cos_i + cos_o[:, None]
    cos_h /= np.sqrt(np.maximum(len2, _HALF_LEN2_FLOOR))
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

    w = None
    if want_fresnel:
        h_wi = np.sqrt(np.clip(0.5 * (1.0 + dot_io), 0.0, 1.0))
        w = (1.0 - h_wi) ** 5
    return val, w


def specular_cosine(material: Material, normals, views, dirs) -> np.ndarray:
    r"""Glossy lobe times cosine: ``f_s(wi, wo) max(0, n.wi)``.

    * ``fresnel == "NONE"``: returns ``(P, D)`` ``float32``
      ``D(h) G2(wi, wo) / (4 cos_o)`` **without** the colour (multiply by
      ``material.specular_color`` yourself, or use :func:`reflectance_cosine`).
    * ``fresnel == "SCHLICK"``: returns ``(P, D, 3)`` ``float32`` including
      ``F = F0 + (1 - F0)(1 - h.wi)^5``, ``F0 = specular_color``.

    Zero where ``n.wi <= 0``; views with ``n.wo < COS_VIEW_MIN`` are bent up to
    the horizon (module docstring), so the output is finite for any input.
    A material with ``specular_color == 0`` returns zeros.
    """
    n, v, L = _prepare(normals, views, dirs)
    P, D = n.shape[0], L.shape[0]
    schlick = material.fresnel == "SCHLICK"
    if material.is_diffuse_only:
        return np.zeros((P, D, 3) if schlick else (P, D), dtype=np.float32)
    val, w = _specular_terms(material.distribution, material.alpha, n, v, L, schlick)
    if not schlick:
        return val.astype(np.float32)
    out = np.empty((P, D, 3), dtype=np.float32)
    val32 = val.astype(np.float32)
    del val
    w32 = w.astype(np.float32)
    del w
    for c, f0 in enumerate(material.specular_color):
        np.multiply(val32, np.float32(f0) + np.float32(1.0 - f0) * w32, out=out[..., c])
    return out


def reflectance_cosine(material: Material, normals, views, dirs) -> np.ndarray:
    r"""Full BRDF times cosine, ``(P, D, 3)`` ``float32``::

        rho / pi * max(0, n.wi)  +  F * D G2 / (4 cos_o) * [n.wi > 0]

    with ``F = specular_color`` (``"NONE"``) or Schlick (``"SCHLICK"``).
    The diffuse part ignores the view, as Cycles' Lambert closure does.
    """
    n, v, L = _prepare(normals, views, dirs)
    P, D = n.shape[0], L.shape[0]
    out = np.zeros((P, D, 3), dtype=np.float32)
    if material.has_diffuse:
        cos_plus = (n @ L.T).astype(np.float32)
        np.maximum(cos_plus, 0.0, out=cos_plus)
        for c, rho in enumerate(material.diffuse_albedo):
            np.multiply(cos_plus, np.float32(rho / np.pi), out=out[..., c])
        del cos_plus
    if material.is_diffuse_only:
        return out
    schlick = material.fresnel == "SCHLICK"
    val, w = _specular_terms(material.distribution, material.alpha, n, v, L, schlick)
    val32 = val.astype(np.float32)
    del val
    w32 = w.astype(np.float32) if schlick else None
    del w
    for c, col in enumerate(material.specular_color):
        if schlick:
            out[..., c] += val32 * (np.float32(col) + np.float32(1.0 - col) * w32)
        elif col != 0.0:
            out[..., c] += val32 * np.float32(col)
    return out
