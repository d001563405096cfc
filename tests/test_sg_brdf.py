"""SG reflectance (core/sg_brdf.py, paper 003 §4) against quadrature of the analytic BRDFs."""

import math

import numpy as np
import pytest

from prt_relight.core import brdf, sg, sg_brdf
from prt_relight.core.directions import fibonacci_sphere, orthonormal_frame

_FIB = fibonacci_sphere(120_000)
_FIB_W = 4.0 * math.pi / len(_FIB)

# lighting for the BRDF integrals: a constant plus three coloured SG lights
_LIGHT_AXES = np.array([[0.3, 0.2, 0.93], [-0.5, 0.4, 0.77], [0.8, -0.1, 0.6]])
_LIGHT_AXES /= np.linalg.norm(_LIGHT_AXES, axis=1, keepdims=True)
_LIGHT_LAM = np.array([30.0, 8.0, 60.0])
_LIGHT_MU = np.array([1.0, 2.0, 0.5])


def _lighting(dirs):
    return 0.1 + sum(sg.evaluate(dirs, _LIGHT_AXES[j], _LIGHT_LAM[j], _LIGHT_MU[j]) for j in range(3))


def _views(degrees, azimuth=0.0):
    th = np.radians(np.asarray(degrees, dtype=np.float64))
    return np.stack([np.sin(th) * math.cos(azimuth), np.sin(th) * math.sin(azimuth), np.cos(th)], 1)


def _lobe_sum(axes, lam, mu, dirs):
    """(P, D, 3) value of the SG mixture at dirs."""
    d2 = np.sum((dirs[None, None] - axes[:, :, None]) ** 2, axis=-1)        # (P, K, D)
    return np.einsum("pkd,pkc->pdc", np.exp(-0.5 * lam[:, :, None] * d2), mu)


def _integrals(material, views, tangents=None):
    """(sg, exact) of int rho_s(o, i) max(0, n.i) L(i) di per view, (P, 3) each."""
    P = len(views)
    n = np.tile([0.0, 0.0, 1.0], (P, 1))
    L = _lighting(_FIB)
    cos = np.maximum(_FIB[:, 2], 0.0)
    ax, lam, mu = sg_brdf.specular_lobes(material, n, views, tangents)
    got = np.einsum("pdc,d->pc", _lobe_sum(ax, lam, mu, _FIB), cos * L) * _FIB_W
    ref = np.einsum("pdc,d->pc", sg_brdf.specular_brdf(material, n, views, _FIB, tangents),
                    cos * L) * _FIB_W
    return got, ref


