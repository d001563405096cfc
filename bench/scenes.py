# SPDX-License-Identifier: GPL-3.0-or-later
"""The one scene builder of the demo, the benchmarks and the tests (headless Blender).

Importing this module registers the repository as the package ``prt_relight`` (the
checkout directory may have any name); :func:`reset` also registers the add-on once, so a
script only needs::

    import scenes
    scenes.reset(); scenes.add_world("sunset"); scenes.add_ground(); ...

The tests import it as ``prt_relight.bench.scenes`` (their conftest registers the package
and the ``registered_addon`` fixture the add-on).  It lives with the benchmarks, outside the
add-on: it is development tooling (renders, timings, EXR files), not shipped in the
extension (bench/ is excluded from its zip); the add-on's own scene building (the report's
hard cases) is ``addon/blender/scene_build.py``, whose materials this module reuses.

Every image written here is linear scene radiance in a 32-bit float EXR unless the name
ends in ``.png`` (then the scene's view transform applies); images read back are
``(H, W, C)`` float32, top row first.  Errors between images are
``core.report.metrics.rel_l2`` (the report's figure), not defined here.
"""

from __future__ import annotations

import importlib.util
import math
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _package():
    """The repository imported as ``prt_relight`` (once; no Blender needed)."""
    mod = sys.modules.get("prt_relight")
    if mod is None:
        spec = importlib.util.spec_from_file_location(
            "prt_relight", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
        mod = importlib.util.module_from_spec(spec)
        sys.modules["prt_relight"] = mod
        spec.loader.exec_module(mod)
    return mod


_package()


def load_addon():
    """Import the repository as ``prt_relight`` and register the add-on (idempotent)."""
    mod = _package()
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
    """One of Blender's bundled HDRIs (``"sunset"``, ``"forest"``, ...)."""
    import bpy
    folder = pathlib.Path(bpy.utils.system_resource("DATAFILES", path="studiolights/world"))
    path = folder / (name if name.endswith(".exr") else name + ".exr")
    if not path.is_file():
        have = sorted(p.stem for p in folder.glob("*.exr"))
        raise SystemExit(f"HDRI '{name}' not found in {folder} (have: {', '.join(have)})")
    return path


def float_image(name: str, pixels_top_first: np.ndarray, is_data: bool = True):
    """A packed float image of the RGB of (H, W, 3|4) pixels given top row first, alpha 1."""
    import bpy
    h, w = pixels_top_first.shape[:2]
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[:, :, :3] = pixels_top_first[:, :, :3]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True, is_data=is_data)
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.pack()
    return img


def sun_image(width: int, height: int, direction, radiance: float = 1e3) -> np.ndarray:
    """A black equirect (H, W, 3) with one pixel of ``radiance`` where the world reads
    ``direction`` (Blender's convention ``u = 0.5 - atan2(y, x) / 2 pi``, ``v = acos(z) / pi``)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    u = (0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0
    v = math.acos(d[2]) / math.pi
    img = np.zeros((height, width, 3), dtype=np.float32)
    img[min(int(v * height), height - 1), min(int(u * width), width - 1)] = radiance
    return img


def add_world(hdri: str = "sunset", strength: float = 1.0, rotation_z: float = 0.0, *,
              image=None, path=None):
    """A world lit by an Environment Texture (+ a Mapping node turning it by ``rotation_z``):
    ``image`` (a bpy image, e.g. :func:`float_image`), else the image file ``path``, else
    Blender's bundled HDRI ``hdri``."""
    import bpy
    scene = bpy.context.scene
    world = bpy.data.worlds.new("PRT World")
    scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = next(n for n in nodes if n.type == "BACKGROUND")
    bg.inputs["Strength"].default_value = strength
    env = nodes.new("ShaderNodeTexEnvironment")
    if image is None:
        file = path if path is not None else hdri_path(hdri)
        image = bpy.data.images.load(str(file), check_existing=True)
    env.image = image
    links.new(env.outputs["Color"], bg.inputs["Color"])
    if rotation_z:
        coord = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
        links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return world


