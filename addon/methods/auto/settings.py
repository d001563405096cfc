"""AUTO's settings in ``scene.prt`` and how the panel shows them."""

from __future__ import annotations

from ...gpu import drawing
from ..contract import Settings
from .shading import LAST_CHOICES
from .store import STORED_STATUS, parse_choice, stored_status


class AutoSettings(Settings):
    def scene_properties(self):
        from bpy.props import FloatProperty, StringProperty
        return {
            "auto_error_target": FloatProperty(
                name="Error Target", default=0.02, min=0.0, max=1.0, precision=3,
                subtype="FACTOR", update=drawing.redraw_viewports,
                description="AUTO: largest rel-L2 error against REFERENCE allowed per object "
                            "(0.02 = 2 %)"),
            "auto_choice": StringProperty(
                name="Stored Choice", default="", options={"HIDDEN"},
                update=drawing.redraw_viewports,
                description="AUTO: the method and budget per object chosen by Precompute or "
                            "Choose (JSON), with the key of what it depends on")}

    def draw(self, layout, prt):
        layout.prop(prt, "auto_error_target")
        box = layout.box()
        record = parse_choice(prt.auto_choice)
        why = stored_status(prt)
        if record is None:
            box.label(text="No stored choice: press Choose (or Precompute)", icon="INFO")
        else:
            if why:
                box.label(text=f"{why}: press Choose (or Precompute)", icon="ERROR")
            else:
                current = STORED_STATUS[0] == prt.auto_choice
                box.label(text="Stored choice" + (", current" if current else ""),
                          icon="CHECKMARK" if current else "INFO")
            box.label(text=f"Chosen for camera '{record['camera']}' at "
                           f"{record['size'][0]}×{record['size'][1]}" if record.get("camera")
                      else "Chosen at probe views (the scene had no camera)", icon="CAMERA_DATA")
            self._draw_choices(box, record["objects"])
        if LAST_CHOICES and (record is None or why):
            box.label(text="Drawn now with a live choice (not saved):")
            self._draw_choices(box, LAST_CHOICES)
        box.operator("prt.auto_choose", icon="FILE_REFRESH")

    @staticmethod
    def _draw_choices(layout, choices):
        for c in choices[:8]:
            margin = c.get("margin")
            err = "" if c["error"] is None else (
                f" ({100 * c['error']:.2f} ± {100 * margin:.2f} %)" if margin
                else f" ({100 * c['error']:.2f} %)")
            layout.label(text=f"{c['object']}: {c['choice']}{err}", icon="OBJECT_DATA")
