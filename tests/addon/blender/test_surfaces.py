"""addon.blender.surfaces in headless Blender: every kind of instance (collection
instances, particles that render an object, geometry-nodes instances of an object and of
bare geometry) is a surface placed where Blender places it, sharing its source's index
arrays; each instance's data is stored on its instancer under its persistent id and
survives save/reload, duplicating the instancer and a precompute that no longer finds it."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import scene_export, storage, surfaces
from prt_relight.addon.frame import state as runtime
from prt_relight.core.scene import mesh as core_mesh
from prt_relight.bench import scenes

from ...cases.small import save_every_method

pytestmark = pytest.mark.usefixtures("registered_addon")

#: how a synced surface shows that each storing method read its stored data
LOADED = {"REFERENCE": lambda st: st.status == "ok",
          "BLOCKS": lambda st: "blocks_dv" in st.data,
          "RSL": lambda st: "rsl" in st.data,
          "SSDF_SG": lambda st: getattr(st.data.get("ssdf_sg"), "precompute_id", "") != ""}


def _surfaces():
    return surfaces.scene_surfaces(bpy.context.evaluated_depsgraph_get())


def _sync(method="REFERENCE"):
    bpy.context.scene.prt.method = method
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def _small_herd(kind="COLLECTION", count=3):
    instancers = scenes.instanced_herd(kind, count=count, subdiv=0, size=(32, 24))
    scene = bpy.context.scene
    scene.prt.resolution = "32"
    scene.prt.supersampling = 1
    return instancers


@pytest.mark.parametrize("kind", ["COLLECTION", "PARTICLES", "NODES"])
def test_every_kind_of_instance_is_a_surface_placed_as_blender_places_it(kind):
    instancers = _small_herd(kind, count=4)
    found = _surfaces()
    placed = [s for s in found if s.instance]
    # the hidden emitter is not drawn; the points geometry nodes instance on are (no faces)
    assert [s.name for s in found if not s.instance] == ["Ground"] + ["Herd"] * (kind == "NODES")
    assert len(placed) == 4 and len({s.name for s in placed}) == 4
    assert {s.owner.instancer for s in placed} <= set(instancers)
    # where Blender's depsgraph puts each instance (the source's own arrays, placed)
    dg = bpy.context.evaluated_depsgraph_get()
    truth = sorted(tuple(np.array(i.matrix_world)[:3, 3])
                   for i in dg.object_instances if i.is_instance)
    np.testing.assert_allclose(sorted(tuple(s.matrix[:3, 3]) for s in placed), truth,
                               atol=1e-9)
    shared = surfaces.SharedArrays()
    arrays = [shared.arrays(s) for s in placed]
    animal = bpy.data.objects["Animal"].evaluated_get(dg)
    own = scene_export.mesh_arrays(animal, placed[0].matrix)
    np.testing.assert_allclose(arrays[0].positions, own.positions, atol=1e-9)
    np.testing.assert_allclose(arrays[0].corner_normals, own.corner_normals, atol=1e-9)
    assert all(np.shares_memory(a.triangles, arrays[0].triangles) for a in arrays)  # shared
    assert not np.allclose(arrays[0].positions, arrays[1].positions)
    assert shared.nbytes() > 0
    # the instances' shading points: their own positions and normals, the first one's
    # index arrays where they are equal (as a turn leaves them)
    points = [shared.shared_points(s, core_mesh.shading_points(a))
              for s, a in zip(placed, arrays)]
    assert all(p.point_of_corner is points[0].point_of_corner for p in points)
    assert all(p.materials is points[0].materials for p in points)
    assert not points[0].point_of_corner.flags.writeable
    alone = core_mesh.shading_points(own)
    assert (points[0].point_of_corner == alone.point_of_corner).mean() > 0.99
    np.testing.assert_allclose(points[0].normals, alone.normals, atol=1e-9)


def test_geometry_instanced_without_an_object_and_nested_instances():
    """Geometry nodes instancing a mesh primitive (no object behind it) and a collection
    instance inside an instanced collection are surfaces too, keyed by every level of
    their persistent id."""
    _small_herd("COLLECTION", count=1)
    pts = bpy.data.meshes.new("pts")
    pts.from_pydata([(2.0, 0.0, 0.0), (-2.0, 0.0, 0.0)], [], [])
    ob = bpy.data.objects.new("Dots", pts)
    bpy.context.scene.collection.objects.link(ob)
    tree = bpy.data.node_groups.new("dots", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    given, out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    place, ico = (tree.nodes.new("GeometryNodeInstanceOnPoints"),
                  tree.nodes.new("GeometryNodeMeshIcoSphere"))
    tree.links.new(given.outputs[0], place.inputs["Points"])
    tree.links.new(ico.outputs["Mesh"], place.inputs["Instance"])
    tree.links.new(place.outputs[0], out.inputs[0])
    ob.modifiers.new("dots", "NODES").node_group = tree
    outer = bpy.data.collections.new("Outer")
    outer.objects.link(bpy.data.objects["Herd 0"])          # an instancer, instanced
    top = bpy.data.objects.new("Top", None)
    top.instance_type, top.instance_collection = "COLLECTION", outer
    top.location = (0.0, 3.0, 0.0)
    bpy.context.scene.collection.objects.link(top)
    names = {s.name: s for s in _surfaces()}
    dots = [n for n in names if n.startswith("Dots#")]
    assert len(dots) == 2 and all(isinstance(names[n].ob, surfaces.GeometrySource) for n in dots)
    nested = [n for n in names if n.startswith("Top#")]
    assert len(nested) == 1 and nested[0].count(".") == 1, names
    shared = surfaces.SharedArrays()
    a, b = (shared.arrays(names[n]) for n in dots)
    assert len(a.triangles) == 20 and np.shares_memory(a.triangles, b.triangles)
    assert np.allclose(names[nested[0]].matrix[:3, 3] - names["Herd 0#0"].matrix[:3, 3],
                       (0.0, 3.0, 0.0))
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = _sync()
    assert {st.name: st.status for st in state.objects if "#" in st.name} == {
        n: "ok" for n in names if "#" in n}


@pytest.fixture(scope="module")
def stored_herd(registered_addon, tmp_path_factory):
    """A saved herd of 3 collection instances holding every storing method's data."""
    _small_herd()
    return save_every_method(tmp_path_factory.mktemp("herd") / "herd.blend")


