"""Blender-side glue of prt_relight (bpy only; the numerics live in ``core``)."""

import atexit

from . import drawing, engine, operators, panels, properties, report, sg_material

_MODULES = (properties, sg_material, operators, report, engine, panels)


def register():
    for m in _MODULES:
        m.register()
    # runs before the exit handler Blender registered when it was imported (LIFO)
    atexit.unregister(drawing.free_gpu_resources)
    atexit.register(drawing.free_gpu_resources)


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
    drawing.free_gpu_resources()
    atexit.unregister(drawing.free_gpu_resources)
