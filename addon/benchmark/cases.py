"""The hard cases of the stability table (``addon/benchmark/operator.py``'s :func:`stability_table`):
small scenes built in a scene of their own -- open and occluded grounds, a sun, a black
world, non-finite pixels, a mirror, grazing views -- plus the cases methods declare
(``Bench.stability_cases``)."""

from __future__ import annotations

import math

import bpy
import numpy as np

from .. import methods
from ..blender import scene_build

def _equirect_world(name, pixels):
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True, is_data=True)
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = pixels
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.pack()
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world


def _hdri_world(name, hdri="forest"):
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    folder = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(f"{folder}/{hdri}.exr", check_existing=True)
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world


def _sun_pixels(direction, radiance, width=64, height=32):
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    u = (0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0
    v = math.acos(d[2]) / math.pi
    img = np.zeros((height, width, 3), dtype=np.float32)
    img[min(int(v * height), height - 1), min(int(u * width), width - 1)] = radiance
    return img


def _mesh_object(scene, name, build, location=(0.0, 0.0, 0.0), scale=1.0, smooth=True):
    import bmesh
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    build(bm)
    bm.to_mesh(me)
    bm.free()
    if smooth:
        for poly in me.polygons:
            poly.use_smooth = True
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    ob.scale = (scale, scale, scale)
    scene.collection.objects.link(ob)
    return ob


def _grid(scene, size=4.0, cuts=8):
    import bmesh
    return _mesh_object(scene, "Grid", lambda bm: bmesh.ops.create_grid(
        bm, x_segments=cuts, y_segments=cuts, size=size / 2), smooth=False)


def _suzanne(scene, location=(0.0, 0.0, 1.0), scale=0.8):
    import bmesh
    return _mesh_object(scene, "Suzanne", lambda bm: bmesh.ops.create_monkey(bm),
                        location=location, scale=scale)


def _ball(scene, location=(0.0, 0.0, 1.0), radius=0.8):
    import bmesh
    return _mesh_object(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=16, v_segments=8, radius=radius), location=location)


def _glossy(name, roughness, colour=(0.8, 0.8, 0.8, 1.0), distribution="GGX"):
    return scene_build.bsdf_material(name, "ShaderNodeBsdfGlossy", distribution=distribution,
                                     Roughness=roughness, Color=colour)

