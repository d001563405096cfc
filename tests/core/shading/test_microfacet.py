# SPDX-License-Identifier: GPL-3.0-or-later
"""core.shading.microfacet: the Beckmann and GGX NDFs normalised over the hemisphere, their
peak and support, Smith's projected area and Lambda against their definitions, in the
dtype given.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.shading import brdf, microfacet

from .quadrature import DISTS, hemisphere_grid, view_at


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


def test_lambda_of_t2_is_smith_lambda_in_the_dtype_given():
    """One Lambda for REFERENCE (float64) and BLOCKS' float32 evaluator: the same values,
    float32 in stays float32; Beckmann is 0 below t2 = 0.39 (a > 1.6)."""
    c = np.linspace(0.05, 1.0, 40)
    for dist, alpha in (("GGX", 0.3), ("BECKMANN", 0.3), ("BECKMANN", 0.05)):
        t2 = alpha ** 2 * (1.0 / (c * c) - 1.0)
        np.testing.assert_allclose(microfacet.lambda_of_t2(dist, t2),
                                   brdf.smith_lambda(dist, alpha, c), rtol=1e-12)
        lam32 = microfacet.lambda_of_t2(dist, t2.astype(np.float32))
        assert lam32.dtype == np.float32
        np.testing.assert_allclose(lam32, brdf.smith_lambda(dist, alpha, c), rtol=2e-6, atol=1e-7)
    assert microfacet.lambda_of_t2("BECKMANN", np.array([0.389]))[0] == 0.0
    a = 1.0 / np.sqrt(0.5)
    assert microfacet.lambda_of_t2("BECKMANN", np.array([0.5]))[0] == pytest.approx(
        (1 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a))


def test_lobe_signature_defines_only_what_every_material_shares():
    """The shaders compile a draw's shared distribution, lobe count and Fresnel kinds in;
    what differs between its materials stays a run-time value."""
    metal = (1.0, 2.0, brdf.SHARP_F82, brdf.SHARP_DIELECTRIC)    # GGX, a metal and a dielectric
    plastic = (1.0, 1.0, brdf.SHARP_DIELECTRIC, 0.0)
    diffuse = (0.0, 0.0, 0.0, 0.0)                                # no lobe: its kinds are not read
    assert microfacet.lobe_signature([plastic, plastic]) == (
        "LOBE_DIST 1", "LOBE_COUNT 1", f"LOBE_KIND0 {brdf.SHARP_DIELECTRIC}")
    assert microfacet.lobe_signature([metal]) == (
        "LOBE_DIST 1", "LOBE_COUNT 2", f"LOBE_KIND0 {brdf.SHARP_F82}",
        f"LOBE_KIND1 {brdf.SHARP_DIELECTRIC}")
    # a diffuse-only material: the count differs, the glossy ones' distribution and kind do not
    assert microfacet.lobe_signature([plastic, diffuse]) == (
        "LOBE_DIST 1", f"LOBE_KIND0 {brdf.SHARP_DIELECTRIC}")
    # a metal beside a plastic: the first lobe's kind differs, the second is the metal's alone
    assert microfacet.lobe_signature([metal, plastic]) == (
        "LOBE_DIST 1", f"LOBE_KIND1 {brdf.SHARP_DIELECTRIC}")
    beckmann = (0.0, 1.0, brdf.SHARP_SCHLICK, 0.0)
    assert microfacet.lobe_signature([beckmann, plastic]) == ("LOBE_COUNT 1",)
    assert microfacet.lobe_signature([diffuse]) == ("LOBE_COUNT 0",)
    assert microfacet.lobe_signature([]) == ()
    # the values the add-on reads from float32 texel rows
    rows = np.array([plastic], np.float32)
    assert microfacet.lobe_signature(rows) == microfacet.lobe_signature([plastic])
