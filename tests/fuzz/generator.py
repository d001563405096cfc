"""Random scenes for the scene fuzzer (issue 31): one integer seed makes one small scene
(``build``), mixing what an artist's file holds -- open and closed meshes, degenerate,
empty, huge, tiny, mirrored and flattened geometry, modifiers, collection instances (and
instances of instances), particles, lamps of every type and count, plain and textured
materials, a rotated HDRI, a plain colour or no World, bounces, every method, dynamic
objects -- at a size (32 x 24 pixels, 6 x 32² directions) where one scene takes seconds.

The same seed builds the same scene (numpy's ``default_rng``); ``build`` returns a line
per choice it made, printed with a failing seed."""

from __future__ import annotations

import math

import bpy
import numpy as np

from prt_relight.bench import scenes

METHODS = ("REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET", "AUTO")
HDRIS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")
LAMPS = ("POINT", "SUN", "SPOT", "AREA")
AREA_SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")
GLOSSY = ("BECKMANN", "GGX", "MULTI_GGX", "ASHIKHMIN_SHIRLEY")


class _Scene:
    """What ``build`` carries between its steps: the generator and the notes."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)
        self.notes: list[str] = []
        self.count = 0

    def pick(self, options, p=None):
        return options[int(self.rng.choice(len(options), p=p))]

    def coin(self, p: float) -> bool:
        return bool(self.rng.random() < p)

    def name(self, kind: str) -> str:
        self.count += 1
        return f"{kind}{self.count:02d}"

    def note(self, text: str):
        self.notes.append(text)


def build(seed: int) -> list[str]:
    """Make scene ``seed`` from factory settings (the add-on registered); returns what it
    holds, a line per choice."""
    s = _Scene(seed)
    bounces = s.pick((0, 1, 4))               # 4: Cycles' default Light Paths
    scene = scenes.reset(bounces=bounces)
    s.note(f"bounces {bounces}")
    _world(s)
    for _ in range(int(s.rng.integers(0, 5))):
        _object(s, scene.collection)
    if s.coin(0.3):
        _instances(s, scene)
    if s.coin(0.15):
        _particles(s, scene)
    n_lamps = s.pick((0, int(s.rng.integers(1, 4)), int(s.rng.integers(4, 13))), p=(0.3, 0.4, 0.3))
    for _ in range(n_lamps):
        _lamp(s, scene)
    _camera(s, scene)
    _settings(s, scene, n_lamps)
    bpy.context.view_layer.update()
    return s.notes


# ------------------------------------------------------------------ world

def _world(s: _Scene):
    scene = bpy.context.scene
    kind = s.pick(("hdri", "colour", "none"), p=(0.7, 0.2, 0.1))
    if kind == "none":
        scene.world = None
        s.note("no world")
        return
    strength = s.pick((1.0, float(s.rng.uniform(0.0, 4.0)), 0.0), p=(0.6, 0.3, 0.1))
    if kind == "colour":
        world = bpy.data.worlds.new("Colour")
        scene.world = world
        bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
        colour = s.rng.uniform(0.0, 1.0, 3)
        bg.inputs["Color"].default_value = (*colour, 1.0)
        bg.inputs["Strength"].default_value = strength
        s.note(f"colour world {np.round(colour, 2).tolist()} x {strength:.2f}")
        return
    hdri = s.pick(HDRIS)
    rotation = s.rng.uniform(-math.pi, math.pi, 3) * s.pick((0.0, 1.0), p=(0.3, 0.7))
    world = scenes.add_world(hdri, strength, rotation_z=float(rotation[2]) or 1e-3)
    mapping = next(n for n in world.node_tree.nodes if n.type == "MAPPING")
    mapping.vector_type = s.pick(("POINT", "VECTOR", "TEXTURE"))
    mapping.inputs["Rotation"].default_value = tuple(rotation[:2]) + (float(rotation[2]) or 1e-3,)
    s.note(f"hdri {hdri} x {strength:.2f}, mapping {mapping.vector_type} "
           f"{np.round(rotation, 2).tolist()}")


# ------------------------------------------------------------------ meshes

def _from_pydata(name, verts, faces, edges=()):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, list(edges), faces)
    ob = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _primitive(s: _Scene, kind: str):
    """A new mesh object of ``kind`` in the scene's collection."""
    ops = bpy.ops.mesh
    if kind == "grid":
        cuts = int(s.rng.integers(1, 13))
        ops.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts,
                               size=float(s.rng.uniform(2.0, 8.0)))
    elif kind == "plane":
        ops.primitive_plane_add(size=float(s.rng.uniform(0.5, 3.0)))
    elif kind == "sphere":
        ops.primitive_uv_sphere_add(segments=int(s.rng.integers(4, 17)),
                                    ring_count=int(s.rng.integers(3, 9)))
    elif kind == "ico":
        ops.primitive_ico_sphere_add(subdivisions=int(s.rng.integers(1, 3)))
    elif kind == "cube":
        ops.primitive_cube_add()
    elif kind == "monkey":
        ops.primitive_monkey_add()
    elif kind == "open cylinder":
        ops.primitive_cylinder_add(vertices=int(s.rng.integers(3, 17)), end_fill_type="NOTHING")
    elif kind == "triangle":
        return _from_pydata(s.name("Triangle"), [(0, 0, 0), (1, 0, 0), (0, 1, 0.2)], [(0, 1, 2)])
    elif kind == "degenerate":
        # zero-area triangles (collinear, and three corners at one point), duplicate
        # vertices (one position, several indices) and one proper triangle
        verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (1, 1, 0), (1, 1, 0), (1, 1, 0),
                 (0, 0, 1), (1, 0, 1), (0, 1, 1), (0, 0, 1)]
        return _from_pydata(s.name("Degenerate"), verts,
                            [(0, 1, 2), (3, 4, 5), (6, 7, 8), (9, 7, 8)])
    elif kind == "empty mesh":
        return _from_pydata(s.name("EmptyMesh"), [], [])
    elif kind == "loose":
        return _from_pydata(s.name("Loose"), [(0, 0, 0), (1, 0, 0), (1, 1, 1)], [],
                            edges=[(0, 1)])
    else:
        raise ValueError(kind)
    ob = bpy.context.object
    ob.name = s.name(kind.title().replace(" ", ""))
    if s.coin(0.5):
        for poly in ob.data.polygons:
            poly.use_smooth = True
    return ob


