# SPDX-License-Identifier: GPL-3.0-or-later
"""Numerical checks of core/brdf.py (quadrature on the sphere / hemisphere)."""

import importlib.util
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if "prt_relight" not in sys.modules:
    spec = importlib.util.spec_from_file_location(
        "prt_relight", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)]
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules["prt_relight"] = mod
    spec.loader.exec_module(mod)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from prt_relight.core import brdf  # noqa: E402

DISTS = ("BECKMANN", "GGX")
N_UP = np.array([[0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------- #
# quadrature helpers
# --------------------------------------------------------------------------- #

def fibonacci_sphere(n):
    """n nearly-uniform unit vectors; equal weights 4*pi/n."""
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def view_at(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]])


def hemisphere_grid(alpha, n_theta, n_phi):
    """(theta, phi) grid on the upper hemisphere, theta concentrated near 0 on
    the scale alpha: theta = arctan(alpha * tan(pi/2 * u)), u uniform.
    Returns directions (T*F, 3), trapezoid weights (T*F,) incl. sin(theta)."""
    u = np.linspace(0.0, 1.0, n_theta)
    theta = np.arctan(alpha * np.tan(0.5 * np.pi * np.minimum(u, 1.0 - 1e-12)))
    theta[-1] = 0.5 * np.pi
    wt = np.zeros_like(theta)
    dt = np.diff(theta)
    wt[:-1] += 0.5 * dt
    wt[1:] += 0.5 * dt
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    T, F = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(F), np.sin(T) * np.sin(F), np.cos(T)], axis=-1)
    w = (wt * np.sin(theta))[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]
    return dirs.reshape(-1, 3), w.reshape(-1)


def lobe_integral(mat, views, dirs, weights, chunk=250_000):
    """sum_d reflectance_cosine[p, d, :] * w_d, chunked over D -> (P, 3)."""
    acc = np.zeros((views.shape[0], 3))
    normals = np.repeat(N_UP, views.shape[0], axis=0)
    for s in range(0, dirs.shape[0], chunk):
        rc = brdf.reflectance_cosine(mat, normals, views, dirs[s:s + chunk])
        acc += np.einsum("pdc,d->pc", rc.astype(np.float64), weights[s:s + chunk])
    return acc


# --------------------------------------------------------------------------- #
# NDF normalisation
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha", [0.05, 0.1, 0.3, 0.7, 1.0])
def test_ndf_normalised(dist, alpha):
    # integral D(m) cos(theta_m) dm = 2 pi int_0^1 D(x) x dx, x = cos(theta_m);
    # D is concentrated at x -> 1 on a scale alpha^2, so integrate in y = 1 - x
    # on a geometric grid.
    y = np.concatenate([[0.0], np.geomspace(1e-14, 1.0, 200_001)])
    x = 1.0 - y
    f = brdf.microfacet_D(dist, alpha, x) * x
    total = 2.0 * np.pi * np.trapz(f, y)
    assert total == pytest.approx(1.0, abs=1e-3)


def test_ndf_peak_and_support():
    for dist in DISTS:
        # peak value 1 / (pi alpha^2) for both distributions
        assert brdf.microfacet_D(dist, 0.2, 1.0) == pytest.approx(1.0 / (np.pi * 0.04), rel=1e-9)
        assert brdf.microfacet_D(dist, 0.2, -0.5) == 0.0
        assert brdf.microfacet_D(dist, 0.2, 0.0) == 0.0


# --------------------------------------------------------------------------- #
# Lambert
# --------------------------------------------------------------------------- #

def test_lambert_hemisphere_integral_is_albedo():
    dirs = fibonacci_sphere(400_000)
    w = np.full(dirs.shape[0], 4.0 * np.pi / dirs.shape[0])
    albedo = (0.8, 0.5, 0.2)
    mat = brdf.Material(diffuse_albedo=albedo)
    assert mat.is_diffuse_only and mat.has_diffuse
    views = np.concatenate([view_at(0), view_at(60, 30), view_at(89.9)])
    got = lobe_integral(mat, views, dirs, w)
    np.testing.assert_allclose(got, np.tile(albedo, (3, 1)), rtol=2e-4)