def _camera(scene, eye, target=(0.0, 0.0, 0.5)):
    from mathutils import Vector
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = eye
    cam.rotation_euler = (Vector(target) - Vector(eye)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.render.resolution_percentage = 100
    return cam


def _case_scene(scene, world, eye=(0.0, -6.0, 3.0)):
    scene.world = world
    _camera(scene, eye)
    return dict(eye=np.asarray(eye, dtype=np.float64))


def _build_open(scene):
    _grid(scene, cuts=6)
    return _case_scene(scene, _hdri_world("PRT stability open"))


def _build_occluded(scene):
    import bmesh
    _suzanne(scene, location=(0.0, 0.0, 1.0), scale=0.5)
    _mesh_object(scene, "Box", lambda bm: bmesh.ops.create_cube(bm, size=3.0),
                 location=(0.0, 0.0, 1.0), smooth=False)
    return _case_scene(scene, _hdri_world("PRT stability occluded"), eye=(0.0, -0.5, 1.2))


def _build_sun(scene):
    _grid(scene)
    _ball(scene)
    world = _equirect_world("PRT stability sun", _sun_pixels((0.4, -0.5, 0.77), 1e6))
    return _case_scene(scene, world)


def _build_black(scene):
    _grid(scene)
    _ball(scene)
    return _case_scene(scene, _equirect_world("PRT stability black",
                                              np.zeros((16, 32, 3), np.float32)))


def _build_bad_pixels():
    def build(scene):
        _grid(scene)
        _ball(scene)
        px = np.full((16, 32, 3), 0.5, dtype=np.float32)
        px[3, 7, 1] = np.nan
        px[9, 20, :] = np.inf
        return _case_scene(scene, _equirect_world("PRT stability NaN/Inf", px))
    return build


def _build_mirror(scene):
    _grid(scene)
    ob = _ball(scene)
    ob.data.materials.append(_glossy("PRT stability mirror", 0.0))
    return _case_scene(scene, _hdri_world("PRT stability mirror"))


def _build_grazing(scene):
    ob = _grid(scene, cuts=8)
    ob.data.materials.append(_glossy("PRT stability grazing", 0.15))
    _ball(scene, radius=0.5)
    return _case_scene(scene, _hdri_world("PRT stability grazing"), eye=(0.0, -12.0, 0.03))


#: The hard cases every method is run through: (name, description, build(scene) -> dict
#: with ``eye``; ``expect_error`` marks input the export must refuse with a message).
BASE_CASES = [
    dict(name="fully open", description="a lone grid: every vertex sees the whole hemisphere",
         build=_build_open),
    dict(name="fully occluded", description="Suzanne inside a closed box, camera inside",
         build=_build_occluded),
    dict(name="1-pixel sun 1e6", description="black world with one pixel of radiance 1e6",
         build=_build_sun),
    dict(name="black world", description="all-zero environment", build=_build_black),
    dict(name="NaN/Inf pixels", description="environment with NaN and +Inf pixels (must "
         "be refused with a message)", build=_build_bad_pixels(), expect_error="NaN/Inf"),
    dict(name="roughness → 0", description="Glossy GGX roughness 0 on a ball",
         build=_build_mirror),
    dict(name="grazing view", description="glossy grid seen from 0.25° above its plane",
         build=_build_grazing),
]


#: Largest rel-L2 against REFERENCE each method may show in a case (per-corner radiance of
#: what the eye can see, default settings, 6×16² directions; the meshes carry the default
#: Principled's glossy layer), from each method's documented accuracy off REFERENCE
#: (docs/measurements.md, docs/report.md; this table's measured values: measurements.md).
ERROR_BOUNDS = {
    "REFERENCE": 0.0,    # the yardstick itself
    "BLOCKS": 0.01,      # tolerance 0.1 on glossy: 6.4e-5-1.9e-4 at 6×64², 7.2e-3 at 6×32²
    "AUTO": 0.02,        # its default target (auto_error_target), judged on the camera image
    "RSL": 0.05,         # 30 lights: 1.2-3.3 % (held-out, demo), 3.9 % mean over 11 lightings
    "WAVELET": 0.10,     # 1 % glossy kept: 1.45 % at 6×64², 9.8 % on a glossy Suzanne at 6×32²
    "SSDF_SG": 0.10,     # 2.0-3.6 % on the diffuse bench scenes, 8.2 % on the glossy bunny
    "SH": 0.10,          # order 4, diffuse only: 2.2 % (demo), 13.6 % off Cycles under a sun
}

#: Cases harder than a method's documented accuracy, with the reason: (case, method) -> bound
CASE_ERROR_BOUNDS = {
    # a lone delta light: order 4 leaves 8.8 % of max(cos, 0) itself (over all normals),
    # and rings across the ball's hard shadow
    ("1-pixel sun 1e6", "SH"): 0.20,
}


def error_bound(case_name: str, method_id: str):
    """The bound of :data:`CASE_ERROR_BOUNDS` or :data:`ERROR_BOUNDS` for a case's cell;
    a method's own cases (``"name [ID]"``) take its general bound; None for a method
    without one."""
    bound = CASE_ERROR_BOUNDS.get((case_name, method_id))
    return bound if bound is not None else ERROR_BOUNDS.get(method_id)


def stability_cases(method_ids=None):
    """:data:`BASE_CASES` plus the cases methods declare with
    ``Bench.stability_cases()`` (same dict form; e.g. SG sharpness 1e-3…1e5 or
    anisotropy 1:16 for a method with spherical Gaussians)."""
    cases = list(BASE_CASES)
    for m in methods.REGISTRY.values():
        if method_ids is not None and m.id not in method_ids:
            continue
        for case in m.bench.stability_cases():
            cases.append(dict(case, name=f"{case['name']} [{m.id}]"))
    return cases
