"""SH's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations
from ...gpu import drawing
from ..contract import Settings


class SHSettings(Settings):
    def scene_properties(self):
        from bpy.props import IntProperty
        return {"sh_order": IntProperty(
            name="SH Order", default=4, min=2, max=5, update=drawing.redraw_viewports,
            description="Spherical-harmonic bands kept by the SH method (order n: n*n "
                        "coefficients)")}
