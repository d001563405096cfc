# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene builders shared by the demo, the benchmarks and tests.

Importing this module registers the repository as the package ``prt_relight``
(the checkout directory may have any name) and registers the add-on once, so a
script only needs ``from scenes import *`` style imports::

    import scenes
    scenes.reset(); scenes.add_world("sunset"); scenes.add_ground(); ...

Every image written here is linear scene radiance in a 32-bit float EXR
unless the name ends in ``.png`` (then the scene's view transform applies).
"""

from __future__ import annotations

import importlib.util
import math
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]


def load_addon():
    """Import the repository as ``prt_relight`` and register it (idempotent)."""
    mod = sys.modules.get("prt_relight")
    if mod is None:
        spec = importlib.util.spec_from_file_location(
            "prt_relight", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
        mod = importlib.util.module_from_spec(spec)
        sys.modules["prt_relight"] = mod
        spec.loader.exec_module(mod)
    import bpy
    if not hasattr(bpy.types.Scene, "prt"):
        mod.register()
    return mod


def reset(bounces: int = 0):
    """An empty scene (factory settings) with the add-on registered; its Cycles Light Paths
    allow ``bounces`` diffuse bounces (0: direct light, what most benches compare)."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    load_addon()
    scene = bpy.context.scene
    scene.cycles.max_bounces = 12 if bounces else 0
    scene.cycles.diffuse_bounces = max(int(bounces), 1)
    return scene


# ------------------------------------------------------------------ world

def hdri_path(name: str) -> pathlib.Path:
    import bpy
    folder = pathlib.Path(bpy.utils.system_resource("DATAFILES", path="studiolights/world"))
    path = folder / (name if name.endswith(".exr") else name + ".exr")
    if not path.is_file():
        have = sorted(p.stem for p in folder.glob("*.exr"))
        raise SystemExit(f"HDRI '{name}' not found in {folder} (have: {', '.join(have)})")
    return path


def add_world(hdri_name: str = "sunset", strength: float = 1.0, rotation_z: float = 0.0):
    """A world lit by one of Blender's bundled HDRIs (Environment Texture [+ Mapping])."""
    import bpy
    scene = bpy.context.scene
    world = bpy.data.worlds.new("PRT World")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = next(n for n in nodes if n.type == "BACKGROUND")
    bg.inputs["Strength"].default_value = strength
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(hdri_path(hdri_name)), check_existing=True)
    links.new(env.outputs["Color"], bg.inputs["Color"])
    if rotation_z:
        coord = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
        links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return world


# ------------------------------------------------------------------ objects

def add_ground(size: float = 6.0, cuts: int = 96):
    """A tessellated ground plane at z = 0 (per-vertex shading needs the cuts)."""
    import bpy
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size)
    ob = bpy.context.active_object
    ob.name = "Ground"
    return ob


def _stand_on_ground(ob, height: float):
    """Scale ``ob`` to ``height`` and move it so it rests on z = 0, centred at x = y = 0."""
    import bpy
    from mathutils import Vector
    bpy.context.view_layer.update()
    corners = [ob.matrix_world @ Vector(c) for c in ob.bound_box]
    lo = Vector([min(c[i] for c in corners) for i in range(3)])
    hi = Vector([max(c[i] for c in corners) for i in range(3)])
    s = height / max(hi.z - lo.z, 1e-9)
    ob.scale = ob.scale * s
    centre = (lo + hi) / 2
    ob.location = Vector((ob.location.x - centre.x * s, ob.location.y - centre.y * s,
                          ob.location.z - lo.z * s))
    bpy.context.view_layer.update()


def _smooth(ob):
    for poly in ob.data.polygons:
        poly.use_smooth = True


def add_suzanne(subdiv: int = 2, height: float = 1.6):
    """Smooth Suzanne with a Subdivision Surface modifier, standing on the ground."""
    import bpy
    bpy.ops.mesh.primitive_monkey_add()
    ob = bpy.context.active_object
    ob.name = "Suzanne"
    ob.rotation_euler = (math.radians(-20.0), 0.0, 0.0)   # tilt the face up a little
    _smooth(ob)
    if subdiv:
        mod = ob.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = subdiv
    _stand_on_ground(ob, height)
    return ob


def add_obj(path, height: float = 1.6, forward_axis: str = "NEGATIVE_Z", up_axis: str = "Y"):
    """Import an OBJ, scale it to ``height``, stand it on the ground, smooth shading."""
    import bpy
    path = pathlib.Path(path)
    if not path.is_file():
        raise SystemExit(f"mesh not found: {path}")
    before = set(bpy.data.objects)
    bpy.ops.wm.obj_import(filepath=str(path), forward_axis=forward_axis, up_axis=up_axis)
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if not new:
        raise SystemExit(f"no mesh imported from {path}")
    ob = new[0]
    if len(new) > 1:                       # several groups: join them into one object
        with bpy.context.temp_override(active_object=ob, selected_editable_objects=new):
            bpy.ops.object.join()
    ob.name = path.stem
    _smooth(ob)
    _stand_on_ground(ob, height)
    return ob


