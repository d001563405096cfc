# SPDX-License-Identifier: GPL-3.0-or-later
"""core.shading.materials: a material's validation and alpha, and the Principled BSDF's
mapping onto the lobes (Specular IOR Level, metallic as the F82 conductor, half metallic as
the mix).  No bpy."""

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials

from .quadrature import N_UP, fibonacci_sphere, view_at


# --------------------------------------------------------------------------- #
# quadrature helpers
# --------------------------------------------------------------------------- #

def test_material_validation_and_alpha():
    assert materials.Material(roughness=0.5).alpha == pytest.approx(0.25)
    assert materials.Material(roughness=0.0).alpha == brdf.MICROFACET_ALPHA_MIN
    assert materials.Material(roughness=3.0).alpha == 1.0
    assert materials.Material(distribution="ggx").distribution == "GGX"
    assert not materials.Material(diffuse_albedo=(0, 0, 0)).has_diffuse
    with pytest.raises(ValueError):
        materials.Material(distribution="PHONG")
    with pytest.raises(ValueError):
        materials.Material(fresnel="CONDUCTOR")


def test_principled_mapping_details():
    # Specular IOR Level 0 switches the layer off (eta = 1), 1 doubles F0.
    off = materials.principled_material(specular_ior_level=0.0)
    assert off.ior == 1.0 and off.is_diffuse_only and off.has_diffuse
    np.testing.assert_array_equal(brdf.diffuse_view_weight(off, N_UP, view_at(80)), 1.0)
    hi = materials.principled_material(specular_ior_level=1.0)
    assert brdf.F0_from_ior(hi.ior) == pytest.approx(0.08, rel=1e-6)
    assert hi.specular_color == pytest.approx((0.08,) * 3)
    # metallic 1: no base, no dielectric lobe, an F82 lobe with F0 = base colour
    metal = materials.principled_material(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3,
                                     distribution="GGX")
    assert not metal.has_diffuse and not metal.is_diffuse_only
    np.testing.assert_array_equal(brdf.diffuse_view_weight(metal, N_UP, view_at(30)), 0.0)
    conductor = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.9, 0.6, 0.3),
                              roughness=0.3, distribution="GGX", fresnel="F82")
    dirs = fibonacci_sphere(500)
    a = brdf.reflectance_cosine(metal, N_UP, view_at(50), dirs)
    b = brdf.reflectance_cosine(conductor, N_UP, view_at(50), dirs)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-9)
    # half metallic: half of each
    half = materials.principled_material(base_color=(0.9, 0.6, 0.3), metallic=0.5, roughness=0.3,
                                    distribution="GGX")
    diel = materials.principled_material(base_color=(0.9, 0.6, 0.3), metallic=0.0, roughness=0.3,
                                    distribution="GGX")
    c = brdf.reflectance_cosine(half, N_UP, view_at(50), dirs)
    d = brdf.reflectance_cosine(diel, N_UP, view_at(50), dirs)
    np.testing.assert_allclose(c, 0.5 * (b + d), rtol=1e-5, atol=1e-8)