def _rel_l2(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# --------------------------------------------------------------------------- NDF fits

def test_isotropic_table_is_the_least_squares_fit():
    for model in sg_brdf.ISOTROPIC_MODELS:
        c_lam, c_mu = sg_brdf.iso_table_fit(model)
        t_lam, t_mu = sg_brdf.ISO_NDF_TABLE[model]
        assert np.allclose(c_lam, t_lam, rtol=2e-6, atol=2e-7), model
        assert np.allclose(c_mu, t_mu, rtol=2e-6, atol=2e-7), model


def _ndf_rel_error_fib(material):
    """||D* - D|| / ||D|| over the hemisphere by a Fibonacci lattice concentrated
    on a cap (independent of the module's quadrature)."""
    f = sg_brdf.ndf_lobes(material)
    # cap around n holding the NDF: rotate a dense Fibonacci set into cos >= c0
    c0 = 0.55
    u = fibonacci_sphere(200_000)
    z = c0 + (1.0 - c0) * (u[:, 2] + 1.0) / 2.0          # uniform in z on [c0, 1]
    r = np.sqrt(1.0 - z * z)
    phi = np.arctan2(u[:, 1], u[:, 0])
    h = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    w = 2.0 * math.pi * (1.0 - c0) / len(h)
    d = sg_brdf.ndf_value(material.model, h, material.roughness, material.aniso_params())
    g = sum(sg.evaluate(h, f.axes[k], f.lam[k], f.mu[k]) for k in range(len(f.lam)))
    return math.sqrt(np.sum((g - d) ** 2) * w / (np.sum(d * d) * w)), f


@pytest.mark.parametrize("model,params,max_err", [
    ("COOK_TORRANCE", dict(roughness=0.1), 0.005),
    ("COOK_TORRANCE", dict(roughness=0.3), 0.04),
    ("BLINN_PHONG", dict(roughness=0.3), 0.015),
    ("WARD", dict(roughness=0.3), 0.03),
    ("WARD_ANISO", dict(alpha_x=0.3, alpha_y=0.1), 0.05),
    ("WARD_ANISO", dict(alpha_x=0.1, alpha_y=0.35), 0.05),
    ("ASHIKHMIN_SHIRLEY", dict(nu=75.0, nv=1200.0), 0.05),
])
def test_ndf_fit_error_by_independent_quadrature(model, params, max_err):
    mat = sg_brdf.SGMaterial(model=model, **params)
    err, fit = _ndf_rel_error_fib(mat)
    print(f"NDF fit {model} {params}: {len(fit.lam)} lobes, rel L2 {err:.4f} "
          f"(module's own estimate {fit.rel_error:.4f})")
    assert err <= max_err
    assert abs(err - fit.rel_error) <= 0.1 * err + 2e-4
    assert len(fit.lam) <= sg_brdf.MAX_LOBES
    if model == "ASHIKHMIN_SHIRLEY":
        assert len(fit.lam) == 7          # Fig. 2 (e): 7 lobes for nu = 75, nv = 1200


def test_sharp_ndf_lobe_normalised_like_the_analytic_ndf():
    # alpha = ALPHA_MIN -> lam ~ 8e4: int D (n.h) dh = 1 (Beckmann), and the lobe integral agrees
    for a in (sg_brdf.ALPHA_MIN, 0.01, 0.03):
        lam, mu = sg_brdf.iso_ndf_sg("COOK_TORRANCE", a)
        # int G (n.h) dh over the hemisphere, closed form in 1-D: 2 pi mu int_0^1 e^{lam(c-1)} c dc
        x, w = np.polynomial.legendre.leggauss(200)
        cmin = max(0.0, 1.0 - 60.0 / lam)
        c = cmin + (1.0 - cmin) * (x + 1) / 2
        val = 2 * math.pi * mu * np.sum(w * np.exp(lam * (c - 1)) * c) * (1.0 - cmin) / 2
        assert abs(val - 1.0) < 2e-3, (a, val)


# --------------------------------------------------------------------------- analytic twin

def test_specular_brdf_is_cycles_glossy_beckmann():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, _ = orthonormal_frame(n)
    v = n * 0.6 + t * 0.8
    dirs = fibonacci_sphere(500)
    cm = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.7, 0.5, 0.2), roughness=0.4,
                       distribution="BECKMANN")
    ref = brdf.reflectance_cosine(cm, n, v, dirs)
    ours = sg_brdf.specular_brdf(sg_brdf.sg_material_from_brdf(cm), n, v, dirs)
    ours = ours * np.maximum(n @ dirs.T, 0)[..., None]
    assert np.allclose(ours, ref, rtol=2e-5, atol=1e-6)


def test_fresnel_eq14_matches_cycles_dielectric():
    c = np.linspace(0.0, 1.0, 101)
    for eta in (1.1, 1.33, 1.5, 2.4, 0.7):
        assert np.allclose(sg_brdf.fresnel_eq14(c, eta), brdf.fresnel_dielectric(c, eta), atol=1e-12)


def test_principled_fresnel_coefficients_reproduce_cycles_remap():
    m = brdf.principled_material(base_color=(0.8, 0.3, 0.1), metallic=0.4, roughness=0.3, ior=1.45)
    s = sg_brdf.sg_material_from_brdf(m)
    c = np.linspace(0.01, 1.0, 50)
    got = sg_brdf._fresnel(s, c)
    f0 = np.asarray(m.specular_color)
    diel = f0 + (1 - f0) * brdf._dielectric_s(c, m.ior)[:, None]
    metal = brdf.fresnel_f82(c, np.clip(m.diffuse_albedo, 0, 1), np.zeros(3))
    ref = (1 - m.metallic) * diel + m.metallic * metal
    assert np.allclose(got, ref, atol=1e-9)


