"""BLOCKS's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations
from ...gpu import drawing
from ..contract import Settings


class BlocksSettings(Settings):
    def scene_properties(self):
        from bpy.props import FloatProperty
        return {"blocks_tolerance": FloatProperty(
            name="Block Tolerance", default=0.1, min=1e-6, max=1.0, precision=6,
            update=drawing.redraw_viewports,
            description="BLOCKS: a block is sampled at every pixel where the glossy lobe "
                        "reaches this fraction of its peak, with 16 / 4 / 1 DCT coefficients "
                        "down to 1/10, 1/100, 1e-7 of it (smaller: more accurate, slower)")}