def environment_node(world=None):
    """The Environment Texture node of ``world`` (default: the scene's)."""
    import bpy
    world = world or bpy.context.scene.world
    return next(n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT")


# ------------------------------------------------------------------ objects

def add_ground(size: float = 6.0, cuts: int = 96, name: str = "Ground"):
    """A tessellated ground plane at z = 0 (per-vertex shading needs the cuts)."""
    import bpy
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size)
    ob = bpy.context.active_object
    ob.name = name
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


def add_suzanne(subdiv: int = 2, height: float = 1.6, location=None):
    """Smooth Suzanne with a Subdivision Surface modifier: tilted a little and scaled to
    ``height`` standing on the ground, or (``location`` given) as modelled, its origin at
    ``location``."""
    import bpy
    bpy.ops.mesh.primitive_monkey_add(location=location or (0.0, 0.0, 0.0))
    ob = bpy.context.active_object
    ob.name = "Suzanne"
    if location is None:
        ob.rotation_euler = (math.radians(-20.0), 0.0, 0.0)   # tilt the face up a little
    _smooth(ob)
    if subdiv:
        mod = ob.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = subdiv
    if location is None:
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


def set_resolution(width: int, height: int):
    """The render size in pixels (at 100 %)."""
    import bpy
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100


def add_camera(target=(0.0, 0.0, 0.75), distance: float = 5.5, elevation_deg: float = 20.0,
               azimuth_deg: float = -90.0, lens: float = 50.0, resolution=(320, 240), *,
               location=None, rotation=(0.0, 0.0, 0.0)):
    """The scene's perspective camera, on a sphere around ``target`` looking at it (azimuth
    -90 = from -Y), or (``location`` given) there with the Euler ``rotation``; it becomes
    the active object.  ``resolution`` (width, height) sets the render size (None: as it is)."""
    import bpy
    from mathutils import Vector
    if location is None:
        el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
        t = Vector(target)
        location = t + distance * Vector((math.cos(el) * math.cos(az),
                                          math.cos(el) * math.sin(az), math.sin(el)))
        rotation = (t - location).to_track_quat("-Z", "Y").to_euler()
    bpy.ops.object.camera_add(location=tuple(location), rotation=tuple(rotation))
    cam = bpy.context.object
    cam.data.lens = lens
    bpy.context.scene.camera = cam
    if resolution is not None:
        set_resolution(*resolution)
    return cam


def bsdf_material(name: str, node_type: str, **inputs):
    """A new material whose surface is one BSDF node (``inputs`` by socket name;
    ``distribution=`` sets the node's distribution): ``addon.blender.scene_build``'s."""
    from prt_relight.addon.blender.scene_build import bsdf_material as make
    return make(name, node_type, **inputs)


def add_bsdf_material(ob, name: str, node_type: str = "ShaderNodeBsdfGlossy", **inputs):
    """Give ``ob`` a :func:`bsdf_material` as its only material, e.g. a Beckmann Glossy BSDF::

        add_bsdf_material(ob, "Glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                          Roughness=0.25)
    """
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


# ------------------------------------------------------------------ instances

