# SPDX-License-Identifier: GPL-3.0-or-later
"""core.shading.brdf (Cycles' Lambert and microfacet lobes, the Principled BSDF's layering)
by quadrature on the sphere and hemisphere: Lambert's albedo, the Cycles transcription,
reciprocity, directional albedo, finite values everywhere, Fresnel conventions, energy
conservation, the F82 tint, the specular terms, and the lobes too sharp for the cubemap.
No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import brdf, brdf_tables, materials

from .quadrature import (CYCLES_TABLE_GGX_E, DISTS, N_UP, fibonacci_sphere, hemisphere_grid,
                         lobe_integral, view_at)


# --------------------------------------------------------------------------- #
# quadrature helpers
# --------------------------------------------------------------------------- #


# --------------------------------------------------------------------------- #
# Lambert
# --------------------------------------------------------------------------- #

def test_lambert_hemisphere_integral_is_albedo():
    dirs = fibonacci_sphere(400_000)
    w = np.full(dirs.shape[0], 4.0 * np.pi / dirs.shape[0])
    albedo = (0.8, 0.5, 0.2)
    mat = materials.Material(diffuse_albedo=albedo)
    assert mat.is_diffuse_only and mat.has_diffuse
    views = np.concatenate([view_at(0), view_at(60, 30), view_at(89.9)])
    got = lobe_integral(mat, views, dirs, w)
    np.testing.assert_allclose(got, np.tile(albedo, (3, 1)), rtol=2e-4)


def test_lambert_ignores_view_side():
    # Cycles' diffuse closure only tests the light side.
    mat = materials.Material(diffuse_albedo=(1.0, 1.0, 1.0))
    dirs = np.array([[0.0, 0.6, 0.8]])
    a = brdf.reflectance_cosine(mat, N_UP, view_at(10), dirs)
    b = brdf.reflectance_cosine(mat, N_UP, -view_at(10), dirs)
    np.testing.assert_allclose(a, 0.8 / np.pi, rtol=1e-6)
    np.testing.assert_allclose(b, a)


# --------------------------------------------------------------------------- #
# agreement with a direct transcription of Cycles' bsdf_microfacet_eval
# --------------------------------------------------------------------------- #

def _cycles_eval_reference(dist, alpha, N, wview, wlight):
    """Scalar transcription of bsdf_microfacet_eval (Cycles wi = view,
    wo = light), reflection only, F = 1.  Returns eval (= f * cos_light)."""
    cos_NI = float(np.dot(N, wview))
    cos_NO = float(np.dot(N, wlight))
    if cos_NI <= 0 or cos_NO < 0:
        return 0.0
    H = wview + wlight
    H = H / np.linalg.norm(H)
    cos_NH = float(np.dot(N, H))
    a2 = alpha * alpha
    c2 = min(cos_NH * cos_NH, 1.0)
    if dist == "BECKMANN":
        with np.errstate(over="ignore"):
            D = 1.0 / (np.exp((1 - c2) / (c2 * a2)) * np.pi * a2 * c2 * c2)
    else:
        D = a2 / (np.pi * ((1 - c2) + a2 * c2) ** 2)

    def lam(cos_N):
        t2 = a2 * max(1.0 / cos_N ** 2 - 1.0, 0.0)
        if dist == "GGX":
            return 0.5 * (np.sqrt(1.0 + t2) - 1.0)
        if t2 < 0.39:
            return 0.0
        a = 1.0 / np.sqrt(t2)
        return ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a)

    common = D / cos_NI * 0.25
    return common / (1.0 + lam(cos_NO) + lam(cos_NI))


@pytest.mark.parametrize("dist", DISTS)
def test_matches_cycles_transcription(dist):
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(6, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # views within 80 deg of their normal
    views = []
    for n in normals:
        while True:
            v = rng.normal(size=3)
            v /= np.linalg.norm(v)
            if np.dot(v, n) > 0.17:
                views.append(v)
                break
    views = np.array(views)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for r in (0.2, 0.45, 0.8, 1.0):
        mat = materials.Material(specular_color=(1, 1, 1), roughness=r, distribution=dist)
        got = brdf.specular_cosine(mat, normals, views, dirs)
        ref = np.array([[_cycles_eval_reference(dist, r * r, n, v, l) for l in dirs]
                        for n, v in zip(normals, views)])
        assert np.count_nonzero(ref) > 200
        np.testing.assert_allclose(got, ref, rtol=2e-5, atol=1e-7)


# --------------------------------------------------------------------------- #
# reciprocity
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("fresnel", ["NONE", "SCHLICK"])
def test_reciprocity(dist, fresnel):
    rng = np.random.default_rng(7)

    def upper(k):
        v = rng.normal(size=(k, 3))
        v[:, 2] = np.abs(v[:, 2]) + 0.1
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    a, b = upper(40), upper(50)
    mat = materials.Material(diffuse_albedo=(0.3, 0.2, 0.1), specular_color=(0.9, 0.5, 0.04),
                        roughness=0.4, distribution=dist, fresnel=fresnel)
    # f(wi = b_d, wo = a_p) and f(wi = a_p, wo = b_d)
    f_ab = brdf.reflectance_cosine(mat, np.repeat(N_UP, 40, 0), a, b) / b[None, :, 2, None]
    f_ba = brdf.reflectance_cosine(mat, np.repeat(N_UP, 50, 0), b, a) / a[None, :, 2, None]
    np.testing.assert_allclose(f_ab, np.transpose(f_ba, (1, 0, 2)), rtol=1e-4, atol=1e-7)


# --------------------------------------------------------------------------- #
# energy
# --------------------------------------------------------------------------- #

VIEW_ANGLES = (0.0, 30.0, 60.0, 80.0, 89.0)


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha", [0.1, 0.3, 0.6, 1.0])
def test_glossy_directional_albedo_at_most_one(dist, alpha):
    dirs, w = hemisphere_grid(alpha, 600, 720)
    mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                        roughness=np.sqrt(alpha), distribution=dist)
    views = np.concatenate([view_at(t, 17.0) for t in VIEW_ANGLES])
    E = lobe_integral(mat, views, dirs, w)[:, 0]
    assert np.all(E <= 1.0 + 5e-3), E
    # single scattering loses energy (most at normal incidence for rough GGX:
    # E(mu=1, alpha=1) = 0.307), but never all of it
    assert np.all(E > 0.25), E
    if alpha <= 0.1:
        assert E[0] > 0.95          # G ~ 1 at normal incidence for a smooth lobe
        assert E[0] < 1.0 + 2e-3


def test_ggx_albedo_matches_cycles_table():
    """Integrating our GGX lobe reproduces Cycles' table_ggx_E: this checks D,
    Lambda, G2, the 1/(4 cos_o) factor and alpha = r^2 end to end."""
    for (row, col), ref in CYCLES_TABLE_GGX_E.items():
        mu, r = row / 31.0, col / 31.0
        dirs, w = hemisphere_grid(r * r, 600, 720)
        mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                            roughness=r, distribution="GGX")
        v = np.array([[np.sqrt(1.0 - mu * mu), 0.0, mu]])
        E = lobe_integral(mat, v, dirs, w)[0, 0]
        assert E == pytest.approx(ref, abs=3e-4), (row, col, E, ref)


# --------------------------------------------------------------------------- #
# robustness
# --------------------------------------------------------------------------- #

def _nasty_views():
    out = []
    for c in (1.0, 0.5, 1e-6, 0.0, -1e-6, -0.3, -1.0):
        s = np.sqrt(max(0.0, 1.0 - c * c))
        out.append([s, 0.0, c])
    return np.array(out)


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("fresnel", ["NONE", "SCHLICK"])
@pytest.mark.parametrize("roughness", [0.0, 1e-4, 0.05, 1.0])
def test_finite_everywhere(dist, fresnel, roughness):
    views = _nasty_views()
    normals = np.repeat(N_UP, len(views), axis=0)
    dirs = np.concatenate([
        fibonacci_sphere(2000),
        views,                       # wi == wo
        -views,                      # wi == -wo (degenerate half vector)
        [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 0]],
        views * np.array([-1.0, -1.0, 1.0]),   # mirror directions
    ])
    mat = materials.Material(diffuse_albedo=(0.5, 0.5, 0.5), specular_color=(1.0, 0.5, 0.2),
                        roughness=roughness, distribution=dist, fresnel=fresnel)
    s = brdf.specular_cosine(mat, normals, views, dirs)
    r = brdf.reflectance_cosine(mat, normals, views, dirs)
    assert s.shape == ((len(views), len(dirs), 3) if fresnel == "SCHLICK" else (len(views), len(dirs)))
    assert r.shape == (len(views), len(dirs), 3)
    assert r.dtype == np.float32
    for arr in (s, r):
        assert np.all(np.isfinite(arr))
        assert np.all(arr >= 0.0)
    # zero below the horizon of the light
    below = dirs[:, 2] <= 0.0
    assert np.all(s[:, below] == 0.0)
    assert np.all(r[:, below] == 0.0)


def test_grazing_view_is_continuous():
    # n.wo = 1e-6, 0 and slightly negative views give (nearly) the same lobe
    mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                        roughness=0.5, distribution="GGX")
    views = _nasty_views()[2:5]
    dirs = fibonacci_sphere(5000)
    s = brdf.specular_cosine(mat, np.repeat(N_UP, 3, 0), views, dirs)
    assert s.max() > 0.0
    np.testing.assert_allclose(s[1], s[0], rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(s[2], s[0], rtol=1e-3, atol=1e-6)


def test_schlick_and_colour_conventions():
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(300, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    views = np.concatenate([view_at(20), view_at(70, 50)])
    normals = np.repeat(N_UP, 2, 0)
    plain = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.5, 0.25, 1.0),
                          roughness=0.3, distribution="GGX")
    s = brdf.specular_cosine(plain, normals, views, dirs)
    r = brdf.reflectance_cosine(plain, normals, views, dirs)
    np.testing.assert_allclose(r, s[..., None] * np.array([0.5, 0.25, 1.0], np.float32), rtol=1e-6)
    # Schlick with F0 = 1 is the uncoloured lobe; with F0 < 1 it is >= F0 * lobe
    one = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                        roughness=0.3, distribution="GGX", fresnel="SCHLICK")
    s1 = brdf.specular_cosine(one, normals, views, dirs)
    s_plain1 = brdf.specular_cosine(materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                                                  roughness=0.3, distribution="GGX"),
                                    normals, views, dirs)
    np.testing.assert_allclose(s1, np.repeat(s_plain1[..., None], 3, axis=-1), rtol=1e-6)
    low = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.04, 0.04, 0.04),
                        roughness=0.3, distribution="GGX", fresnel="SCHLICK")
    s04 = brdf.specular_cosine(low, normals, views, dirs)
    assert np.all(s04[..., 0] >= 0.04 * s_plain1 * (1 - 1e-5))
    assert np.all(s04[..., 0] <= s_plain1 * (1 + 1e-5))
    # explicit Schlick factor from an explicitly built half vector
    F0 = 0.04
    h = views[:, None, :] + dirs[None, :, :]
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    h_wi = np.einsum("pdk,dk->pd", h, dirs)
    F = F0 + (1.0 - F0) * (1.0 - h_wi) ** 5
    np.testing.assert_allclose(s04[..., 1], F * s_plain1, rtol=1e-5, atol=1e-9)
    # zero specular colour switches the lobe off in both modes
    off = materials.Material(specular_color=(0, 0, 0), fresnel="SCHLICK")
    assert off.is_diffuse_only
    assert not np.any(brdf.specular_cosine(off, normals, views, dirs))


def _albedo(mat, theta, n_theta=600, n_phi=720):
    alpha = max(mat.alpha, 1e-3)
    dirs, w = hemisphere_grid(alpha, n_theta, n_phi)
    return lobe_integral(mat, view_at(theta, 23.0), dirs, w)[0]


@pytest.mark.parametrize("col,row", [(6, 31), (12, 20), (19, 10), (25, 5), (31, 31), (31, 3)])
def test_multiscatter_glossy_white_furnace(col, row):
    # A white Multiscatter GGX lobe reflects all light: E * (1 + (1 - E) / E) = 1.
    r, mu = col / 31.0, row / 31.0
    mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=r,
                        distribution="MULTI_GGX")
    got = _albedo(mat, np.degrees(np.arccos(mu)))
    np.testing.assert_allclose(got, 1.0, atol=1.5e-3)
    # single-scatter GGX loses exactly 1 - E
    ss = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=r,
                       distribution="GGX")
    assert _albedo(ss, np.degrees(np.arccos(mu)))[0] == pytest.approx(
        brdf_tables.ggx_E_table_column(col)[row], abs=1e-3)


def test_multiscatter_glossy_colour_saturates():
    # Coloured multiscatter lobes gain less than 1/E (Fms < 1): the Kulla-Conty
    # factor 1 + Fms (1 - E) / E, per channel.
    r, mu = 1.0, 0.5
    mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.5, 0.2), roughness=r,
                        distribution="MULTI_GGX")
    k = brdf.multiscatter_factor(mat, [mu])[0]
    E, Ea = brdf.ggx_E(r, mu)[()], brdf.ggx_E_avg(r)
    C = np.array(mat.specular_color)
    Fms = C * Ea / (1.0 - C * (1.0 - Ea))
    np.testing.assert_allclose(k, 1.0 + Fms * (1.0 - E) / E, rtol=1e-12)
    assert np.all(k < 1.0 / E) and np.all(k > 1.0)
    got = _albedo(mat, 60.0)
    np.testing.assert_allclose(got, C * E * k, rtol=2e-3)


PRINCIPLED_ROUGH = (0.0, 0.05, 0.3, 0.5, 0.8, 1.0)


@pytest.mark.parametrize("rough", PRINCIPLED_ROUGH)
def test_principled_energy_conservation(rough):
    # white base: Lambert weight + specular albedo <= 1 at every view, and the
    # layering weight is Cycles' 1 - (albedo estimate of the specular layer).
    mat = materials.principled_material(base_color=(1, 1, 1), roughness=rough)
    for theta in (0.0, 40.0, 66.0, 80.0, 88.0):
        v = view_at(theta, 10.0)
        spec = np.zeros(3)
        quad_ok = rough >= 0.3      # hemisphere_grid resolves off-normal lobes for alpha >~ 0.1
        if quad_ok:
            spec = _albedo(materials.Material(**{**mat.__dict__, "diffuse_albedo": (0, 0, 0)}), theta)
        wd = brdf.diffuse_view_weight(mat, N_UP, v)[0]
        est = brdf.specular_albedo_estimate(mat, [np.cos(np.radians(theta))])[0]
        np.testing.assert_allclose(wd, 1.0 - est.max(), rtol=1e-6)
        assert np.all(wd > 0.0) and np.all(wd <= 1.0)
        assert np.all(wd + spec <= 1.0 + 2e-3), (theta, wd, spec)
        if quad_ok:
            # Cycles' albedo estimate (LUT of the VNDF-mean Fresnel) is close to the
            # true albedo of the layer; it is what the base loses.
            np.testing.assert_allclose(spec, est, rtol=0.08, atol=3e-3)


def test_principled_default_darkens_base_at_grazing_views():
    mat = materials.principled_material()          # Cycles' default surface
    assert mat.fresnel == "DIELECTRIC" and mat.distribution == "MULTI_GGX"
    assert mat.specular_color == pytest.approx((0.04, 0.04, 0.04))
    w = [brdf.diffuse_view_weight(mat, N_UP, view_at(t))[0, 0] for t in (0, 30, 66, 85)]
    assert np.all(np.diff(w) < 0)
    assert w[0] == pytest.approx(0.9626, abs=2e-3)
    assert w[2] == pytest.approx(0.9144, abs=2e-3)
    # a plain Diffuse BSDF has no layering
    lam = materials.Material(diffuse_albedo=(0.8, 0.8, 0.8))
    np.testing.assert_array_equal(brdf.diffuse_view_weight(lam, N_UP, view_at(66)), 1.0)


def test_principled_fresnel_is_remapped_real_fresnel():
    # F = mix(f0 * tint, 1, (F_diel(h.wi) - F0) / (1 - F0)); with tint 1 that is F_diel.
    mat = materials.principled_material(roughness=0.4, distribution="GGX")
    plain = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=0.4,
                          distribution="GGX")
    rng = np.random.default_rng(5)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    views = np.concatenate([view_at(10), view_at(75, 40)])
    normals = np.repeat(N_UP, 2, 0)
    s = brdf.specular_cosine(mat, normals, views, dirs)
    lobe = brdf.specular_cosine(plain, normals, views, dirs)
    h = views[:, None, :] + dirs[None, :, :]
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    F = brdf.fresnel_dielectric(np.einsum("pdk,pk->pd", h, views), 1.5)
    np.testing.assert_allclose(s[..., 0], F * lobe, rtol=1e-5, atol=1e-9)
    # specular tint scales f0 only; metallic blends in the F82 metal lobe
    tinted = materials.principled_material(roughness=0.4, distribution="GGX", specular_tint=(1, 0.5, 0))
    assert tinted.specular_color == pytest.approx((0.04, 0.02, 0.0))
    st = brdf.specular_cosine(tinted, normals, views, dirs)
    assert np.all(st[..., 2] <= st[..., 1] + 1e-9) and np.all(st[..., 1] <= st[..., 0] + 1e-9)
    assert np.all(st[..., 2] >= 0.0) and st[..., 2].max() > 0.0     # F90 = 1 stays
    # the Fresnel curve is the textbook one (s/p average via Snell), not Schlick
    c = np.array([1.0, 0.7, 0.3, 0.1, 0.01])
    ct = np.sqrt(1.0 - (1.0 - c * c) / 1.5 ** 2)
    rs = (c - 1.5 * ct) / (c + 1.5 * ct)
    rp = (1.5 * c - ct) / (1.5 * c + ct)
    np.testing.assert_allclose(brdf.fresnel_dielectric(c, 1.5), 0.5 * (rs ** 2 + rp ** 2),
                               rtol=1e-12)
    assert brdf.fresnel_dielectric(0.3, 1.0 / 1.5) == 1.0          # total internal reflection


def test_f82_tint():
    f0 = np.array([0.9, 0.6, 0.3])
    tint = np.array([1.0, 0.5, 0.0])
    B = brdf.f82_tint_B(f0, tint)
    c82 = 1.0 / 7.0
    schlick = f0 + (1 - f0) * (1 - c82) ** 5
    np.testing.assert_allclose(brdf.fresnel_f82(np.array([c82]), f0, B)[0], schlick * tint,
                               atol=1e-12)
    np.testing.assert_allclose(brdf.fresnel_f82(np.array([1.0]), f0, B)[0], f0)
    np.testing.assert_allclose(brdf.fresnel_f82(np.array([0.0]), f0, B)[0], 1.0)
    # clamped at 0 for dark, untinted metals (the clamped path is used)
    m = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.02, 0.02, 0.02), roughness=0.5,
                      distribution="GGX", fresnel="F82", f82_tint=(0, 0, 0))
    r = brdf.reflectance_cosine(m, N_UP, view_at(45), fibonacci_sphere(2000))
    assert np.all(r >= 0.0) and np.all(np.isfinite(r))


@pytest.mark.parametrize("fresnel,dist", [("DIELECTRIC", "MULTI_GGX"), ("DIELECTRIC", "GGX"),
                                          ("F82", "MULTI_GGX"), ("NONE", "MULTI_GGX"),
                                          ("SCHLICK", "MULTI_GGX")])


@pytest.mark.parametrize("roughness", [0.0, 1e-4, 0.05, 1.0])
def test_new_modes_finite_everywhere(fresnel, dist, roughness):
    views = _nasty_views()
    normals = np.repeat(N_UP, len(views), axis=0)
    dirs = np.concatenate([fibonacci_sphere(1000), views, -views,
                           [[0, 0, 1], [0, 0, -1], [1, 0, 0]],
                           views * np.array([-1.0, -1.0, 1.0])])
    mat = materials.Material(diffuse_albedo=(0.5, 0.5, 0.5), specular_color=(0.9, 0.5, 0.04),
                        roughness=roughness, distribution=dist, fresnel=fresnel,
                        f82_tint=(0.3, 0.8, 1.0), metallic=0.3 if fresnel == "DIELECTRIC" else 0.0)
    s = brdf.specular_cosine(mat, normals, views, dirs)
    r = brdf.reflectance_cosine(mat, normals, views, dirs)
    w = brdf.diffuse_view_weight(mat, normals, views)
    assert s.shape == (len(views), len(dirs), 3) and r.dtype == np.float32
    for arr in (s, r, w):
        assert np.all(np.isfinite(arr)) and np.all(arr >= 0.0)
    assert np.all(w <= 1.0)
    below = dirs[:, 2] <= 0.0
    assert np.all(s[:, below] == 0.0) and np.all(r[:, below] == 0.0)
    # grazing and slightly back-facing views give (nearly) the same result
    np.testing.assert_allclose(w[3], w[2], atol=1e-3)
    np.testing.assert_allclose(w[4], w[2], atol=1e-3)
    if roughness >= 0.05:
        np.testing.assert_allclose(s[3], s[2], rtol=2e-3, atol=1e-5)


def test_principled_single_scatter_is_reciprocal():
    # GGX (no multiscatter factor) with a Fresnel of h.wi only is reciprocal.
    rng = np.random.default_rng(11)

    def upper(k):
        v = rng.normal(size=(k, 3))
        v[:, 2] = np.abs(v[:, 2]) + 0.1
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    a, b = upper(30), upper(40)
    mat = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.04, 0.03, 0.02), roughness=0.4,
                        distribution="GGX", fresnel="DIELECTRIC", ior=1.45)
    f_ab = brdf.specular_cosine(mat, np.repeat(N_UP, 30, 0), a, b) / b[None, :, 2, None]
    f_ba = brdf.specular_cosine(mat, np.repeat(N_UP, 40, 0), b, a) / a[None, :, 2, None]
    np.testing.assert_allclose(f_ab, np.transpose(f_ba, (1, 0, 2)), rtol=1e-4, atol=1e-7)


def test_specular_terms_sum_to_specular_cosine():
    mats = [materials.principled_material(base_color=(0.7, 0.5, 0.2), metallic=0.4, roughness=0.35,
                                     specular_tint=(1.0, 0.7, 0.4)),
            materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.6, 0.1), roughness=0.4,
                          distribution="MULTI_GGX")]
    views = np.concatenate([view_at(20), view_at(70, 50)])
    normals = np.repeat(N_UP, 2, 0)
    dirs = fibonacci_sphere(300)
    for mat in mats:
        total = sum(l[:, :, None] * w[:, None, :]
                    for l, w in brdf.specular_terms(mat, normals, views, dirs))
        np.testing.assert_allclose(total, brdf.specular_cosine(mat, normals, views, dirs),
                                   rtol=1e-6, atol=1e-9)

# --------------------------------------------------------------------------- core

def test_sharp_lobes_are_those_the_cubemap_cannot_resolve():
    mirror = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=0.0)
    assert brdf.is_sharp(mirror, 32) and brdf.is_sharp(mirror, 128)
    rough = materials.principled_material(roughness=0.5)
    assert not brdf.is_sharp(rough, 32)
    # the limit shrinks with the texels: roughness 0.12 is sharp at 32 and 64, not 128
    mid = materials.principled_material(roughness=0.12)
    assert [brdf.is_sharp(mid, n) for n in (32, 64, 128)] == [True, True, False]
    assert not brdf.is_sharp(materials.Material(diffuse_albedo=(0.5, 0.5, 0.5)), 32)


def test_a_per_pixel_lobe_leaves_only_the_layered_lambert_base():
    """Every per-vertex evaluation skips the lobes; the Principled base keeps Cycles'
    layering weight (the dielectric layer above it is still there, drawn per pixel)."""
    m = materials.principled_material(roughness=0.05, metallic=0.25)
    flagged = brdf.with_sharp_lobe(m, 32)
    assert flagged.per_pixel_lobe and flagged.is_diffuse_only and not m.is_diffuse_only
    n = np.array([[0.0, 0.0, 1.0]] * 3)
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [0.0, 0.96, 0.28]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, -0.6, 0.8]])
    assert brdf.specular_terms(flagged, n, v, d) == []
    np.testing.assert_array_equal(brdf.diffuse_view_weight(flagged, n, v),
                                  brdf.diffuse_view_weight(m, n, v))
    lobes = brdf.sharp_lobes(flagged)
    kinds = sorted((k, round(w, 6)) for k, w, *_ in lobes)
    assert kinds == [(brdf.SHARP_DIELECTRIC, 0.75), (brdf.SHARP_F82, 0.25)]