def add_camera(target=(0.0, 0.0, 0.75), distance: float = 5.5, elevation_deg: float = 20.0,
               azimuth_deg: float = -90.0, lens: float = 50.0, resolution=(320, 240)):
    """A perspective camera on a sphere around ``target``, looking at it (azimuth -90 = from -Y)."""
    import bpy
    from mathutils import Vector
    scene = bpy.context.scene
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    t = Vector(target)
    pos = t + distance * Vector((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                                 math.sin(el)))
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    cam.location = pos
    cam.rotation_euler = (t - pos).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    return cam


def add_bsdf_material(ob, name: str, node_type: str = "ShaderNodeBsdfGlossy", **inputs):
    """Give ``ob`` a material whose surface is one BSDF node (``inputs`` by socket name;
    ``distribution=`` sets the node's distribution), e.g. a Beckmann Glossy BSDF::

        add_bsdf_material(ob, "Glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                          Roughness=0.25)
    """
    from prt_relight.addon.blender.scene_build import bsdf_material
    mat = bsdf_material(name, node_type, **inputs)
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    return mat


def glossy_bunny_scene(hdri: str = "city", roughness: float = 0.25, cuts: int = 96,
                       mesh=None, rotation_z: float = 0.6):
    """Held-out glossy scene (BLOCKS bench): the Stanford bunny with a Beckmann Glossy BSDF
    (white, ``roughness``) on a diffuse (0.8) ground grid, lit by a bundled HDRI."""
    reset()
    add_world(hdri, rotation_z=rotation_z)
    ground = add_ground(cuts=cuts)
    add_bsdf_material(ground, "Ground Diffuse", "ShaderNodeBsdfDiffuse",
                      Color=(0.8, 0.8, 0.8, 1.0))
    mesh = pathlib.Path(mesh) if mesh else ROOT.parent / "shared/data/meshes/stanford-bunny.obj"
    ob = add_obj(mesh) if mesh.is_file() else add_suzanne()
    add_bsdf_material(ob, "Bunny Glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                      Roughness=roughness, Color=(1.0, 1.0, 1.0, 1.0))
    add_camera()
    return ob


# ------------------------------------------------------------------ rendering

def _save_render(path):
    """Save the Render Result: .exr as linear 32-bit float, .png through the view transform."""
    import bpy
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    settings = bpy.context.scene.render.image_settings
    if path.suffix.lower() == ".exr":
        settings.file_format = "OPEN_EXR"
        settings.color_depth = "32"
        settings.color_mode = "RGBA"
    else:
        settings.file_format = "PNG"
        settings.color_depth = "8"
        settings.color_mode = "RGBA"
    bpy.data.images["Render Result"].save_render(str(path))


def _render(engine, paths):
    import bpy
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.film_transparent = True
    t0 = time.perf_counter()
    bpy.ops.render.render()
    seconds = time.perf_counter() - t0
    for p in paths:
        _save_render(p)
    return seconds


def render_cycles(path, samples: int = 256, png=None, seed: int = 0) -> float:
    """Direct-light-only Cycles render (ground truth), saved as EXR; returns seconds."""
    import bpy
    scene = bpy.context.scene
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    scene.cycles.seed = seed
    return _render("CYCLES", [path] + ([png] if png else []))


def render_prt(path, png=None) -> float:
    """F12 with the PRT_RELIGHT engine, saved as EXR; returns seconds."""
    return _render("PRT_RELIGHT", [path] + ([png] if png else []))


def render_workbench(path=None) -> float:
    """F12 with Workbench (timing baseline); returns seconds."""
    return _render("BLENDER_WORKBENCH", [path] if path else [])


def precompute(resolution: int = 32, threads=None, method: str = "REFERENCE") -> dict:
    """Run the add-on's gather/run/commit (what ``prt.precompute`` does) and return timings.

    Keys: export, build_bvh, rays, storage, ray_count, rays_per_second, points, total.
    """
    import bpy
    from prt_relight.addon.blender import precompute as pc
    scene = bpy.context.scene
    scene.prt.method = method          # derive/store run for the active method only
    scene.prt.resolution = str(resolution)
    t0 = time.perf_counter()
    job = pc.gather(bpy.context.evaluated_depsgraph_get(), scene.prt)
    job.timings["export"] = time.perf_counter() - t0
    job.run(threads=threads)
    pc.commit(scene, job)
    t = dict(job.timings)
    t["points"] = job.point_count
    t["total"] = time.perf_counter() - t0
    t["warnings"] = job.warnings + [o.coarse_warning for o in job.objects if o.coarse_warning]
    t["report"] = scene.prt.last_report
    return t


# ------------------------------------------------------------------ images

def read_exr(path) -> np.ndarray:
    """(H, W, C) float32 of an EXR, top row first."""
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise RuntimeError(f"cannot read {path}: {buf.geterror()}")
    return np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float32)


def rel_l2(a: np.ndarray, b: np.ndarray, mask_from=None) -> float:
    """||a - b|| / ||b|| over RGB of the pixels where ``b``'s alpha > 0.5.

    ``b`` is the reference (Cycles); ``mask_from`` overrides the image whose
    alpha selects the pixels.
    """
    ref_alpha = (mask_from if mask_from is not None else b)
    mask = ref_alpha[..., 3] > 0.5 if ref_alpha.shape[-1] > 3 else np.ones(b.shape[:2], bool)
    da = a[..., :3][mask].astype(np.float64)
    db = b[..., :3][mask].astype(np.float64)
    return float(np.linalg.norm(da - db) / max(np.linalg.norm(db), 1e-30))
