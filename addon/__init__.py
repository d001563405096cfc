"""Blender-side glue of prt_relight (bpy only; the numerics live in ``core``)."""

import atexit

import bpy

from .gpu import drawing
from .frame import engine, keys, state as runtime
from .ui import operators, panels, properties, sg_material
from .benchmark import operator as report

_MODULES = (properties, sg_material, operators, report, engine, panels)


@bpy.app.handlers.persistent
def _on_load(*_args):
    """File > New / Open: the previous file's messages are no longer true."""
    runtime.LAST_MESSAGES.clear()


def register():
    for m in _MODULES:
        m.register()
    bpy.app.handlers.load_post.append(_on_load)
    # runs before the exit handler Blender registered when it was imported (LIFO)
    atexit.unregister(drawing.free_gpu_resources)
    atexit.register(drawing.free_gpu_resources)


def unregister():
    if _on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load)
    for m in reversed(_MODULES):
        m.unregister()
    drawing.free_gpu_resources()
    keys.free()                      # every other cache (docs/README.md lists them)
    atexit.unregister(drawing.free_gpu_resources)