def instanced_herd(kind: str = "COLLECTION", count: int = 7, hdri: str = "city",
                   size=(64, 48), subdiv: int = 1, seed: int = 3, spread: float = 2.2):
    """``count`` instances of one Suzanne (``subdiv`` levels, 0.8 m tall) scattered and
    turned at random (``seed``) on a diffuse 6 m ground, the source in a collection
    excluded from the view layer: placed by ``kind`` ``"COLLECTION"`` (an empty per
    instance instancing the collection), ``"PARTICLES"`` (a hidden emitter whose particles
    render the object) or ``"NODES"`` (geometry nodes' Instance on Points with an Object
    Info node).  Returns the instancers (the empties, the emitter, the points object)."""
    import bpy
    reset()
    add_world(hdri)
    ground = add_ground(cuts=64)
    add_bsdf_material(ground, "Ground Diffuse", "ShaderNodeBsdfDiffuse",
                      Color=(0.8, 0.8, 0.8, 1.0))
    animal = add_suzanne(subdiv=subdiv, height=0.8)
    animal.name = "Animal"
    add_bsdf_material(animal, "Animal Diffuse", "ShaderNodeBsdfDiffuse",
                      Color=(0.7, 0.5, 0.3, 1.0))
    animal.location = (0.0, 0.0, animal.location.z)
    source = bpy.data.collections.new("Herd source")
    bpy.context.scene.collection.children.link(source)
    for c in list(animal.users_collection):
        c.objects.unlink(animal)
    source.objects.link(animal)
    bpy.context.view_layer.layer_collection.children[source.name].exclude = True
    rng = np.random.default_rng(seed)
    spots = rng.uniform(-spread, spread, (count, 2))
    turns = rng.uniform(0.0, 2.0 * math.pi, count)
    instancers = []
    if kind == "COLLECTION":
        for i, ((x, y), turn) in enumerate(zip(spots, turns)):
            ob = bpy.data.objects.new(f"Herd {i}", None)
            ob.instance_type, ob.instance_collection = "COLLECTION", source
            ob.location, ob.rotation_euler = (x, y, 0.0), (0.0, 0.0, turn)
            bpy.context.scene.collection.objects.link(ob)
            instancers.append(ob)
    elif kind in ("PARTICLES", "NODES"):
        mesh = bpy.data.meshes.new("Herd points")
        mesh.from_pydata([(x, y, 0.0) for x, y in spots], [], [])
        ob = bpy.data.objects.new("Herd", mesh)
        bpy.context.scene.collection.objects.link(ob)
        instancers.append(ob)
        if kind == "PARTICLES":
            ps = ob.modifiers.new("Herd", "PARTICLE_SYSTEM").particle_system
            st = ps.settings
            st.count, st.emit_from, st.use_emit_random = count, "VERT", False
            st.frame_start = st.frame_end = 1
            st.lifetime, st.physics_type = 10000, "NO"
            st.render_type, st.instance_object, st.particle_size = "OBJECT", animal, 1.0
            st.use_rotations, st.rotation_mode = True, "GLOB_Z"    # lying on their side
            st.phase_factor_random = 2.0           # turned at random about that axis
            ob.show_instancer_for_render = ob.show_instancer_for_viewport = False
        else:
            _instance_on_points(ob, animal, turns)
    else:
        raise ValueError(f"unknown kind of instances: {kind}")
    add_camera(target=(0.0, 0.0, 0.3), distance=7.5, elevation_deg=35.0, resolution=size)
    bpy.context.view_layer.update()
    return instancers


