"""core.sg.albedo: GGX's directional albedo against its single-scattering integral, the
multiscatter factors against their definition (a white lobe keeps all its energy), each
Fresnel mode's mean against its hemispherical average, the diffuse albedo and its split
per view (Cycles' layered Principled base).  No bpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sg import brdf as sg_brdf
from prt_relight.core.sg import albedo
from prt_relight.core.sg import reflectance


def test_diffuse_albedo_split():
    m = reflectance.SGMaterial(diffuse=(0.5, 0.4, 0.3))
    assert np.allclose(albedo.diffuse_albedo(m), (0.5, 0.4, 0.3))
    cm = materials.principled_material(base_color=(0.8, 0.8, 0.8), metallic=0.25)
    sm = sg_brdf.sg_material_from_brdf(cm)
    n = np.tile([0.0, 0.0, 1.0], (64, 1))
    mu = (np.arange(64) + 0.5) / 64
    v = np.stack([np.sqrt(1 - mu * mu), 0 * mu, mu], 1)
    w = brdf.diffuse_view_weight(cm, n, v)[:, 0]
    mean = 2.0 * np.sum(w * mu) / 64          # cosine-weighted mean over views
    assert np.allclose(albedo.diffuse_albedo(sm), 0.8 * mean, rtol=5e-3)
    # kd times the view ratio is Cycles' layered base at each view (the Lambert radiance of
    # core.shading.brdf, per view), also when the lobes are drawn elsewhere
    for m in (sm, sg_brdf.without_glossy(sm)):
        got = albedo.diffuse_albedo(m)[0] * albedo.diffuse_view_ratio(m, mu)
        np.testing.assert_allclose(got, 0.8 * w, rtol=1e-5)
    assert np.all(albedo.diffuse_view_ratio(reflectance.SGMaterial(), mu) == 1.0)


def _ggx_albedo_by_quadrature(a, mu_o, n_u=600, n_phi=240):
    """Cycles' GGX single-scattering albedo E (Fresnel 1) from its definition: the integral
    over the half vectors h of D(h) G2(i, o) (o.h) / (n.o), i = 2 (o.h) h - o above the
    horizon (di = 4 (o.h) dh), with D and the height-correlated Smith G2 written here; the
    polar angle graded to the lobe's width, theta = atan(a tan(pi u / 2))."""
    u = (np.arange(n_u) + 0.5) / n_u
    th = np.arctan(a * np.tan(0.5 * np.pi * u))
    dth = a * 0.5 * np.pi / np.cos(0.5 * np.pi * u) ** 2 / (1.0 + (a * np.tan(0.5 * np.pi * u)) ** 2) / n_u
    ph = (np.arange(n_phi) + 0.5) / n_phi * np.pi          # half the azimuths: symmetric
    T, PH = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], -1)
    o = np.array([math.sqrt(1.0 - mu_o * mu_o), 0.0, mu_o])
    oh = h @ o
    i = 2.0 * oh[..., None] * h - o
    ci = i[..., 2]
    a2 = a * a
    c2 = np.cos(T) ** 2
    D = a2 / (np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2)

    def lam(c):
        c = np.maximum(c, 1e-12)
        return 0.5 * (-1.0 + np.sqrt(1.0 + a2 * (1.0 - c * c) / (c * c)))

    g2 = 1.0 / (1.0 + lam(ci) + lam(mu_o))
    f = np.where((ci > 0) & (oh > 0), D * g2 * oh / mu_o, 0.0)
    dw = (np.sin(T) * dth[:, None]) * (np.pi / n_phi) * 2.0
    return float(np.sum(f * dw))


@pytest.mark.parametrize("r", [0.3, 0.5, 0.8])
def test_ggx_albedo_is_the_single_scattering_integral(r):
    """E(r, n.o) (Cycles' table at Blender roughness r = sqrt(a), between its nodes too)
    against the integral of GGX's D G2 / (4 n.o) over the hemisphere; E_avg against
    2 int E(mu) mu dmu of those integrals."""
    a = r * r
    m = reflectance.SGMaterial(model="GGX", roughness=a, specular=(1.0, 1.0, 1.0))
    mus = np.array([0.2, 0.45, 0.7, 0.95])
    e, e_avg = albedo.ggx_albedo(m, mus, len(mus))
    want = [_ggx_albedo_by_quadrature(a, mu) for mu in mus]
    np.testing.assert_allclose(e, want, atol=4e-3)
    x, w = np.polynomial.legendre.leggauss(12)
    mu = 0.5 * (x + 1.0)
    mean = float(np.sum(0.5 * w * 2.0 * mu * [_ggx_albedo_by_quadrature(a, v, 300, 120) for v in mu]))
    np.testing.assert_allclose(e_avg, mean, atol=4e-3)
    assert np.all(e_avg == e_avg[0])                     # a material's, not a view's