def _loaded_by(name) -> list:
    return [m for m, loaded in LOADED.items()
            if loaded(next(st for st in _sync(m).objects if st.name == name))]


def test_save_reload_keeps_every_instance_data_for_every_method(stored_herd, tmp_path):
    bpy.ops.wm.open_mainfile(filepath=str(stored_herd))
    assert "Animal" not in bpy.context.scene.objects.keys() or \
        bpy.data.objects["Animal"].get(storage.STORE) is None      # stored per instance
    herd = bpy.data.objects["Herd 1"]
    assert [r.name for r in storage.instance_records(herd)] == ["Herd 1#0"]
    assert _loaded_by("Herd 1#0") == list(LOADED)
    bpy.context.scene.prt.method = "REFERENCE"
    before = scenes.render_exr(tmp_path / "a.exr")
    again = tmp_path / "again.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(again))
    scenes.reset()
    bpy.ops.wm.open_mainfile(filepath=str(again))
    state = _sync()
    assert {st.name: st.status for st in state.objects} == {
        "Ground": "ok", "Herd 0#0": "ok", "Herd 1#0": "ok", "Herd 2#0": "ok"}
    assert not [w for w in state.warnings if "too coarse" not in w], state.warnings
    assert bpy.context.scene.prt.method == "REFERENCE"
    np.testing.assert_allclose(scenes.render_exr(tmp_path / "b.exr"), before, atol=1e-6)


def test_notes_of_a_scatter_of_instancers_are_one_line_per_source(stored_herd):
    """Three instancers of one animal (how an artist scatters with Alt+D) whose instances
    each carry a tessellation note: the panels and the log get one line naming the source
    and counting them, not a line per instancer."""
    bpy.ops.wm.open_mainfile(filepath=str(stored_herd))
    for i in range(3):
        for r in storage.instance_records(bpy.data.objects[f"Herd {i}"]):
            r.prt.coarse_warning = f"'{r.name}' is too coarse for its shadows"
    lines = [w for w in _sync().warnings if "too coarse" in w]
    assert len(lines) == 1, lines
    assert lines[0].startswith("3 instances of 'Animal' have notes"), lines


def test_duplicated_instancer_carries_its_instances_data(stored_herd):
    bpy.ops.wm.open_mainfile(filepath=str(stored_herd))
    ob = bpy.data.objects["Herd 2"]
    bpy.ops.object.select_all(action="DESELECT")
    ob.select_set(True)
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.object.duplicate() == {"FINISHED"}
    copy = bpy.context.active_object
    assert copy != ob
    name = storage.instance_name(copy.name, "0")
    assert _loaded_by(name) == list(LOADED)              # in place: its data is right
    copy.location.x += 0.5
    statuses = {st.name: st.status for st in _sync().objects}
    assert statuses[name] == "stale" and statuses["Herd 2#0"] == "ok"


def test_a_precompute_drops_the_instances_it_no_longer_finds(stored_herd):
    bpy.ops.wm.open_mainfile(filepath=str(stored_herd))
    gone = bpy.data.objects["Herd 0"]
    gone.instance_type = "NONE"
    assert storage.instance_records(gone)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert storage.instance_records(gone) == []
    assert storage.has(storage.owner("Herd 1#0"), storage.VISIBILITY)
    gone.instance_type = "COLLECTION"
    state = _sync()
    assert {st.name: st.status for st in state.objects}["Herd 0#0"] == "missing"
    assert any("Not precomputed" in w and "Herd 0#0" in w for w in state.warnings)
    assert bpy.ops.prt.clear() == {"FINISHED"}
    assert not any(storage.INSTANCES in o for o in bpy.data.objects)