def _instance_on_points(ob, source, turns):
    """Geometry nodes on ``ob``: ``source`` (Object Info, as an instance) on each of its
    points, turned about z by the point's ``turns``."""
    import bpy
    tree = bpy.data.node_groups.new("Herd nodes", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = tree.nodes, tree.links
    given, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = source
    info.inputs["As Instance"].default_value = True
    info.transform_space = "RELATIVE"          # the source as it stands, placed per point
    place = nodes.new("GeometryNodeInstanceOnPoints")
    turn = nodes.new("GeometryNodeInputNamedAttribute")
    turn.data_type = "FLOAT"
    turn.inputs["Name"].default_value = "turn"
    combine = nodes.new("ShaderNodeCombineXYZ")
    links.new(given.outputs[0], place.inputs["Points"])
    links.new(info.outputs["Geometry"], place.inputs["Instance"])
    links.new(turn.outputs["Attribute"], combine.inputs["Z"])
    links.new(combine.outputs["Vector"], place.inputs["Rotation"])
    links.new(place.outputs["Instances"], out.inputs[0])
    attr = ob.data.attributes.new("turn", "FLOAT", "POINT")
    attr.data.foreach_set("value", np.asarray(turns, np.float32))
    ob.modifiers.new("Herd", "NODES").node_group = tree


# ------------------------------------------------------------------ scenes with bounced light

def light_paths(bounces: int):
    """The scene's Cycles Light Paths: ``bounces`` diffuse bounces (0: direct light only)."""
    import bpy
    scene = bpy.context.scene
    scene.cycles.max_bounces = 12 if bounces else 0
    scene.cycles.diffuse_bounces = max(int(bounces), 1)


def _diffuse(name: str, colour):
    return bsdf_material(name, "ShaderNodeBsdfDiffuse", Color=(*colour, 1.0))


def cornell_box(size=(96, 96)):
    """Five inward-facing 2 m walls (red left, green right), a box, a 0.5 m area lamp under
    the ceiling, a black world; the camera looks in through the open front.  Returns the
    lamp."""
    import bpy
    reset()
    walls = (("Floor", (0, 0, 0), (0, 0, 0), (0.8, 0.8, 0.8)),
             ("Ceiling", (0, 0, 2), (math.pi, 0, 0), (0.8, 0.8, 0.8)),
             ("Back", (0, 1, 1), (math.pi / 2, 0, 0), (0.8, 0.8, 0.8)),
             ("Left", (-1, 0, 1), (0, math.pi / 2, 0), (0.8, 0.1, 0.1)),
             ("Right", (1, 0, 1), (0, -math.pi / 2, 0), (0.1, 0.8, 0.1)))
    for name, loc, rot, col in walls:
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=2,
                                        location=loc, rotation=rot)
        bpy.context.object.name = name
        bpy.context.object.data.materials.append(_diffuse(name, col))
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(-0.35, 0.3, 0.3))
    bpy.context.object.data.materials.append(_diffuse("Box", (0.8, 0.8, 0.8)))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 1.98))
    lamp = bpy.context.object
    lamp.data.size, lamp.data.energy = 0.5, 60.0
    world = bpy.data.worlds.new("Black")
    bpy.context.scene.world = world
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    add_camera(location=(0, -3.4, 1), rotation=(math.pi / 2, 0, 0), resolution=size)
    bpy.context.scene.camera.data.lens = 35
    return lamp


def window_room(size=(64, 48), hdri: str = "sunrise"):
    """A 4 x 4 x 2.6 m room made as a box whose normals face out (its walls are seen from
    behind: two-sided), a window cut in the +x wall, a box inside; lit by ``hdri``, whose
    sun falls through the window.  Returns the room."""
    import bmesh
    import bpy
    reset()
    add_world(hdri)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bmesh.ops.scale(bm, vec=(4, 4, 2.6), verts=bm.verts)
    bmesh.ops.translate(bm, vec=(0, 0, 1.3), verts=bm.verts)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=15, use_grid_fill=True)
    window = [f for f in bm.faces if f.normal.x > 0.9 and abs(f.calc_center_median().y) < 0.9
              and 0.8 < f.calc_center_median().z < 2.0]
    bmesh.ops.delete(bm, geom=window, context="FACES")
    mesh = bpy.data.meshes.new("Room")
    bm.to_mesh(mesh)
    bm.free()
    room = bpy.data.objects.new("Room", mesh)
    bpy.context.collection.objects.link(room)
    room.data.materials.append(_diffuse("Wall", (0.75, 0.72, 0.68)))
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(-0.6, 0.5, 0.4))
    bpy.context.object.data.materials.append(_diffuse("Box", (0.6, 0.2, 0.15)))
    add_camera(location=(-1.8, -1.8, 1.5), rotation=(math.radians(80), 0, math.radians(-50)),
               resolution=size)
    bpy.context.scene.camera.data.lens = 18
    return room


def coloured_ground(size=(80, 60), hdri: str = "courtyard", subdiv: int = 1):
    """Suzanne (Principled grey, roughness 0.6) over an orange Principled ground (roughness
    0.8) under ``hdri``: the ground's colour bleeds onto her.  Returns Suzanne."""
    reset()
    add_world(hdri)
    ground = add_ground(size=8, cuts=40)
    ground.data.materials.append(bsdf_material(
        "Ground", "ShaderNodeBsdfPrincipled", **{"Base Color": (0.7, 0.35, 0.15, 1),
                                                 "Roughness": 0.8}))
    suzanne = add_suzanne(location=(0, 0, 1), subdiv=subdiv)
    suzanne.data.materials.append(bsdf_material(
        "Grey", "ShaderNodeBsdfPrincipled", **{"Base Color": (0.8, 0.8, 0.8, 1),
                                               "Roughness": 0.6}))
    add_camera(location=(0, -5.5, 2.2), rotation=(1.25, 0, 0), resolution=size)
    return suzanne