MESH_KINDS = ("grid", "plane", "sphere", "ico", "cube", "monkey", "open cylinder", "triangle",
              "degenerate", "empty mesh", "loose")
MESH_P = (0.14, 0.1, 0.14, 0.1, 0.12, 0.08, 0.08, 0.06, 0.06, 0.06, 0.06)


def _transform(s: _Scene, ob):
    ob.location = (*s.rng.uniform(-2.0, 2.0, 2), float(s.rng.uniform(0.0, 2.0)))
    ob.rotation_euler = tuple(s.rng.uniform(0.0, 2.0 * math.pi, 3) * s.pick((0.0, 1.0)))
    kind = s.pick(("uniform", "non-uniform", "negative", "flat", "huge", "tiny"),
                  p=(0.6, 0.12, 0.1, 0.06, 0.06, 0.06))
    if kind == "uniform":
        scale = np.full(3, s.rng.uniform(0.3, 1.5))
    elif kind == "non-uniform":
        scale = s.rng.uniform(0.1, 3.0, 3)
    elif kind == "negative":
        scale = s.rng.uniform(0.3, 1.5, 3) * np.where(s.rng.random(3) < 0.5, -1.0, 1.0)
        scale[0] = -abs(scale[0])
    elif kind == "flat":                       # zero along one axis: a singular matrix
        scale = np.ones(3)
        scale[int(s.rng.integers(0, 3))] = 0.0
    else:
        scale = np.full(3, 1e4 if kind == "huge" else 1e-4)
    ob.scale = tuple(scale)
    return kind


def _modifiers(s: _Scene, ob):
    added = []
    if s.coin(0.12):
        mod = ob.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = 1
        added.append("subsurf")
    if s.coin(0.12):
        mod = ob.modifiers.new("Solidify", "SOLIDIFY")
        mod.thickness = float(s.rng.uniform(-0.2, 0.2))
        added.append("solidify")
    if s.coin(0.12):
        mod = ob.modifiers.new("Mirror", "MIRROR")
        mod.use_axis = tuple(bool(b) for b in s.rng.random(3) < 0.5)
        added.append("mirror")
    if s.coin(0.12):
        mod = ob.modifiers.new("Array", "ARRAY")
        mod.count = int(s.rng.integers(1, 4))
        mod.relative_offset_displace = tuple(s.rng.uniform(-1.5, 1.5, 3))
        added.append("array")
    return added


def _object(s: _Scene, collection, dynamic_ok: bool = True):
    """A random mesh object, transformed, with modifiers and a material, linked to
    ``collection`` only."""
    kind = s.pick(MESH_KINDS, p=MESH_P)
    ob = _primitive(s, kind)
    scale = _transform(s, ob)
    mods = _modifiers(s, ob)
    mat = _material(s, ob)
    if collection is not bpy.context.scene.collection:
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        collection.objects.link(ob)
    dynamic = dynamic_ok and s.coin(0.12)
    ob.prt.dynamic = dynamic
    s.note(f"{ob.name}: {kind}, scale {scale}, modifiers {mods or 'none'}, material {mat}"
           + (", dynamic" if dynamic else "") + f" (in {collection.name})")
    return ob


# ------------------------------------------------------------------ materials

