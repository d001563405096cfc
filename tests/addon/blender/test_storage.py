"""addon.blender.storage in headless Blender: every method's stored data follows the object
datablock through rename, duplicate, delete, undo/redo, save/reload, append and link;
an earlier or newer layout is reported, never misread; Clear leaves nothing."""

from __future__ import annotations

import struct

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import storage
from prt_relight.core.store import layouts
from prt_relight.addon.frame import state as runtime
from prt_relight.addon.methods.blocks import shading as blocks
from prt_relight.addon.methods.rsl import shading as rsl
from prt_relight.addon.methods.ssdf_sg import store as ssdf_sg_storage
from prt_relight.core.common import codec
from prt_relight.bench import scenes

from ...cases.small import save_every_method


pytestmark = pytest.mark.usefixtures("registered_addon")

#: the blob each storing method writes, and how a synced object shows it was loaded
BLOBS = {"REFERENCE": storage.VISIBILITY, "BLOCKS": blocks.BLOB, "RSL": rsl.BLOB,
         "SSDF_SG": ssdf_sg_storage.BLOB}
LOADED = {"REFERENCE": lambda st: st.status == "ok",
          "BLOCKS": lambda st: "blocks_dv" in st.data,
          "RSL": lambda st: "rsl" in st.data,
          "SSDF_SG": lambda st: getattr(st.data.get("ssdf_sg"), "precompute_id", "") != ""}


def _scene(subdiv=0, cuts=8):
    scenes.reset()
    scenes.add_world("sunset")
    scenes.add_ground(size=6.0, cuts=cuts)
    scenes.add_suzanne(subdiv=subdiv, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 24)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.prt.resolution = "32"
    return scene


def _blobs(ob) -> dict:
    """name -> stored bytes of every blob on ``ob``."""
    store = ob.get(storage.STORE)
    return {} if store is None else {n: bytes(store[n]["blob"]) for n in store.keys()}


def _sync(method="REFERENCE"):
    scene = bpy.context.scene
    scene.prt.method = method
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def _loaded_by(name) -> list:
    """The methods that drew object ``name`` from its stored data."""
    out = []
    for method, loaded in LOADED.items():
        st = next(st for st in _sync(method).objects if st.name == name)
        if loaded(st):
            out.append(method)
    return out


@pytest.fixture(scope="module")
def stored_file(registered_addon, tmp_path_factory):
    """A .blend whose objects hold the data of every storing method (one precompute,
    then each method's derive/store on the same job) and their blobs."""
    _scene()
    path = save_every_method(tmp_path_factory.mktemp("storage") / "stored.blend")
    blobs = {ob.name: _blobs(ob) for ob in bpy.data.objects if ob.type == "MESH"}
    assert all(set(b) == set(BLOBS.values()) for b in blobs.values()), blobs.keys()
    return path, blobs