def test_lambert_ignores_view_side():
    # Cycles' diffuse closure only tests the light side.
    mat = brdf.Material(diffuse_albedo=(1.0, 1.0, 1.0))
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
        mat = brdf.Material(specular_color=(1, 1, 1), roughness=r, distribution=dist)
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
    mat = brdf.Material(diffuse_albedo=(0.3, 0.2, 0.1), specular_color=(0.9, 0.5, 0.04),
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
    mat = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
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


# Cycles' own precomputed single-scattering GGX directional albedo,
# intern/cycles/scene/shader.tables, ``table_ggx_E[1024]`` (32 x 32, row = mu
# index, column = roughness index, grid value = index / 31; read in
# microfacet_ggx_preserve_energy via lookup_table_read_2D(rough, mu)).
# (row, col) -> E
CYCLES_TABLE_GGX_E = {
    (31, 31): 0.306853, (31, 20): 0.770757, (31, 15): 0.926694, (31, 10): 0.987261,
    (15, 31): 0.457779, (15, 20): 0.748187, (15, 10): 0.964995,
    (5, 31): 0.681600, (5, 20): 0.832480,
    (1, 31): 0.888202, (1, 15): 0.952526,
}


def test_ggx_albedo_matches_cycles_table():
    """Integrating our GGX lobe reproduces Cycles' table_ggx_E: this checks D,
    Lambda, G2, the 1/(4 cos_o) factor and alpha = r^2 end to end."""
    for (row, col), ref in CYCLES_TABLE_GGX_E.items():
        mu, r = row / 31.0, col / 31.0
        dirs, w = hemisphere_grid(r * r, 600, 720)
        mat = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                            roughness=r, distribution="GGX")
        v = np.array([[np.sqrt(1.0 - mu * mu), 0.0, mu]])
        E = lobe_integral(mat, v, dirs, w)[0, 0]
        assert E == pytest.approx(ref, abs=3e-4), (row, col, E, ref)


# --------------------------------------------------------------------------- #
# Smith masking: projected-area identity
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("dist,tol", [("GGX", 0.01), ("BECKMANN", 0.03)])
@pytest.mark.parametrize("alpha", [0.1, 0.3, 0.7, 1.0])
def test_smith_projected_area(dist, tol, alpha):
    # G1(wo) * integral max(0, wo.m) D(m) dm = cos(theta_o)
    m, w = hemisphere_grid(alpha, 1500, 1024)
    Dm = brdf.microfacet_D(dist, alpha, m[:, 2]) * w
    for theta_o in (0.0, 30.0, 60.0, 75.0, 85.0):
        wo = view_at(theta_o, 40.0)[0]
        proj = np.maximum(m @ wo, 0.0) @ Dm
        g1 = 1.0 / (1.0 + brdf.smith_lambda(dist, alpha, wo[2]))
        assert float(brdf.smith_G1(dist, alpha, wo[2])) == pytest.approx(float(g1))
        assert g1 * proj == pytest.approx(wo[2], rel=tol), (theta_o, g1 * proj, wo[2])


def test_smith_lambda_values():
    # GGX closed form and Beckmann cut-off, as in Cycles.
    c = np.cos(np.radians(60.0))
    t2 = 0.25 * 3.0  # alpha = 0.5, tan^2(60) = 3
    assert brdf.smith_lambda("GGX", 0.5, c) == pytest.approx(0.5 * (np.sqrt(1 + t2) - 1))
    assert brdf.smith_lambda("BECKMANN", 0.5, 1.0) == 0.0
    a = 1.0 / np.sqrt(t2)
    ref = (1 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a)
    assert brdf.smith_lambda("BECKMANN", 0.5, c) == pytest.approx(ref)
    # below the cut a >= 1.6 -> 0
    assert brdf.smith_lambda("BECKMANN", 0.1, np.cos(np.radians(60.0))) == 0.0


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
    mat = brdf.Material(diffuse_albedo=(0.5, 0.5, 0.5), specular_color=(1.0, 0.5, 0.2),
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
    mat = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
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
    plain = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.5, 0.25, 1.0),
                          roughness=0.3, distribution="GGX")
    s = brdf.specular_cosine(plain, normals, views, dirs)
    r = brdf.reflectance_cosine(plain, normals, views, dirs)
    np.testing.assert_allclose(r, s[..., None] * np.array([0.5, 0.25, 1.0], np.float32), rtol=1e-6)
    # Schlick with F0 = 1 is the uncoloured lobe; with F0 < 1 it is >= F0 * lobe
    one = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                        roughness=0.3, distribution="GGX", fresnel="SCHLICK")
    s1 = brdf.specular_cosine(one, normals, views, dirs)
    s_plain1 = brdf.specular_cosine(brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1),
                                                  roughness=0.3, distribution="GGX"),
                                    normals, views, dirs)
    np.testing.assert_allclose(s1, np.repeat(s_plain1[..., None], 3, axis=-1), rtol=1e-6)
    low = brdf.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.04, 0.04, 0.04),
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
    off = brdf.Material(specular_color=(0, 0, 0), fresnel="SCHLICK")
    assert off.is_diffuse_only
    assert not np.any(brdf.specular_cosine(off, normals, views, dirs))


def test_material_validation_and_alpha():
    assert brdf.Material(roughness=0.5).alpha == pytest.approx(0.25)
    assert brdf.Material(roughness=0.0).alpha == brdf.ALPHA_MIN
    assert brdf.Material(roughness=3.0).alpha == 1.0
    assert brdf.Material(distribution="ggx").distribution == "GGX"
    assert not brdf.Material(diffuse_albedo=(0, 0, 0)).has_diffuse
    with pytest.raises(ValueError):
        brdf.Material(distribution="PHONG")
    with pytest.raises(ValueError):
        brdf.Material(fresnel="CONDUCTOR")