# --------------------------------------------------------------------------- view slices

MODEL_CASES = [
    ("COOK_TORRANCE", dict(roughness=0.09), 0.03),
    ("COOK_TORRANCE", dict(roughness=0.3), 0.10),
    ("BLINN_PHONG", dict(roughness=0.3), 0.10),
    ("WARD", dict(roughness=0.1), 0.05),
    ("WARD_ANISO", dict(alpha_x=0.3, alpha_y=0.1), 0.05),
    ("ASHIKHMIN_SHIRLEY", dict(nu=75.0, nv=1200.0), 0.05),
]


@pytest.mark.parametrize("model,params,max_err", MODEL_CASES)
def test_specular_lobes_integrate_like_the_brdf(model, params, max_err):
    """int rho_s cos L by quadrature: SG view slice (eq. 22) vs the analytic BRDF,
    views 0-70 deg, two azimuths (anisotropic models see the tangent)."""
    mat = sg_brdf.SGMaterial(model=model, specular=(1.0, 0.8, 0.5), **params)
    views = np.vstack([_views([0, 20, 40, 60, 70]), _views([30, 60], azimuth=1.0)])
    tangents = np.tile([math.cos(0.3), math.sin(0.3), 0.0], (len(views), 1))
    got, ref = _integrals(mat, views, tangents)
    err = _rel_l2(got, ref)
    print(f"{model} {params}: rel L2 of int rho_s cos L over views 0-70 deg: {err:.4f}; "
          f"per view ratio {np.round(got[:, 0] / ref[:, 0], 3)}")
    assert err <= max_err


def test_grazing_views_stay_finite_and_bounded():
    views = _views([80, 85, 89, 89.99, 90.0, 95.0])
    for model, params, _ in MODEL_CASES:
        mat = sg_brdf.SGMaterial(model=model, **params)
        n = np.tile([0.0, 0.0, 1.0], (len(views), 1))
        ax, lam, mu = sg_brdf.specular_lobes(mat, n, views)
        assert np.all(np.isfinite(ax)) and np.all(np.isfinite(lam)) and np.all(np.isfinite(mu))
        assert np.all(lam > 0) and np.all(lam <= sg_brdf.LAMBDA_MAX) and np.all(mu >= 0)
        got, ref = _integrals(mat, views[:3])
        print(f"{model} {params}: SG/exact at 80, 85, 89 deg: {np.round(got[:, 0] / ref[:, 0], 3)}")
        # near the horizon the isotropic warp loses energy (§4.3 says so): measured
        # down to 0.26 at 85 deg and 0.06 at 89 deg (Cook-Torrance a = 0.09)
        assert np.all(got[:, 0] <= 2.0 * ref[:, 0] + 1e-6), model
        assert np.all(got[:2, 0] >= 0.2 * ref[:2, 0]), model


def test_cycles_glossy_beckmann_03_within_6_percent():
    """The issue's target: Cycles' Glossy BSDF (Beckmann, roughness 0.3) through
    sg_material_from_brdf, against core.brdf (Cycles' evaluation) by quadrature,
    views 0-80 deg, the SG clamped cosine of eq. 40 NOT used (exact cosine)."""
    cm = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.8, 0.8), roughness=0.3,
                       distribution="BECKMANN")
    views = _views([0, 15, 30, 45, 60, 70, 80])
    n = np.tile([0.0, 0.0, 1.0], (len(views), 1))
    L = _lighting(_FIB)
    ref = np.einsum("pdc,d->pc", brdf.reflectance_cosine(cm, n, views, _FIB), L) * _FIB_W
    ax, lam, mu = sg_brdf.specular_lobes(sg_brdf.sg_material_from_brdf(cm), n, views)
    got = np.einsum("pdc,d->pc", _lobe_sum(ax, lam, mu, _FIB), np.maximum(_FIB[:, 2], 0) * L) * _FIB_W
    err = _rel_l2(got, ref)
    print(f"Cycles Glossy Beckmann r=0.3: rel L2 {err:.4f}")
    assert err <= 0.06


