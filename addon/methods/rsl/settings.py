"""RSL's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations
from ...gpu import drawing
from ..contract import Settings


class RSLSettings(Settings):
    def scene_properties(self):
        from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty
        upd = drawing.redraw_viewports
        return {
            "rsl_lights": IntProperty(
                name="Lights", default=30, min=1, max=2000, update=upd,
                description="Number of rotatable square lights the environment is split into"),
            "rsl_mode": EnumProperty(
                name="Light Count", update=upd,
                items=[("COUNT", "Count", "Use exactly the given number of lights"),
                       ("BUDGET", "Error Budget", "Merge until the RSL fitting error reaches "
                                                  "the budget")],
                default="COUNT"),
            "rsl_error_budget": FloatProperty(
                name="Fitting Error", default=0.5, min=1e-4, max=100.0, soft_max=10.0,
                update=upd,
                description="Error budget mode: the fewest lights whose summed squared "
                            "intensity error is within this multiple of (integral of the "
                            "luminance)^2 / 4 pi (sharp HDRIs need larger values)"),
            "rsl_visibility": EnumProperty(
                name="Visibility", update=upd,
                items=[("VDT", "Distance Table", "One look-up per light (eq. 9)"),
                       ("SAT", "Summed-Area Table", "Exact box integral, four look-ups")],
                default="VDT"),
            "rsl_cpca_error": FloatProperty(
                name="VDT Compression Error", default=0.02, min=1e-4, max=0.5,
                description="Precompute: RMS error allowed when compressing the per-vertex "
                            "distance tables with clustered PCA, relative to their spread "
                            "about the mean table"),
            "rsl_gpu": BoolProperty(
                name="GPU Pass", default=True, update=upd,
                description="Shade the vertices in a GLSL pass (one texel per vertex) when a GPU "
                            "context is available; numpy otherwise"),
        }

    def draw(self, layout, prt):
        layout.prop(prt, "rsl_mode")
        if prt.rsl_mode == "BUDGET":
            layout.prop(prt, "rsl_error_budget")
        else:
            layout.prop(prt, "rsl_lights")
        layout.prop(prt, "rsl_visibility")
        layout.prop(prt, "rsl_gpu")
        layout.prop(prt, "rsl_cpca_error")