def _open(path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.data.objects["Suzanne"]


def test_put_get_delete_and_a_blob_of_another_run_is_ignored():
    scenes.reset()
    ob = bpy.data.objects.new("Thing", None)
    ob.prt.precompute_id = "run-1"
    bits = np.arange(768 * 3, dtype=np.uint8).reshape(3, 768)
    storage.put(ob, "probe", storage.pack({"bits": bits}, {"note": "x"}))
    arrays, meta = storage.get(ob, "probe")
    np.testing.assert_array_equal(arrays["bits"], bits)
    assert meta == {"note": "x"} and storage.has(ob, "probe")
    first = storage.key(ob, "probe")
    storage.put(ob, "probe", storage.pack({"bits": bits}))
    assert storage.key(ob, "probe") != first                # a new key per put: caches miss
    ob.prt.precompute_id = "run-2"                          # the record moved on
    assert not storage.has(ob, "probe") and storage.get(ob, "probe") is None
    ob.prt.precompute_id = "run-1"
    storage.delete(ob, "probe")
    assert storage.get(ob, "probe") is None and storage.stored_bytes(ob) == 0
    with pytest.raises(TypeError, match="storage.pack"):
        storage.put(ob, "probe", bits)
    with pytest.raises(ValueError, match="6x32"):
        layouts.visibility_blob(bits[:, :700], 32)


def test_visibility_takes_at_most_128_bytes_per_point(tmp_path):
    """Blender's Suzanne (subdivided once) on a ground at 6x32^2: the stored visibility
    (768 bytes per point bit-packed) is the lossless blob, at most 128 bytes per point."""
    _scene(subdiv=1, cuts=32)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = _sync()
    for st in state.objects:
        ob = bpy.data.objects[st.name]
        arrays, meta = storage.get(ob, storage.VISIBILITY)
        np.testing.assert_array_equal(arrays["bits"], st.bits)
        per_point = storage.stored_bytes(ob, storage.VISIBILITY) / st.points.count
        print(f"{st.name}: {st.points.count} points, {per_point:.1f} bytes/point")
        assert per_point <= 128 and meta == {"resolution": 32}


def test_rename_keeps_every_methods_data(stored_file):
    path, blobs = stored_file
    ob = _open(path)
    assert _loaded_by("Suzanne") == list(BLOBS)
    ob.name = "Renamed"
    bpy.data.objects["Ground"].name = "Floor"
    assert _blobs(ob) == blobs["Suzanne"] and _blobs(bpy.data.objects["Floor"]) == blobs["Ground"]
    assert _loaded_by("Renamed") == list(BLOBS)
    assert _loaded_by("Floor") == list(BLOBS)
    assert not [i for i in bpy.data.images if i.name.startswith("PRT")]


@pytest.mark.parametrize("linked", [False, True])
def test_duplicate_copies_the_data_and_a_moved_copy_is_stale(stored_file, linked):
    path, blobs = stored_file
    ob = _open(path)
    bpy.ops.object.select_all(action="DESELECT")
    ob.select_set(True)
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.object.duplicate(linked=linked) == {"FINISHED"}
    copy = bpy.context.active_object
    assert copy != ob and (copy.data == ob.data) == linked
    assert _blobs(copy) == blobs["Suzanne"] and _blobs(ob) == blobs["Suzanne"]
    assert _loaded_by(copy.name) == list(BLOBS)      # in place: the same geometry
    copy.location.x += 2.0
    statuses = {st.name: st.status for st in _sync().objects}
    assert statuses[copy.name] == "stale" and statuses["Suzanne"] == "ok"
    assert _loaded_by("Suzanne") == list(BLOBS)


def test_delete_drops_the_data_with_the_object(stored_file):
    path, blobs = stored_file
    _open(path)
    bpy.data.objects.remove(bpy.data.objects["Suzanne"])
    bpy.data.orphans_purge(do_recursive=True)
    assert not [i for i in bpy.data.images if i.name.startswith("PRT")]
    assert _blobs(bpy.data.objects["Ground"]) == blobs["Ground"]
    state = _sync()
    assert any("removed" in w for w in state.warnings), state.warnings
    bpy.ops.object.select_all(action="SELECT")
    assert bpy.ops.object.delete() == {"FINISHED"}
    assert not any(storage.STORE in ob for ob in bpy.data.objects)


def test_undo_redo_restores_the_data_bit_identical(stored_file):
    path, blobs = stored_file
    ob = _open(path)
    bpy.ops.ed.undo_push(message="opened")
    ob.name = "Renamed"
    bpy.ops.ed.undo_push(message="rename")
    assert bpy.ops.prt.clear() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="clear")
    assert _blobs(bpy.data.objects["Renamed"]) == {}
    bpy.ops.ed.undo()
    ob = bpy.data.objects["Renamed"]
    assert _blobs(ob) == blobs["Suzanne"]
    assert _loaded_by("Renamed") == list(BLOBS)
    bpy.ops.ed.undo()
    assert _blobs(bpy.data.objects["Suzanne"]) == blobs["Suzanne"]
    bpy.ops.ed.redo()
    bpy.ops.ed.redo()
    assert _blobs(bpy.data.objects["Renamed"]) == {}
    assert _sync().objects[0].status == "missing"


def test_save_reload_same_blobs_and_same_f12(stored_file, tmp_path):
    path, blobs = stored_file
    _open(path)
    bpy.context.scene.prt.method = "BLOCKS"
    before = scenes.render_exr(tmp_path / "a.exr")
    again = tmp_path / "again.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(again))
    scenes.reset()
    _open(again)
    assert {n: _blobs(bpy.data.objects[n]) for n in blobs} == blobs
    bpy.context.scene.prt.method = "BLOCKS"
    blocks.STORED.clear()
    after = scenes.render_exr(tmp_path / "b.exr")
    assert blocks.LAST_STATS["sources"] == ["stored", "stored"]
    np.testing.assert_array_equal(before, after)


def test_append_and_link_bring_the_data(stored_file):
    path, blobs = stored_file
    scenes.reset()
    scenes.add_world("sunset")
    assert bpy.ops.wm.append(directory=f"{path}/Object/", filename="Suzanne") == {"FINISHED"}
    appended = bpy.data.objects["Suzanne"]
    assert appended.library is None and _blobs(appended) == blobs["Suzanne"]
    assert _loaded_by("Suzanne") == list(BLOBS)
    scenes.reset()
    scenes.add_world("sunset")
    with bpy.data.libraries.load(str(path), link=True) as (_src, dst):
        dst.objects = ["Ground"]
    linked = dst.objects[0]
    bpy.context.scene.collection.objects.link(linked)
    assert linked.library is not None and _blobs(linked) == blobs["Ground"]
    assert _loaded_by("Ground") == list(BLOBS)
    # Clear leaves a library's data alone: it lives in (and is saved with) that file
    bpy.ops.prt.clear()
    assert _blobs(linked) == blobs["Ground"]


