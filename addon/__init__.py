"""Blender-side glue of prt_relight (bpy only; the numerics live in ``core``)."""

from . import engine, operators, panels, properties, report

_MODULES = (properties, operators, report, engine, panels)


def register():
    for m in _MODULES:
        m.register()


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