def test_principled_default_surface_error():
    """Cycles' default surface (Principled, Multiscatter GGX, r = 0.5) mapped to
    Cook-Torrance/Beckmann: total (diffuse + specular) error by quadrature."""
    cm = brdf.principled_material()
    sm = sg_brdf.sg_material_from_brdf(cm)
    views = _views([0, 30, 60, 75])
    n = np.tile([0.0, 0.0, 1.0], (len(views), 1))
    L = _lighting(_FIB)
    cos = np.maximum(_FIB[:, 2], 0)
    ref = np.einsum("pdc,d->pc", brdf.reflectance_cosine(cm, n, views, _FIB), L) * _FIB_W
    ax, lam, mu = sg_brdf.specular_lobes(sm, n, views)
    spec = np.einsum("pdc,d->pc", _lobe_sum(ax, lam, mu, _FIB), cos * L) * _FIB_W
    diff = sg_brdf.diffuse_albedo(sm)[None, :] / math.pi * np.sum(cos * L) * _FIB_W
    err = _rel_l2(spec + diff, ref)
    print(f"Principled default: rel L2 {err:.4f}")
    # measured 0.093: GGX drawn with a Beckmann NDF, multiscatter energy dropped
    assert err <= 0.10


def test_textured_parameters_match_per_point_materials():
    rough = np.array([0.05, 0.2, 0.5])
    ks = np.array([[1, 0, 0], [0, 1, 0], [0.2, 0.3, 0.4]], float)
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    v = _views([10, 40, 70])
    tex = sg_brdf.SGMaterial(model="COOK_TORRANCE", roughness=rough, specular=ks,
                             fresnel="DIELECTRIC", ior=np.array([1.3, 1.5, 2.0]))
    ax, lam, mu = sg_brdf.specular_lobes(tex, n, v)
    for p in range(3):
        one = sg_brdf.SGMaterial(model="COOK_TORRANCE", roughness=rough[p], specular=ks[p],
                                 fresnel="DIELECTRIC", ior=[1.3, 1.5, 2.0][p])
        a1, l1, m1 = sg_brdf.specular_lobes(one, n[p:p + 1], v[p:p + 1])
        assert np.allclose(ax[p], a1[0]) and np.allclose(lam[p], l1[0]) and np.allclose(mu[p], m1[0])


def test_bad_input_is_reported():
    with pytest.raises(ValueError):
        sg_brdf.SGMaterial(roughness=float("nan"))
    with pytest.raises(ValueError):
        sg_brdf.SGMaterial(model="PHONG")
    with pytest.raises(ValueError):
        sg_brdf.specular_lobes(sg_brdf.SGMaterial(), [[0, 0, 1]], [[np.inf, 0, 1]])


def test_diffuse_albedo_split():
    m = sg_brdf.SGMaterial(diffuse=(0.5, 0.4, 0.3))
    assert np.allclose(sg_brdf.diffuse_albedo(m), (0.5, 0.4, 0.3))
    cm = brdf.principled_material(base_color=(0.8, 0.8, 0.8), metallic=0.25)
    sm = sg_brdf.sg_material_from_brdf(cm)
    n = np.tile([0.0, 0.0, 1.0], (64, 1))
    mu = (np.arange(64) + 0.5) / 64
    v = np.stack([np.sqrt(1 - mu * mu), 0 * mu, mu], 1)
    w = brdf.diffuse_view_weight(cm, n, v)[:, 0]
    mean = 2.0 * np.sum(w * mu) / 64          # cosine-weighted mean over views
    assert np.allclose(sg_brdf.diffuse_albedo(sm), 0.8 * mean, rtol=5e-3)
