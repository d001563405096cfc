"""WAVELET's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations
from ...gpu import drawing
from ..contract import Settings


class WaveletSettings(Settings):
    def scene_properties(self):
        from bpy.props import FloatProperty, IntProperty
        upd = drawing.redraw_viewports
        return {
            "wavelet_terms": IntProperty(
                name="Lighting Terms", default=256, min=1, max=98304, update=upd,
                description="Haar coefficients of the lighting kept for diffuse transfer "
                            "(non-linear approximation: the largest ones)"),
            "wavelet_glossy_percent": FloatProperty(
                name="Glossy Kept %", default=1.0, min=0.01, max=100.0, precision=2,
                update=upd, subtype="PERCENTAGE",
                description="Percentage of the lighting's and of each BRDF's Haar "
                            "coefficients kept in the glossy triple product"),
            "wavelet_transfer_percent": FloatProperty(
                name="Transport Kept %", default=10.0, min=0.1, max=100.0, precision=1,
                update=upd, subtype="PERCENTAGE",
                description="Percentage of each point's diffuse transport coefficients "
                            "stored (the largest ones)"),
        }