def test_an_instance_record_reads_and_writes_like_an_object_record():
    scenes.reset()
    ob = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(ob)
    rec = storage.owner(storage.instance_name("Holder", "4.1"))
    assert isinstance(rec, storage.InstanceRecord) and rec.key == "4.1"
    assert rec.prt.point_count == 0 and rec.prt.precompute_id == "" and not rec.prt.dynamic
    assert storage.owner("Nobody#1") is None and storage.owner("Holder") == ob
    rec.prt.precompute_id, rec.prt.point_count = "run-1", 12
    storage.put(rec, "probe", storage.pack({"x": np.arange(3)}))
    again = storage.owner("Holder#4.1")
    assert again.prt.point_count == 12 and storage.has(again, "probe")
    assert storage.get(again, "probe")[0]["x"].tolist() == [0, 1, 2]
    with pytest.raises(AttributeError):
        rec.prt.nonsense = 1
    assert storage.clear_object(again) and not storage.has(again, "probe")
    assert again.prt.point_count == 0


def test_instances_carry_their_bounce_rows():
    """With bounces in the Light Paths every instance stores its bounce transfer, and the
    frame's bounce reaches it (the ground lights the herd from below)."""
    _small_herd(count=2)
    scenes.light_paths(4)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    for name in ("Herd 0#0", "Herd 1#0"):
        assert storage.has(storage.owner(name), storage.BOUNCE), name
    state = _sync()
    bounced = dict(zip((st.name for st in state.objects), state.bounce.irradiance(state)))
    for name in ("Herd 0#0", "Herd 1#0"):
        st = next(st for st in state.objects if st.name == name)
        assert st.bounce is not None and float(np.max(bounced[name])) > 0.0, name


def test_a_scatter_past_the_rows_budget_keeps_rows_of_fewer_entries():
    """Past the Bounce Rows Budget each receiver's row keeps its largest entry and the sum
    of the rest (read at what its own clusters see): stored so, drawn finite and lit."""
    _small_herd(count=2)
    scenes.light_paths(4)
    bpy.context.scene.prt.bounce_rows_budget = 0
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    arrays, _ = storage.get(storage.owner("Herd 0#0"), storage.BOUNCE)
    assert arrays["columns"].shape[1] == 1 and float(arrays["rest"].max()) > 0.0
    state = _sync()
    bounced = dict(zip((st.name for st in state.objects), state.bounce.irradiance(state)))
    for name in ("Herd 0#0", "Herd 1#0"):
        assert np.isfinite(bounced[name]).all() and float(np.max(bounced[name])) > 0.0, name


def test_lamp_shadow_rays_of_the_bounce_see_instances_through_their_source():
    """The bounce's shadow rays test an instance in its source's frame (no triangle of it
    placed): they answer as one Embree scene of every placed triangle does."""
    from prt_relight.addon.frame import bounce
    from prt_relight.core.scene import visibility
    _small_herd(count=3)
    scenes.light_paths(4)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = _sync()
    objs = [st for st in state.objects if st.status == "ok"]
    assert all(st.local_source is not None for st in objs if "#" in st.name)
    test = bounce.occlusion_test(objs)
    flat = visibility.build_occluder_scene(np.concatenate(
        [core_mesh.occluder_triangles(st.arrays)[0] for st in objs]))
    rng = np.random.default_rng(5)
    lo, hi = core_mesh.bounds([st.arrays for st in objs])
    o = rng.uniform(lo, hi, (4000, 3))
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dist = np.where(rng.uniform(size=4000) < 0.5, np.inf, rng.uniform(0.05, 3.0, 4000))
    diag = core_mesh.bounding_diagonal(core_mesh.bounds([st.arrays for st in objs]))
    step = 1e-4 * diag
    truth = flat.run((o + step * d).astype(np.float32), d.astype(np.float32),
                     dists=np.minimum(dist - 2 * step, 1e30).astype(np.float32),
                     query="OCCLUDED") != -1
    got = test(o, d, dist)
    assert 0.05 < truth.mean() < 0.95
    assert (got != truth).sum() <= 4, (got != truth).sum()


def test_an_instancer_hidden_from_renders_hides_its_instances_from_the_trace():
    """Hidden from renders (the instancer's flag): not traced, casting nothing; the
    viewport still draws its instances, unshadowed."""
    herd = _small_herd(count=2)
    herd[0].hide_render = True
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert storage.instance_records(herd[0]) == []
    statuses = {st.name: st.status for st in _sync().objects}
    assert statuses["Herd 0#0"] == "unshadowed" and statuses["Herd 1#0"] == "ok"
