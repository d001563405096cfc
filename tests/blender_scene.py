"""Small scene builders for the bpy tests (Blender as a Python module)."""

from __future__ import annotations

import math

import bpy
import numpy as np

from prt_relight.addon.blender import scene_build

try:
    import OpenImageIO as oiio
except ImportError:  # pragma: no cover
    oiio = None


def hdri_path(name: str = "sunset") -> str:
    return bpy.utils.system_resource("DATAFILES", path="studiolights/world") + f"/{name}.exr"


def reset(bounces: int = 0):
    """An empty scene whose Cycles Light Paths allow ``bounces`` diffuse bounces (0: the
    direct light most tests compare with Cycles' ``max_bounces = 0``)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.cycles.max_bounces = 12 if bounces else 0
    scene.cycles.diffuse_bounces = max(int(bounces), 1)
    return scene


def add_world(image=None, strength=1.0, rotation_z=0.0, path=None):
    """World with an Environment Texture (``image`` a bpy image or ``path``)."""
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    if image is None and path is not None:
        image = bpy.data.images.load(path, check_existing=True)
    env.image = image
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    if rotation_z:
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value[2] = rotation_z
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return world, env


def float_image(name: str, pixels_top_first: np.ndarray):
    """A generated float image (H, W, 3|4) given top row first."""
    h, w = pixels_top_first.shape[:2]
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[:, :, :3] = pixels_top_first[:, :, :3]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True, is_data=True)
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.pack()
    return img


def bsdf_material(name: str, node_type: str, **inputs):
    """A material whose surface is one BSDF node (``addon.blender.scene_build.bsdf_material``)."""
    return scene_build.bsdf_material(name, node_type, **inputs)

def add_ground(size=6.0, cuts=32):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size)
    return bpy.context.object


def add_suzanne(location=(0.0, 0.0, 1.0), subdiv=1):
    bpy.ops.mesh.primitive_monkey_add(location=location)
    ob = bpy.context.object
    bpy.ops.object.shade_smooth()
    if subdiv:
        mod = ob.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = subdiv
    return ob


def add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0)):
    bpy.ops.object.camera_add(location=location, rotation=rotation)
    cam = bpy.context.object
    bpy.context.scene.camera = cam
    return cam


def set_resolution(width, height):
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100


def render_exr(path, engine="PRT_RELIGHT", samples=64, transparent=True):
    """F12 with ``engine`` (film transparent, linear 32-bit EXR) -> (H, W, 4) top row first."""
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.film_transparent = transparent
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.max_bounces = 0
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    bpy.ops.render.render()
    bpy.data.images["Render Result"].save_render(str(path))
    return read_exr(path)


def read_exr(path) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "float"), dtype=np.float32)
    inp.close()
    return px.reshape(spec.height, spec.width, spec.nchannels)


def rel_l2(ours: np.ndarray, truth: np.ndarray, alpha_min=0.5) -> float:
    m = truth[..., 3] > alpha_min
    return float(np.linalg.norm(ours[m][:, :3] - truth[m][:, :3]) / np.linalg.norm(truth[m][:, :3]))


def sun_image(width, height, direction, radiance=1e3):
    """Black equirect with one pixel of ``radiance`` where world ``direction`` reads it."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    u = (0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0
    v = math.acos(d[2]) / math.pi
    img = np.zeros((height, width, 3), dtype=np.float32)
    img[min(int(v * height), height - 1), min(int(u * width), width - 1)] = radiance
    return img


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
        from prt_relight.addon.frame.engine import PRTRenderEngine
        PRTRenderEngine.view_update(self, context, depsgraph)


def view_draw(depsgraph, view_matrix, window_matrix, width, height, perspective=True,
              engine=None):
    """Run the engine's ``view_draw`` headless into an offscreen with a fake region/view
    (needs the gpu module's context: one Workbench render first).  Returns (engine,
    drawn RGBA (height, width, 4) bottom row first)."""
    import types

    import gpu
    from prt_relight.addon.frame.engine import PRTRenderEngine
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