@pytest.mark.parametrize("r", [0.1, 0.4, 0.9])
def test_multiscatter_of_a_white_lobe_restores_the_lost_energy(r):
    """Fresnel 1, white: k = 1 + F_ms (1 - E) / E with F_ms = 1, so E k = 1 at every view
    (a white furnace); for a colour c the main factor is 1 + F_ms (1 - E) / E with
    F_ms = c E_avg / (1 - c (1 - E_avg))."""
    mus = np.linspace(0.05, 1.0, 9)
    white = reflectance.SGMaterial(model="GGX", roughness=r * r, specular=(1.0, 1.0, 1.0),
                                   multiscatter=True)
    e, e_avg = albedo.ggx_albedo(white, mus, len(mus))
    k_main, _ = albedo.multiscatter_factors(white, mus, len(mus))
    np.testing.assert_allclose(k_main * e[:, None], 1.0, rtol=1e-9)
    c = np.array([0.9, 0.5, 0.1])
    tinted = reflectance.SGMaterial(model="GGX", roughness=r * r, specular=c, multiscatter=True)
    k_main, _ = albedo.multiscatter_factors(tinted, mus, len(mus))
    fms = c * e_avg[:, None] / (1.0 - c * (1.0 - e_avg[:, None]))
    np.testing.assert_allclose(k_main, 1.0 + fms * ((1.0 - e) / e)[:, None], rtol=1e-12)
    assert np.all(k_main[:, 0] > k_main[:, 2])           # a brighter colour gains more


def _fresnel_dielectric(c, eta):
    """The exact unpolarised Fresnel reflectance of a dielectric (no total reflection for
    eta > 1)."""
    g = np.sqrt(eta * eta - 1.0 + c * c)
    return 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + ((c * (g + c) - 1.0) / (c * (g - c) + 1.0)) ** 2)


def _hemispherical_mean(f):
    """2 int_0^1 f(mu) mu dmu by Gauss-Legendre."""
    x, w = np.polynomial.legendre.leggauss(64)
    mu = 0.5 * (x + 1.0)
    return float(np.sum(0.5 * w * 2.0 * mu * f(mu)))


def test_mean_fresnel_of_each_mode_is_its_hemispherical_average():
    """F_ss is the cosine-weighted mean of the lobe's Fresnel over views: Schlick's
    F0 + (1 - F0)/21 (exact), the dielectric's mean as Cycles approximates it (Kulla & Conty
    2017's (eta - 1) / (4.08567 + 1.00071 eta), within 10 % of the exact mean), times ks;
    the Principled dielectric's remap of it to F0 and the metal's Schlick with F0 = base."""
    q = _hemispherical_mean(lambda mu: (1.0 - mu) ** 5)
    assert q == pytest.approx(1.0 / 21.0, rel=1e-12)
    ks = np.array([0.04, 0.3, 0.9])
    schlick = reflectance.SGMaterial(fresnel="SCHLICK", specular=ks)
    np.testing.assert_allclose(albedo.multiscatter_fss(schlick, 1)[0][0], ks + (1 - ks) * q)
    for eta in (1.33, 1.5, 2.4):
        exact = _hemispherical_mean(lambda mu: _fresnel_dielectric(mu, eta))
        fss = (eta - 1.0) / (4.08567 + 1.00071 * eta)
        assert fss == pytest.approx(exact, rel=0.1)
        diel = reflectance.SGMaterial(fresnel="DIELECTRIC", specular=(1.0, 0.5, 0.25), ior=eta)
        np.testing.assert_allclose(albedo.multiscatter_fss(diel, 1)[0][0],
                                   fss * np.array([1.0, 0.5, 0.25]), rtol=1e-5)
        f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
        base = np.array([0.8, 0.4, 0.1])
        principled = reflectance.SGMaterial(fresnel="PRINCIPLED", specular=(0.1, 0.2, 0.3),
                                            ior=eta, diffuse=base)
        main, metal = albedo.multiscatter_fss(principled, 1)
        s = (fss - f0) / (1.0 - f0)
        np.testing.assert_allclose(main[0], 0.1 * np.array([1.0, 2.0, 3.0]) * (1.0 - s) + s,
                                   rtol=1e-5)
        np.testing.assert_allclose(metal[0], base + (1.0 - base) * q, rtol=1e-12)


def test_metal_fresnel_is_schlick_with_the_base_colour():
    base = np.array([0.9, 0.6, 0.3])
    m = reflectance.SGMaterial(fresnel="PRINCIPLED", diffuse=base, metallic=0.75)
    c = np.array([[0.0, 0.5, 1.0]])                       # (P, K)
    got = albedo.metal_fresnel(m, c, 1)
    want = 0.75 * (base + (1.0 - base) * ((1.0 - c[0]) ** 5)[:, None])
    np.testing.assert_allclose(got[0], want, rtol=1e-12)
    np.testing.assert_allclose(got[0, 2], 0.75 * base)    # at normal incidence: F0


@pytest.mark.parametrize("roughness, metallic", [(0.3, 0.0), (0.6, 0.5), (0.09, 0.2)])
def test_view_ratio_averages_to_one_over_views(roughness, metallic):
    """diffuse_view_ratio is the layering weight over its cosine-weighted mean: its own
    cosine-weighted mean over views is 1 (kd keeps the base's energy over all views), to the
    precision of the module's 16-node mean."""
    cm = materials.principled_material(base_color=(0.8, 0.8, 0.8), metallic=metallic,
                                       roughness=roughness)
    sm = sg_brdf.sg_material_from_brdf(cm)
    assert _hemispherical_mean(lambda mu: albedo.diffuse_view_ratio(sm, mu)) == \
        pytest.approx(1.0, abs=5e-4)
    ratio = albedo.diffuse_view_ratio(sm, np.array([1.0, 0.5, 0.05]))
    assert ratio[0] > ratio[1] > ratio[2]                  # the layer takes more at grazing
