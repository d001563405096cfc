"""SG reflectance settings per material (Wang et al. 2009, §4) and the exports SSDF_SG needs.

Blender side only; the numerics are in ``core/sg/brdf.py`` / ``core/sg/lighting.py``.

* ``material.prt_sg`` (:class:`PRTSGMaterialSettings`): "Use Blender Material"
  (default on: the node tree is mapped by ``core.sg.brdf.sg_material_from_brdf``),
  otherwise the SG model, roughness (Blender roughness r, slope a = r^2),
  anisotropic parameters, Fresnel mode/IOR and colour overrides.  Every slider
  only redraws the viewports (no recompute: the BRDF is evaluated per pixel).
* Panel "PRT Reflectance" in Material properties for the PRT_RELIGHT engine.

Functions for the method module (``addon/methods/ssdf_sg/shading.py``):
:func:`export_sg_material` and :func:`uses_blender_material`.  A material's textured
inputs (colour, roughness, metallic, specular, normal and bump maps) are read by
``addon/blender/texture_export.py``, the lamps by ``addon/blender/scene_export.py`` (``export_lamps``).
"""

from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       PointerProperty)

from ...core.sg import brdf as sg_brdf
from ...core.sg import reflectance
from ..blender import scene_export
from ..gpu.drawing import redraw_viewports

MODEL_ITEMS = [
    ("COOK_TORRANCE", "Cook-Torrance", "Beckmann NDF, Smith shadowing (eq. 10-12): one SG lobe"),
    ("BLINN_PHONG", "Blinn-Phong", "Exponent 2/a^2 - 2: one SG lobe"),
    ("WARD", "Ward", "Isotropic Ward: one SG lobe"),
    ("WARD_ANISO", "Ward Anisotropic", "Anisotropic Ward (alpha x, alpha y): several SG lobes"),
    ("ASHIKHMIN_SHIRLEY", "Ashikhmin-Shirley", "Anisotropic Phong exponents nu, nv: several SG lobes"),
]
FRESNEL_ITEMS = [
    ("NONE", "None", "F = 1: the specular colour is the reflectance (Cycles Glossy BSDF)"),
    ("SCHLICK", "Schlick", "Schlick's approximation with F0 = specular colour"),
    ("DIELECTRIC", "Dielectric", "Cook-Torrance Fresnel of eq. 14 with the IOR, times the specular colour"),
]


class PRTSGMaterialSettings(bpy.types.PropertyGroup):
    use_blender_material: BoolProperty(
        name="Use Blender Material", default=True, update=redraw_viewports,
        description="Map the material's node tree (Diffuse/Glossy/Principled BSDF) to "
                    "SG lobes (Beckmann or GGX); off: use the settings below")
    model: EnumProperty(name="Model", items=MODEL_ITEMS, default="COOK_TORRANCE",
                        update=redraw_viewports)
    roughness: FloatProperty(name="Roughness", default=0.3, min=0.0, max=1.0,
                             subtype="FACTOR", update=redraw_viewports,
                             description="Blender roughness r; the microfacet slope is r squared")
    alpha_x: FloatProperty(name="Alpha X", default=0.3, min=sg_brdf.SG_ALPHA_MIN, max=1.0,
                           update=redraw_viewports, description="Ward slope along the tangent")
    alpha_y: FloatProperty(name="Alpha Y", default=0.1, min=sg_brdf.SG_ALPHA_MIN, max=1.0,
                           update=redraw_viewports, description="Ward slope along the bitangent")
    nu: FloatProperty(name="nu", default=75.0, min=1.0, max=10000.0, update=redraw_viewports,
                      description="Ashikhmin-Shirley exponent along the tangent")
    nv: FloatProperty(name="nv", default=1200.0, min=1.0, max=10000.0, update=redraw_viewports,
                      description="Ashikhmin-Shirley exponent along the bitangent")
    fresnel: EnumProperty(name="Fresnel", items=FRESNEL_ITEMS, default="DIELECTRIC",
                          update=redraw_viewports)
    ior: FloatProperty(name="IOR", default=1.5, min=1.0, max=5.0, update=redraw_viewports)
    diffuse_color: FloatVectorProperty(name="Diffuse", subtype="COLOR", size=3, min=0.0, max=1.0,
                                       default=(0.5, 0.5, 0.5), update=redraw_viewports)
    specular_color: FloatVectorProperty(name="Specular", subtype="COLOR", size=3, min=0.0,
                                        max=1.0, default=(1.0, 1.0, 1.0),
                                        update=redraw_viewports)


class PRT_PT_sg_material(bpy.types.Panel):
    bl_label = "PRT Reflectance"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"
    COMPAT_ENGINES = {"PRT_RELIGHT"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and context.material is not None

    def draw(self, context):
        s = context.material.prt_sg
        col = self.layout.column()
        col.prop(s, "use_blender_material")
        if s.use_blender_material:
            col.label(text="Drawn from the node tree (Beckmann or GGX lobes)", icon="INFO")
            return
        col.prop(s, "model")
        if s.model == "WARD_ANISO":
            col.prop(s, "alpha_x")
            col.prop(s, "alpha_y")
        elif s.model == "ASHIKHMIN_SHIRLEY":
            col.prop(s, "nu")
            col.prop(s, "nv")
        else:
            col.prop(s, "roughness")
        col.prop(s, "fresnel")
        if s.fresnel == "DIELECTRIC":
            col.prop(s, "ior")
        col.prop(s, "diffuse_color")
        col.prop(s, "specular_color")


def uses_blender_material(blender_material) -> bool:
    """Whether SSDF_SG draws the material's node tree (not its own SG model)."""
    s = getattr(blender_material, "prt_sg", None) if blender_material is not None else None
    return s is None or s.use_blender_material


def export_sg_material(blender_material, warnings: list | None = None) -> reflectance.SGMaterial:
    """The material's SG reflectance (``None``: Cycles' default surface)."""
    warnings = [] if warnings is None else warnings
    s = getattr(blender_material, "prt_sg", None) if blender_material is not None else None
    if uses_blender_material(blender_material):
        return sg_brdf.sg_material_from_brdf(scene_export.export_material(blender_material, warnings))
    a = max(float(s.roughness) ** 2, sg_brdf.SG_ALPHA_MIN)
    return reflectance.SGMaterial(model=s.model, diffuse=tuple(s.diffuse_color),
                              specular=tuple(s.specular_color), roughness=a,
                              alpha_x=s.alpha_x, alpha_y=s.alpha_y, nu=s.nu, nv=s.nv,
                              fresnel=s.fresnel, ior=s.ior)


CLASSES = (PRTSGMaterialSettings, PRT_PT_sg_material)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Material.prt_sg = PointerProperty(type=PRTSGMaterialSettings)


def unregister():
    del bpy.types.Material.prt_sg
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
