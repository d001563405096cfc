"""Stand-ins for the layout and context Blender hands a panel's draw(): the layout records
what is drawn and checks every property and operator against the RNA (needs bpy)."""

from __future__ import annotations

import bpy


class FakeLayout:
    """Records what a draw() puts in the layout and checks it against the RNA."""

    def __init__(self, log):
        self.log = log
        self.enabled = True
        self.active = True

    def _child(self, *args, **kwargs):
        return FakeLayout(self.log)

    column = row = box = split = _child

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"{data!r} has no property {name!r}"
        self.log.append(("prop", name))

    def operator(self, idname, **kwargs):
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), f"no operator {idname}"
        self.log.append(("operator", idname))

    def label(self, text="", **kwargs):
        assert isinstance(text, str)
        self.log.append(("label", text))

    def separator(self, **kwargs):
        pass


class FakeContext:
    def __init__(self, scene, material=None):
        self.scene = scene
        self.active_object = scene.objects.get("Suzanne")
        self.material = material
        self.engine = "PRT_RELIGHT"
