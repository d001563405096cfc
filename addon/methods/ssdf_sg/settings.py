"""SSDF_SG's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations
from ....core.methods.ssdf_sg import scene as scene
from ...gpu import drawing
from ..contract import Settings
from .shading import LAST_TERMS, OCCLUSION_TARGET_DEFAULT


class SSDFSGSettings(Settings):
    def scene_properties(self):
        from bpy.props import EnumProperty, FloatProperty, IntProperty
        return {
            "ssdf_cosine": EnumProperty(
                name="Clamped Cosine", default="SG7", update=drawing.redraw_viewports,
                items=[("EQ40", "1 lobe (paper, eq. 40)",
                        "One SG on the normal: fastest, L2 error 17.7 %"),
                       ("SG7", "7 lobes", "SG mixture over the hemisphere, L2 error 6.3 %"),
                       ("SG19", "19 lobes", "SG mixture over the hemisphere, L2 error 3.7 %")],
                description="SG mixture standing in for max(0, n.i) in eq. 39/41; more lobes "
                            "are more accurate and probe visibility more locally, but slower"),
            "ssdf_resolution": IntProperty(
                name="SSDF Resolution", default=32, min=8, max=64,
                description="Texels per edge of each point's SSDF square (Shirley-Chiu map of "
                            "the hemisphere); its visibility boundary is supersampled 2x"),
            "ssdf_error_budget": FloatProperty(
                name="SSDF Error Budget", default=0.05, min=0.001, max=1.0, precision=3,
                subtype="ANGLE",
                description="RMS angular error allowed for the PCA-compressed SSDFs; decides "
                            "the number of PCA terms per object (needs a precompute)"),
            "ssdf_max_terms": IntProperty(
                name="SSDF Max Terms", default=48, min=4, max=60,
                description="Upper limit of PCA terms per object"),
            "ssdf_occlusion_target": FloatProperty(
                name="Min Occlusion Kept", default=OCCLUSION_TARGET_DEFAULT, min=0.0, max=1.0,
                subtype="FACTOR",
                description="Take more PCA terms (up to the maximum) until this share of each "
                            "object's blocked directions stays blocked after compression; the "
                            "RMS budget alone can drop small occluders' shadows on a ground. "
                            "Flat triangles (a ground) pay the terms only when the lighting "
                            "changes, curved ones per pixel (0 = the budget alone; needs a "
                            "precompute)"),
            "sg_lighting_fit": EnumProperty(
                name="Lighting Fit", default="SCENE", update=drawing.redraw_viewports,
                items=[("SCENE", "Scene",
                        "Lobes from the environment, amplitudes fitted to the scene's exact "
                        "shadowed irradiance at up to 1024 surface points (redone when the "
                        "world turns, tens of milliseconds)"),
                       ("ENVIRONMENT", "Environment",
                        "Lobes and amplitudes from the environment alone (the paper's §6): "
                        "keeps the unshadowed irradiance")],
                description="How the diffuse term's SG lighting (eq. 39) is fitted"),
            "ssdf_lamps": EnumProperty(
                name="Lamps", default="PASS", update=drawing.redraw_viewports,
                items=[("PASS", "Shadow Maps",
                        "Point and spot lamps drawn per pixel by the lamp pass every method "
                        "shares (shadow maps, the lamp's exact irradiance); SSDF_SG's own "
                        "shading stays per pixel"),
                       ("SG", "Spherical Gaussians",
                        "Point and spot lamps as SG lobes with SSDF visibility (Wang et al. "
                        "2009, eq. 32-33, 42-43); the frame is then shaded per vertex")],
                description="How SSDF_SG draws point and spot lamps (sun and area lamps and "
                            "the World's compact sources always go through the lamp pass)"),
            "sg_environment_lobes": IntProperty(
                name="Environment Lobes", default=8, min=1, max=16,
                update=drawing.redraw_viewports,
                description="SG lobes fitted to the environment for the diffuse term"),
        }

    def draw(self, layout, prt):
        for name in self.scene_properties():
            layout.prop(prt, name)
        for line in LAST_TERMS:
            layout.label(text=line)