def _image(s: _Scene, name: str, colorspace: str, normal: bool = False):
    """A packed float image of random size and pixels (a normal map: near +z)."""
    h, w = (int(v) for v in s.rng.integers(1, 17, 2))
    rgba = np.ones((h, w, 4), np.float32)
    if normal:
        tilt = s.rng.uniform(-0.4, 0.4, (h, w, 2))
        rgba[..., :2] = 0.5 + 0.5 * tilt
        rgba[..., 2] = 0.5 + 0.5 * np.sqrt(np.clip(1.0 - (tilt ** 2).sum(-1), 0.0, 1.0))
    else:
        rgba[..., :3] = s.rng.uniform(0.0, 1.0, (h, w, 3))
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = colorspace          # first: it regenerates the buffer
    img.pixels.foreach_set(rgba.reshape(-1))
    img.pack()
    return img


def _material(s: _Scene, ob) -> str:
    if ob.type != "MESH" or s.coin(0.2):
        return "none"
    node_type = s.pick(("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
                        "ShaderNodeBsdfPrincipled"))
    colour = (*s.rng.uniform(0.0, 1.0, 3), 1.0)
    roughness = s.pick((0.0, 1.0, float(s.rng.uniform(0.0, 1.0))), p=(0.2, 0.2, 0.6))
    inputs = {}
    if node_type == "ShaderNodeBsdfDiffuse":
        inputs = {"Color": colour, "Roughness": roughness}
    elif node_type == "ShaderNodeBsdfGlossy":
        inputs = {"Color": colour, "Roughness": roughness, "distribution": s.pick(GLOSSY)}
    else:
        metallic = s.pick((0.0, 1.0, float(s.rng.uniform(0.0, 1.0))))
        inputs = {"Base Color": colour, "Roughness": roughness, "Metallic": metallic}
    mat = scenes.bsdf_material(s.name("Mat"), node_type, **inputs)
    what = f"{node_type[len('ShaderNodeBsdf'):]} roughness {roughness:.2f}"
    nt = mat.node_tree
    out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    bsdf = out.inputs["Surface"].links[0].from_node    # Glossy is an Anisotropic node
    if s.coin(0.35):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = _image(s, s.name("Colour"), s.pick(("sRGB", "Non-Color")))
        tex.interpolation = s.pick(("Linear", "Closest"))
        nt.links.new(tex.outputs["Color"], bsdf.inputs[0])
        what += ", colour texture"
    if node_type != "ShaderNodeBsdfDiffuse" and s.coin(0.25):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = _image(s, s.name("Rough"), "Non-Color")
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
        what += ", roughness texture"
    if s.coin(0.2):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = _image(s, s.name("Normal"), "Non-Color", normal=True)
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nmap.inputs["Strength"].default_value = float(s.rng.uniform(0.0, 2.0))
        nt.links.new(tex.outputs["Color"], nmap.inputs["Color"])
        nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
        what += ", normal map"
    ob.data.materials.append(mat)
    return what


# ------------------------------------------------------------------ instances

def _hidden_collection(scene, name):
    """A collection linked to the scene and excluded from its view layer (a source)."""
    coll = bpy.data.collections.new(name)
    scene.collection.children.link(coll)
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    return coll


def _instancer(s: _Scene, collection, into):
    ob = bpy.data.objects.new(s.name("Instancer"), None)
    ob.instance_type, ob.instance_collection = "COLLECTION", collection
    ob.location = (*s.rng.uniform(-2.0, 2.0, 2), float(s.rng.uniform(0.0, 1.0)))
    ob.rotation_euler = (0.0, 0.0, float(s.rng.uniform(0.0, 2.0 * math.pi)))
    ob.scale = (float(s.rng.choice((1.0, 0.5, -1.0))),) * 3
    into.objects.link(ob)
    return ob


def _instances(s: _Scene, scene):
    """Collection instances of one or two objects, and sometimes instances of an
    instancer of them (instances of instances)."""
    source = _hidden_collection(scene, s.name("Source"))
    for _ in range(int(s.rng.integers(1, 3))):
        _object(s, source, dynamic_ok=False)
    n = int(s.rng.integers(1, 4))
    for _ in range(n):
        ob = _instancer(s, source, scene.collection)
        ob.prt.dynamic = s.coin(0.1)
    s.note(f"{n} instances of {source.name}")
    if s.coin(0.5):
        outer = _hidden_collection(scene, s.name("Outer"))
        _instancer(s, source, outer)
        if s.coin(0.5):
            _object(s, outer, dynamic_ok=False)
        m = int(s.rng.integers(1, 3))
        for _ in range(m):
            _instancer(s, outer, scene.collection)
        s.note(f"{m} instances of {outer.name}, which instances {source.name}")


