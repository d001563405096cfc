"""Blender-side glue of prt_relight (bpy only; the numerics live in ``core``)."""

from . import engine, operators, panels, properties, report, sg_material

_MODULES = (properties, sg_material, operators, report, engine, panels)


def register():
    for m in _MODULES:
        m.register()


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
