"""core.sg.reflectance: the SG material's parameters as its definition states them: names
checked, colours and scalars clamped to their valid ranges, per-point (textured) values kept
per point, the anisotropic models' pair of widths; bad input refused.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.sg import brdf as sg_brdf
from prt_relight.core.sg import reflectance
from prt_relight.core.sg.ndf import SG_ALPHA_MIN, FRESNEL_MODES, MODELS


def test_bad_input_is_reported():
    with pytest.raises(ValueError):
        reflectance.SGMaterial(roughness=float("nan"))
    with pytest.raises(ValueError):
        reflectance.SGMaterial(model="PHONG")
    with pytest.raises(ValueError):
        sg_brdf.specular_lobes(reflectance.SGMaterial(), [[0, 0, 1]], [[np.inf, 0, 1]])


def test_inputs_are_clamped_to_their_valid_ranges():
    m = reflectance.SGMaterial(diffuse=(-0.5, 0.2, 2.0), specular=(-1.0, 0.0, 0.5),
                               roughness=0.0, metallic=1.7, ior=-2.0, nu=-5.0)
    np.testing.assert_array_equal(m.diffuse, [0.0, 0.2, 2.0])        # colours: >= 0
    np.testing.assert_array_equal(m.specular, [0.0, 0.0, 0.5])
    assert float(m.roughness) == SG_ALPHA_MIN                             # NDFs need a width
    assert float(m.metallic) == 1.0 and float(m.ior) == pytest.approx(1e-3)
    assert m.nu == 0.0
    assert reflectance.SGMaterial(metallic=-0.2).metallic == 0.0


def test_names_are_case_insensitive_and_checked():
    m = reflectance.SGMaterial(model="ward_aniso", fresnel="schlick")
    assert m.model == "WARD_ANISO" and m.fresnel == "SCHLICK"
    assert m.model in MODELS and m.fresnel in FRESNEL_MODES
    with pytest.raises(ValueError, match="fresnel"):
        reflectance.SGMaterial(fresnel="CONDUCTOR")
    with pytest.raises(ValueError, match="3 components"):
        reflectance.SGMaterial(diffuse=(0.5, 0.5))
    with pytest.raises(ValueError, match="NaN"):
        reflectance.SGMaterial(specular=(0.5, np.inf, 0.5))
    with pytest.raises(ValueError, match="NaN"):
        reflectance.SGMaterial(alpha_x=np.nan)


def test_per_point_parameters_keep_their_shapes():
    """Textured inputs: scalars per point (P,), colours per point (P, 3)."""
    P = 5
    rough = np.linspace(0.0, 1.0, P)
    m = reflectance.SGMaterial(roughness=rough, diffuse=np.full((P, 3), 0.3),
                               metallic=np.linspace(-1.0, 2.0, P), ior=np.full(P, 1.45))
    assert m.roughness.shape == (P,) and m.diffuse.shape == (P, 3)
    np.testing.assert_array_equal(m.roughness, np.maximum(rough, SG_ALPHA_MIN))
    np.testing.assert_array_equal(m.metallic, np.clip(np.linspace(-1.0, 2.0, P), 0.0, 1.0))


@pytest.mark.parametrize("model, aniso, params", [
    ("WARD_ANISO", True, (0.3, 0.1)), ("ASHIKHMIN_SHIRLEY", True, (75.0, 1200.0)),
    ("COOK_TORRANCE", False, None), ("BLINN_PHONG", False, None), ("WARD", False, None),
    ("GGX", False, None)])
def test_the_anisotropic_models_read_their_own_pair(model, aniso, params):
    m = reflectance.SGMaterial(model=model)
    assert m.is_anisotropic == aniso
    if aniso:
        assert m.aniso_params() == params
