"""addon.ui.sg_material: a Blender material exported to an SG material, and the reflectance
panel's own sliders."""


import numpy as np
import pytest

from prt_relight.bench import scenes


# --------------------------------------------------------------------------- Blender side

@pytest.mark.usefixtures("registered_addon")
def test_blender_material_export_and_the_reflectance_panel():
    import bpy

    from prt_relight.addon.ui import sg_material


    scenes.reset()
    mat = scenes.bsdf_material("SGMat", "ShaderNodeBsdfPrincipled", **{"Metallic": 0.2, "IOR": 1.45})
    assert mat.prt_sg.use_blender_material
    sgm = sg_material.export_sg_material(mat, [])
    assert sgm.model == "GGX" and sgm.multiscatter and sgm.fresnel == "PRINCIPLED"
    assert np.isclose(float(sgm.metallic), 0.2) and np.isclose(float(sgm.ior), 1.45)

    # the sliders: own model when "Use Blender Material" is off
    s = mat.prt_sg
    s.use_blender_material = False
    s.model = "ASHIKHMIN_SHIRLEY"
    s.nu, s.nv = 100.0, 400.0
    s.fresnel = "SCHLICK"
    sgm = sg_material.export_sg_material(mat)
    assert sgm.model == "ASHIKHMIN_SHIRLEY" and sgm.aniso_params() == (100.0, 400.0)
    s.model = "COOK_TORRANCE"
    s.roughness = 0.5
    assert np.isclose(float(sg_material.export_sg_material(mat).roughness), 0.25)
    # panel is registered for the PRT engine
    assert hasattr(bpy.types, "PRT_PT_sg_material")
    assert sg_material.PRT_PT_sg_material.COMPAT_ENGINES == {"PRT_RELIGHT"}
