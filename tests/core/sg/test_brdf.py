"""core.sg.brdf (Wang et al. 2009, §4): SG BRDFs and their view slices against quadrature of
the analytic BRDFs and of Cycles' (core.shading.brdf), Fresnel (eq. 14, the Principled
remap), grazing views, textured parameters, near-mirror lobes and the GGX slice drawn on an
open surface.  No bpy."""

import math

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sg import algebra as sg, brdf as sg_brdf
from prt_relight.core.sg import albedo
from prt_relight.core.sg import reflectance
from prt_relight.core.sphere.directions import fibonacci_sphere, orthonormal_frame


_FIB = fibonacci_sphere(120_000)
_FIB_W = 4.0 * math.pi / len(_FIB)

# lighting for the BRDF integrals: a constant plus three coloured SG lights
_LIGHT_AXES = np.array([[0.3, 0.2, 0.93], [-0.5, 0.4, 0.77], [0.8, -0.1, 0.6]])
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


# --------------------------------------------------------------------------- analytic twin

def test_specular_brdf_is_cycles_glossy_beckmann():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t, _ = orthonormal_frame(n)
    v = n * 0.6 + t * 0.8
    dirs = fibonacci_sphere(500)
    cm = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.7, 0.5, 0.2), roughness=0.4,
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
    m = materials.principled_material(base_color=(0.8, 0.3, 0.1), metallic=0.4, roughness=0.3, ior=1.45)
    s = sg_brdf.sg_material_from_brdf(m)
    c = np.linspace(0.01, 1.0, 50)
    got = sg_brdf.ks_fresnel(s, c)
    f0 = np.asarray(m.specular_color)
    diel = f0 + (1 - f0) * brdf.dielectric_s(c, m.ior)[:, None]
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
    mat = reflectance.SGMaterial(model=model, specular=(1.0, 0.8, 0.5), **params)
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
        mat = reflectance.SGMaterial(model=model, **params)
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
    """The target: Cycles' Glossy BSDF (Beckmann, roughness 0.3) through
    sg_material_from_brdf, against core.shading.brdf (Cycles' evaluation) by quadrature,
    views 0-80 deg, the SG clamped cosine of eq. 40 NOT used (exact cosine)."""
    cm = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.8, 0.8), roughness=0.3,
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
    """Cycles' default surface (Principled, Multiscatter GGX, r = 0.5) mapped to the GGX
    lobes: total (diffuse + specular) error by quadrature."""
    cm = materials.principled_material()
    sm = sg_brdf.sg_material_from_brdf(cm)
    views = _views([0, 30, 60, 75])
    n = np.tile([0.0, 0.0, 1.0], (len(views), 1))
    L = _lighting(_FIB)
    cos = np.maximum(_FIB[:, 2], 0)
    ref = np.einsum("pdc,d->pc", brdf.reflectance_cosine(cm, n, views, _FIB), L) * _FIB_W
    ax, lam, mu = sg_brdf.specular_lobes(sm, n, views)
    spec = np.einsum("pdc,d->pc", _lobe_sum(ax, lam, mu, _FIB), cos * L) * _FIB_W
    diff = albedo.diffuse_albedo(sm)[None, :] / math.pi * np.sum(cos * L) * _FIB_W
    err = _rel_l2(spec + diff, ref)
    print(f"Principled default: rel L2 {err:.4f}")
    # measured 0.062 (0.093 with the Beckmann lobe of the same alpha, no multiscatter)
    assert err <= 0.07


def test_textured_parameters_match_per_point_materials():
    rough = np.array([0.05, 0.2, 0.5])
    ks = np.array([[1, 0, 0], [0, 1, 0], [0.2, 0.3, 0.4]], float)
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    v = _views([10, 40, 70])
    tex = reflectance.SGMaterial(model="COOK_TORRANCE", roughness=rough, specular=ks,
                             fresnel="DIELECTRIC", ior=np.array([1.3, 1.5, 2.0]))
    ax, lam, mu = sg_brdf.specular_lobes(tex, n, v)
    for p in range(3):
        one = reflectance.SGMaterial(model="COOK_TORRANCE", roughness=rough[p], specular=ks[p],
                                 fresnel="DIELECTRIC", ior=[1.3, 1.5, 2.0][p])
        a1, l1, m1 = sg_brdf.specular_lobes(one, n[p:p + 1], v[p:p + 1])
        assert np.allclose(ax[p], a1[0]) and np.allclose(lam[p], l1[0]) and np.allclose(mu[p], m1[0])