def _particles(s: _Scene, scene):
    """A grid emitting a few particles that render a hidden object."""
    source = _hidden_collection(scene, s.name("ParticleSource"))
    shape = _object(s, source, dynamic_ok=False)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=3, y_subdivisions=3, size=3.0)
    emitter = bpy.context.object
    emitter.name = s.name("Emitter")
    ps = emitter.modifiers.new("Particles", "PARTICLE_SYSTEM").particle_system
    st = ps.settings
    st.count = int(s.rng.integers(1, 7))
    st.frame_start = st.frame_end = 1
    st.lifetime, st.physics_type = 10000, "NO"
    st.render_type, st.instance_object = "OBJECT", shape
    st.particle_size = float(s.rng.uniform(0.05, 0.6))
    st.use_rotations = s.coin(0.5)
    emitter.show_instancer_for_render = s.coin(0.5)
    s.note(f"{emitter.name}: {st.count} particles of {shape.name}, emitter "
           f"{'shown' if emitter.show_instancer_for_render else 'hidden'}")


# ------------------------------------------------------------------ lamps, camera, settings

def _lamp(s: _Scene, scene):
    kind = s.pick(LAMPS)
    light = bpy.data.lights.new(s.name(kind.title()), kind)
    zero = s.coin(0.1)
    if kind == "SUN":
        light.energy = 0.0 if zero else float(10 ** s.rng.uniform(-1.0, 1.0))
        light.angle = s.pick((0.0, float(s.rng.uniform(0.0, 0.6))))
    else:
        light.energy = 0.0 if zero else float(10 ** s.rng.uniform(0.0, 3.3))
        light.shadow_soft_size = s.pick((0.0, float(s.rng.uniform(0.0, 1.0))))
    light.color = tuple(s.rng.uniform(0.0, 1.0, 3))
    extra = ""
    if kind == "SPOT":
        light.spot_size = float(s.rng.uniform(0.02, math.pi))
        light.spot_blend = float(s.rng.uniform(0.0, 1.0))
        extra = f", cone {light.spot_size:.2f}"
    elif kind == "AREA":
        light.shape = s.pick(AREA_SHAPES)
        light.size = s.pick((0.0, float(s.rng.uniform(0.01, 3.0))), p=(0.15, 0.85))
        light.size_y = float(s.rng.uniform(0.0, 3.0))
        extra = f", {light.shape} {light.size:.2f} x {light.size_y:.2f}"
    ob = bpy.data.objects.new(light.name, light)
    ob.location = (*s.rng.uniform(-4.0, 4.0, 2), float(s.rng.uniform(-1.0, 5.0)))
    ob.rotation_euler = tuple(s.rng.uniform(-math.pi, math.pi, 3))
    scene.collection.objects.link(ob)
    s.note(f"{ob.name}: {light.energy:.3g} W{extra}")


def _camera(s: _Scene, scene):
    if s.coin(0.04):
        s.note("no camera")
        return
    cam = scenes.add_camera(target=(0.0, 0.0, 0.5), distance=float(s.rng.uniform(3.0, 10.0)),
                            elevation_deg=float(s.rng.uniform(-10.0, 70.0)),
                            azimuth_deg=float(s.rng.uniform(-180.0, 180.0)),
                            lens=float(s.rng.uniform(18.0, 80.0)), resolution=None)
    if s.coin(0.1):
        cam.data.type, cam.data.ortho_scale = "ORTHO", float(s.rng.uniform(2.0, 10.0))
    width, height = s.pick(((32, 24), (24, 24), (17, 11)))
    scenes.set_resolution(width, height)
    s.note(f"camera {cam.data.type}, {width} x {height}")


def _settings(s: _Scene, scene, n_lamps: int):
    prt = scene.prt
    prt.method = s.pick(METHODS)
    prt.resolution = "32"
    prt.supersampling = s.pick((1, 1, 2))
    scene.render.filter_size = s.pick((0.0, 1.5, 3.0))
    scene.render.film_transparent = s.coin(0.5)
    prt.light_sources = s.pick((8, 0, int(s.rng.integers(1, 8))))
    prt.write_attributes = s.coin(0.5)
    prt.attribute_sh_order = int(s.rng.integers(0, 6))
    prt.field_detail = s.pick(("LOW", "MEDIUM"))       # HIGH: tens of seconds per object
    prt.ssdf_lamps = s.pick(("PASS", "SG"))
    # each light group costs a frame: only with few lamps
    prt.light_group_passes = n_lamps <= 3 and s.coin(0.1)
    s.note(f"method {prt.method}, AA {prt.supersampling}, filter {scene.render.filter_size}, "
           f"sources {prt.light_sources}, attributes {prt.write_attributes} "
           f"(SH order {prt.attribute_sh_order}), field {prt.field_detail}, SSDF lamps "
           f"{prt.ssdf_lamps}, light groups {prt.light_group_passes}")