# ------------------------------------------------------------------ scenes with many lamps

def spot_rows_scene(count: int, power: float = 60.0, spot_deg: float = 50.0):
    """An interior lit by rows of spots (issue 31's many lamps): a 10 m floor with three
    Suzannes, ``count`` spots of ``power`` W in a square grid 3 m up pointing down (cone
    ``spot_deg``, blend 0.3, radius 5 cm, named Spot00...), a dim uniform World and a
    camera looking down the room.  Returns the scene."""
    import bpy
    scene = reset()
    add_world(image=float_image("dim", np.full((8, 16, 3), 0.02, np.float32)))
    add_ground(size=10.0, cuts=32)
    for k, x in enumerate((-2.5, 0.0, 2.5)):
        add_suzanne(subdiv=1, location=(x, 0.5 * k, 0.8))
    side = max(1, round(math.sqrt(count)))
    for i in range(count):
        r, c = divmod(i, side)
        light = bpy.data.lights.new(f"Spot{i:02d}", "SPOT")
        light.energy, light.shadow_soft_size = power, 0.05
        light.spot_size, light.spot_blend = math.radians(spot_deg), 0.3
        ob = bpy.data.objects.new(f"Spot{i:02d}", light)
        ob.location = (-4.0 + 8.0 * (c + 0.5) / side, -4.0 + 8.0 * (r + 0.5) / side, 3.0)
        scene.collection.objects.link(ob)
    add_camera(location=(0.0, -8.0, 5.0), rotation=(1.0, 0.0, 0.0), resolution=None)
    return scene


# ------------------------------------------------------------------ rendering

def save_render(path):
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


def render(paths=(), engine: str = "PRT_RELIGHT", samples: int = 256, transparent: bool = True,
           seed: int | None = None) -> float:
    """F12 with ``engine`` (Cycles: the scene's Light Paths -- :func:`reset` makes them
    direct light only --, CPU, ``samples`` per pixel with ``seed`` (None: the scene's), no
    denoising, no adaptive sampling), film transparent unless told; saved to each of
    ``paths``.  Returns the render's seconds."""
    import bpy
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.film_transparent = transparent
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.use_denoising = False
        if seed is not None:
            scene.cycles.seed = seed
    t0 = time.perf_counter()
    bpy.ops.render.render()
    seconds = time.perf_counter() - t0
    for p in paths:
        save_render(p)
    return seconds


def render_exr(path, engine: str = "PRT_RELIGHT", samples: int = 64, transparent: bool = True,
               seed: int | None = None) -> np.ndarray:
    """:func:`render` to the EXR ``path`` and its pixels read back (H, W, 4), top row first."""
    render([path], engine, samples, transparent, seed)
    return read_exr(path)


def render_cycles(path, samples: int = 256, png=None, seed: int = 0) -> float:
    """Cycles with the scene's Light Paths (ground truth; :func:`reset` makes them direct
    light only), saved as EXR; returns seconds."""
    return render([path] + ([png] if png else []), "CYCLES", samples, seed=seed)


def render_prt(path, png=None) -> float:
    """F12 with the PRT_RELIGHT engine, saved as EXR; returns seconds."""
    return render([path] + ([png] if png else []))


def render_workbench(path=None) -> float:
    """F12 with Workbench (timing baseline); returns seconds."""
    return render([path] if path else [], "BLENDER_WORKBENCH")


def render_eevee(path=None, samples: int = 16) -> float:
    """F12 with EEVEE at ``samples`` render samples (timing baseline); returns seconds."""
    import bpy
    bpy.context.scene.eevee.taa_render_samples = samples
    return render([path] if path else [], "BLENDER_EEVEE")


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