def _cap(axis, theta_max, n_theta=128, n_phi=128):
    """Directions and weights of a cap around ``axis`` (GL in theta, 4 panels; midpoint in phi)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    x, w = np.polynomial.legendre.leggauss(n_theta // 4)
    edges = np.linspace(0.0, theta_max, 5)
    th = np.concatenate([(edges[i] + edges[i + 1]) / 2 + (edges[i + 1] - edges[i]) / 2 * x for i in range(4)])
    wt = np.concatenate([(edges[i + 1] - edges[i]) / 2 * w for i in range(4)]) * np.sin(th)
    ph = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    d = (np.sin(th)[:, None, None] * (np.cos(ph)[None, :, None] * t + np.sin(ph)[None, :, None] * b)
         + np.cos(th)[:, None, None] * axis)
    return d.reshape(-1, 3), np.repeat(wt, n_phi) * (2 * math.pi / n_phi)


@pytest.mark.parametrize("alpha", [sg_brdf.SG_ALPHA_MIN, 0.01, 0.03])
def test_sharp_lobes_lambda_1e4_to_1e5_by_cap_quadrature(alpha):
    """Near-mirror Cook-Torrance (NDF sharpness 2/a^2 = 8e4 .. 2e3; warped lobes up to
    the 1e5 cap at grazing): SG view slice vs the analytic BRDF, both integrated
    against the smooth lighting by quadrature on a cap around the mirror direction."""
    mat = reflectance.SGMaterial(model="COOK_TORRANCE", roughness=alpha, specular=(1.0, 1.0, 1.0))
    n = np.array([[0.0, 0.0, 1.0]])
    for deg in (0.0, 45.0, 70.0, 88.0):
        o = _views([deg])
        ax, lam, mu = sg_brdf.specular_lobes(mat, n, o)
        assert 500.0 <= lam[0, 0] <= sg_brdf.LAMBDA_MAX
        r = ax[0, 0]
        d, w = _cap(r, min(0.5 * math.pi, 12.0 * alpha / max(math.cos(math.radians(deg)), 0.2)))
        keep = d[:, 2] > 0
        L = _lighting(d)
        cos = np.maximum(d[:, 2], 0.0)
        ref = np.sum(sg_brdf.specular_brdf(mat, n, o, d)[0, :, 0] * cos * L * w)
        g = mu[0, 0, 0] * np.exp(-0.5 * lam[0, 0] * np.sum((d - r) ** 2, axis=1))
        got = np.sum(g * cos * L * w * keep)
        # the SG's own integral over the sphere is known in closed form (eq. 4 with lam2 = 0)
        full = np.sum(g * w)
        assert abs(full - sg.integral(lam[0, 0], mu[0, 0, 0])) < 2e-5 * full
        print(f"a={alpha} view {deg}: lam_W {lam[0, 0]:.0f}, SG/exact {got / ref:.4f}")
        # 88 deg: a = 0.005 hits the LAMBDA_MAX cap (warp 5.7e5), the lobe keeps its energy
        assert abs(got / ref - 1.0) < (0.02 if deg < 60 else 0.06 if deg < 80 else 0.25)


class _OpenHemisphere:
    """An SSDF field of open points: the elevation over the horizon (core.methods.ssdf_sg.ssdf)."""

    def theta_d(self, rows, local):
        return np.arcsin(np.clip(np.asarray(local)[..., 2], -1.0, 1.0))

    def theta_d_slopes(self, rows, local, e1, e2):
        z = np.clip(np.asarray(local)[..., 2], -1.0, 1.0)
        root = np.sqrt(np.maximum(1.0 - z * z, 1e-12))
        return self.theta_d(rows, local), e1[..., 2] / root, e2[..., 2] / root


@pytest.mark.parametrize("r", [0.3, 0.7, 1.0])
def test_ggx_slice_returns_E_as_drawn_on_an_open_surface(r):
    """With ``horizon`` the GGX slice drawn by eq. 41 (the 7-lobe cosine mixture, each
    product cut by an open hemisphere's visibility, a white sky) returns Cycles' E(r, n.o)
    (Fresnel 1, no multiscatter): the normalisation counts what is drawn.  Without it the
    products below the horizon count toward E and are then cut: darker (measured at
    0 / 30 / 60 / 80 / 88 deg: r 0.3 1.00 / 1.00 / 0.97 / 0.87 / 0.78, r 0.7 0.98 / 0.98 /
    0.97 / 0.97 / 0.97, r 1.0 0.98 / 0.97 / 0.97 / 0.97 / 0.96)."""
    from prt_relight.core.methods.ssdf_sg import shading as ssdf_sg
    cosine = ssdf_sg.COSINE_SG7
    mat = reflectance.SGMaterial(model="GGX", roughness=r * r, specular=(1.0, 1.0, 1.0),
                             fresnel="NONE", multiscatter=False)
    deg = np.array([0.0, 30.0, 60.0, 80.0, 88.0])
    n = np.tile([0.0, 0.0, 1.0], (len(deg), 1))
    o = np.stack([np.sin(np.radians(deg)), 0 * deg, np.cos(np.radians(deg))], 1)
    t, b = ssdf_sg.ssdf_frames(n)
    E, _ = albedo.ggx_albedo(mat, o[:, 2], len(deg))

    def drawn(horizon):
        lobes = sg_brdf.specular_lobes(mat, n, o, cosine=cosine, cosine_frame=(t, b),
                                       horizon=horizon)
        return ssdf_sg.specular_radiance(_OpenHemisphere(), np.arange(len(deg)), n, *lobes,
                                         lambda d, lam: np.repeat(sg.integral(lam)[:, None], 3, 1),
                                         t, b, cosine=cosine)[:, 0]

    np.testing.assert_allclose(drawn(True), E, rtol=1e-6)
    without = drawn(False) / E
    assert np.all(without < 1.0 + 1e-9) and without.min() < 0.97, (without, r)
