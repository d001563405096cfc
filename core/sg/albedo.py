"""What an SG material reflects in all (Wang et al. 2009's SG BRDFs with Cycles' energy): GGX's
directional albedo, the multiscatter factors, the diffuse albedo and the Principled base's
layering weight per view."""

from __future__ import annotations

import math

import numpy as np

from ..shading import brdf as core_brdf
from ..shading import materials
from ..shading.brdf_tables import ggx_E, ggx_E_avg
from ..shading.microfacet import F0_from_ior, fresnel_dielectric_Fss
from .ndf import broadcast_rows
from .reflectance import SGMaterial


def ggx_albedo(material, cos_o, P):
    """Cycles' GGX single-scattering albedo ``E(r, n.o)`` and ``E_avg(r)`` per point (P,),
    ``r = sqrt(a)`` the Blender roughness."""
    cos_o = np.broadcast_to(np.asarray(cos_o, dtype=np.float64), (P,))
    r = np.sqrt(np.clip(broadcast_rows(material.roughness, P), 0.0, 1.0))
    e, e_avg = np.zeros(P), np.zeros(P)
    for rv in np.unique(r):
        sel = r == rv
        e[sel] = ggx_E(float(rv), np.clip(cos_o[sel], 0.0, 1.0))
        e_avg[sel] = ggx_E_avg(float(rv))
    return e, e_avg


def metal_fresnel(material, c, P):
    """The Principled metal lobe's part of ``ks F`` (P, K, 3): ``m (base + (1 - base)(1 - c)^5)``."""
    m = broadcast_rows(material.metallic, P)[:, None, None]
    base = np.clip(broadcast_rows(material.diffuse, P, (3,)), 0.0, 1.0)[:, None, :]
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
    ks = np.clip(broadcast_rows(material.specular, P, (3,)), 0.0, None)
    mode = material.fresnel
    if mode == "NONE":
        fss = ks
    elif mode == "SCHLICK":
        fss = ks + (1.0 - ks) / 21.0
    elif mode == "DIELECTRIC":
        fss = ks * np.array([fresnel_dielectric_Fss(float(x)) for x in
                             broadcast_rows(material.ior, P)])[:, None]
    else:
        eta = broadcast_rows(material.ior, P)
        s = np.zeros(P)
        for ev in np.unique(eta):
            f0r = F0_from_ior(float(ev))
            s[eta == ev] = min(max((fresnel_dielectric_Fss(float(ev)) - f0r) / (1.0 - f0r), 0.0),
                               1.0) if f0r < 1.0 else 1.0
        f0 = np.clip(ks, 0.0, 1.0)
        fss = f0 + (1.0 - f0) * s[:, None]
    f0m = np.clip(broadcast_rows(material.diffuse, P, (3,)), 0.0, 1.0)
    return fss, f0m + (1.0 - f0m) / 21.0


def multiscatter_fms(material: SGMaterial, e_avg, P):
    """``(F_ms main, F_ms metal)`` (P, 3) of :func:`multiscatter_factors` for ``E_avg`` (P,):
    ``F_ss E_avg / (1 - F_ss (1 - E_avg))``."""
    ea = np.broadcast_to(np.asarray(e_avg, dtype=np.float64), (P,))[:, None]
    return tuple(f * ea / np.maximum(1.0 - f * (1.0 - ea), 1e-12)
                 for f in multiscatter_fss(material, P))


def diffuse_albedo(material: SGMaterial):
    """Lambert albedo ``rho_d`` of eq. 8 (``kd = rho_d / pi``), (3,) or (P, 3).

    ``fresnel="PRINCIPLED"``: Cycles scales the base colour by ``(1 - metallic)``
    and a view-dependent layering weight (:func:`.brdf.diffuse_view_weight`);
    here its cosine-weighted average over views ``2 int w(mu) mu dmu``, so that
    ``kd`` stays view independent; :func:`diffuse_view_ratio` is the view's share of it
    (the shader and :func:`.ssdf_sg_scene.shade_points` multiply it per pixel / point).
    Other modes: ``material.diffuse``.
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
    return materials.Material(diffuse_albedo=(1.0, 1.0, 1.0), specular_color=tuple(ks),
                              roughness=r, distribution="MULTI_GGX", fresnel="DIELECTRIC", ior=eta,
                              metallic=0.0)


def _principled_layering(material, mu):
    """Cycles' layering weight of the Principled base (without ``1 - metallic``) at view
    cosines ``mu`` (1-D) over a normal ``+z`` (:func:`.brdf.diffuse_view_weight`)."""
    mu = np.clip(np.asarray(mu, dtype=np.float64), -1.0, 1.0)
    v = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (mu.size, 1))
    bm = _principled_brdf_material(material)
    return core_brdf.diffuse_view_weight(bm, n, v)[:, 0].astype(np.float64)


def _principled_mean_layering(material):
    x, w = np.polynomial.legendre.leggauss(16)
    mu = 0.5 * (x + 1.0)
    return float(np.sum(w * mu * _principled_layering(material, mu)))


def diffuse_view_ratio(material: SGMaterial, cos_o):
    """Cycles' Principled layering weight of the Lambert base at view cosines ``cos_o``
    (any shape) over its mean that :func:`diffuse_albedo` folds into ``kd``: ``kd`` times
    this is Cycles' base at that view (a factor of the view alone, like the multiscatter
    factor: exact per pixel).  At roughness 0.3 it runs from 1.04 at a normal view to 0.6 at
    grazing ones, where the dielectric layer takes most of the light.  1 for other modes."""
    c = np.asarray(cos_o, dtype=np.float64)
    if material.fresnel != "PRINCIPLED":
        return np.ones(c.shape)
    w = _principled_layering(material, c.reshape(-1))
    return (w / max(_principled_mean_layering(material), 1e-12)).reshape(c.shape)
