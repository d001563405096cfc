"""REFERENCE's settings in ``scene.prt``: where its sums run."""

from __future__ import annotations

from ...gpu import drawing
from ..contract import Settings


class ReferenceSettings(Settings):
    def scene_properties(self):
        from bpy.props import BoolProperty
        return {
            "reference_gpu": BoolProperty(
                name="GPU Pass", default=True, update=drawing.redraw_viewports,
                description="Sum the glossy reflection of every shading point in a GLSL pass "
                            "(one texel per point) when a GPU context is available; numpy "
                            "otherwise (the same sums)"),
        }
