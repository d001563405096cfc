"""The viewport's draw path run headless: a stand-in for the RenderEngine instance Blender
passes to ``view_draw`` and a draw into an offscreen with a fake region and view (needs
bpy and the gpu module's context: one Workbench render first)."""

from __future__ import annotations

import types

import gpu
import numpy as np

from prt_relight.addon.frame.engine import PRTRenderEngine


class FakeViewEngine:
    """Stands in for the RenderEngine instance Blender passes to ``view_draw``."""

    def __init__(self):
        self._state = None
        self._view_texture = None
        self._view_key = None
        self._shading = None
        self.bound = 0
        self.stats = None
        self.workers = []

    def _redraw_when_done(self, worker):
        self.workers.append(worker)           # Blender's timer would poll it

    def bind_display_space_shader(self, scene):
        self.bound += 1

    def unbind_display_space_shader(self):
        self.bound -= 1

    def update_stats(self, a, b):
        self.stats = (a, b)

    def view_update(self, context, depsgraph):
        PRTRenderEngine.view_update(self, context, depsgraph)


def view_draw(depsgraph, view_matrix, window_matrix, width, height, perspective=True,
              engine=None):
    """Run the engine's ``view_draw`` headless into an offscreen with a fake region/view
    (needs the gpu module's context: one Workbench render first).  Returns (engine,
    drawn RGBA (height, width, 4) bottom row first)."""
    rv3d = types.SimpleNamespace(view_matrix=view_matrix, window_matrix=window_matrix,
                                 is_perspective=perspective, view_perspective="CAMERA")
    ctx = types.SimpleNamespace(region=types.SimpleNamespace(width=width, height=height),
                                region_data=rv3d)
    engine = engine or FakeViewEngine()
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    with offscreen.bind():
        PRTRenderEngine.view_draw(engine, ctx, depsgraph)
    offscreen.free()
    buf = engine._view_texture.read()
    buf.dimensions = height * width * 4          # flat first: np.array of a 3D Buffer is wrong
    return engine, np.array(buf, dtype=np.float32).reshape(height, width, 4)


def gpu_context():
    """An empty scene rendered once by Workbench: the gpu module's context in -b."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 8, 8
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