def _legacy_layout(ob):
    """What the earlier layout left on an object: a tagged packed float image linked
    from ``ob.prt`` (the ``visibility`` pointer, now unregistered), the RSL image and
    ID properties, and the precompute record."""
    ob.prt.resolution = 32
    ob.prt.point_count = 500
    ob.prt.precompute_id = "0123456789abcdef"
    images = []
    for prefix in ("PRT Visibility ", "PRT RSL "):
        img = bpy.data.images.new(prefix + ob.name, 4096, 2, alpha=True, float_buffer=True,
                                  is_data=True)
        img["prt_relight"] = True
        img.use_fake_user = True
        img.pixels.foreach_set(np.full(4096 * 2 * 4, 12345.0, np.float32))
        img.pack()
        images.append(img)
    ob.prt["visibility"] = images[0]
    ob["prt_rsl_image"] = images[1]
    ob["prt_rsl_id"] = ob.prt.precompute_id
    ob["prt_rsl_rotation"] = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]
    return images


def test_earlier_layout_is_reported_and_replaced(tmp_path):
    _scene()
    ob = bpy.data.objects["Suzanne"]
    _legacy_layout(ob)
    path = tmp_path / "old.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    ob = _open(path)
    for method in BLOBS:
        state = _sync(method)
        st = next(st for st in state.objects if st.name == "Suzanne")
        assert st.status == "missing" and not LOADED[method](st)
        assert any("earlier prt_relight" in w and "Suzanne" in w for w in state.warnings)
        np.testing.assert_array_equal(st.bits, runtime.open_visibility(
            st.points.normals, runtime.directions.cubemap(32)))    # unshadowed, not misread
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert not [i for i in bpy.data.images if i.get("prt_relight") or i.name.startswith("PRT")]
    assert [k for k in ob.keys() if k.startswith("prt")] == [storage.STORE]
    assert ob.prt.get("visibility") is None
    assert not any("earlier" in w for w in _sync().warnings)


def test_newer_layout_or_codec_is_reported_not_misread(stored_file):
    path, blobs = stored_file
    ob = _open(path)
    vis = blobs["Suzanne"][storage.VISIBILITY]
    newer = vis[:4] + struct.pack("<H", codec.FORMAT + 1) + vis[6:]
    storage.put(ob, storage.VISIBILITY, newer)
    state = _sync()
    st = next(st for st in state.objects if st.name == "Suzanne")
    assert st.status == "missing"
    assert any("'Suzanne': stored with a newer prt_relight (layout 2" in w
               and "precompute again" in w for w in state.warnings), state.warnings
    # a method's blob of a newer layout: noted, and the method derives from the bits
    ob = _open(path)
    storage.put(ob, blocks.BLOB, newer)
    state = _sync("BLOCKS")
    st = next(st for st in state.objects if st.name == "Suzanne")
    assert st.status == "ok" and "blocks_dv" not in st.data
    assert any("newer prt_relight" in w for w in state.warnings)
    # an entry that is not a layout-1 blob at all
    ob = _open(path)
    ob[storage.STORE][storage.VISIBILITY] = {"data": [1, 2, 3]}
    state = _sync()
    assert any("layout this prt_relight does not know" in w for w in state.warnings)


def test_clear_leaves_nothing_the_addon_wrote(stored_file, tmp_path):
    path, blobs = stored_file
    ob = _open(path)
    run = ob.prt.precompute_id
    _legacy_layout(bpy.data.objects["Ground"])
    hidden = bpy.data.objects.new("Unlinked", ob.data)         # in no scene
    hidden["prt_store"] = ob["prt_store"]
    assert bpy.ops.prt.clear() == {"FINISHED"}
    cleared = tmp_path / "cleared.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(cleared))
    for ob in bpy.data.objects:
        assert not [k for k in ob.keys() if k.startswith("prt")], ob.name
        assert not ob.prt.keys(), (ob.name, ob.prt.keys())    # record unset
    assert not [i.name for i in bpy.data.images if i.name.startswith("PRT")
                or i.get("prt_relight")]
    assert bpy.context.scene.prt.precompute_id == ""
    data = cleared.read_bytes()
    for written in (b"prt_store", b"prt_rsl", b"PRT Visibility", b"PRT RSL",
                    run.encode(), blobs["Suzanne"][storage.VISIBILITY][:64]):
        assert written not in data, written
