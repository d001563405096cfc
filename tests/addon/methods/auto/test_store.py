"""AUTO's stored choice (addon/methods/auto/store.py): a reopened .blend renders the same
frame, the choice holds until the scene or the target changes, Clear removes it, Choose
stores it for the scene camera."""

from __future__ import annotations

import json
import subprocess
import sys
import types

import bpy
import numpy as np
import pytest

from prt_relight.addon.methods import REGISTRY
from prt_relight.addon.methods.auto import shading as auto
from prt_relight.addon.methods.auto import assign as auto_assign, measure as auto_measure
from prt_relight.addon.methods.auto import store as auto_store
from prt_relight.bench import scenes

from .cases import auto_scene, fewer_candidates, stored_choice, synced_state


pytestmark = pytest.mark.usefixtures("registered_addon")


# ---------------------------------------------------------------- the stored choice

def _untimed(monkeypatch):
    """AUTO's clock fails the test when read: a frame drawn with the stored choice times
    nothing."""
    def read():
        raise AssertionError("AUTO timed a frame that has a stored choice")
    monkeypatch.setattr(auto_measure, "time", types.SimpleNamespace(perf_counter=read))


class _Labels:
    """A layout that keeps the labels and operators an AUTO settings draw puts in it."""

    def __init__(self):
        self.texts = []

    def box(self):
        return self

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties

    def operator(self, idname, **kwargs):
        self.texts.append(idname)

    def label(self, text="", **kwargs):
        self.texts.append(text)


def _panel(scene):
    layout = _Labels()
    REGISTRY["AUTO"].settings.draw(layout, scene.prt)
    return layout.texts


def _drawn_with_stored(state, eye):
    state.shade(eye)
    return any(w.startswith("AUTO (stored choice)") for w in state.warnings)


# Draws a saved .blend's F12 in a new process, the add-on registered as conftest.py does.
# AUTO's clock there reads 1 s for every interval it times: a process whose timings differ
# from the first one's (the live choice then takes REFERENCE everywhere).
_REOPEN = """

import importlib.util, pathlib, sys, types
root = pathlib.Path(sys.argv[1])
spec = importlib.util.spec_from_file_location(
    "prt_relight", root / "__init__.py", submodule_search_locations=[str(root)])
addon = importlib.util.module_from_spec(spec)
sys.modules["prt_relight"] = addon
spec.loader.exec_module(addon)
import bpy
addon.register()
from prt_relight.addon.methods.auto import measure as auto
reads = [0]
def tick():
    reads[0] += 1
    return float(reads[0])
auto.time = types.SimpleNamespace(perf_counter=tick)
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
bpy.ops.render.render()
bpy.data.images["Render Result"].save_render(sys.argv[3])
print("AUTO clock reads:", reads[0], flush=True)
"""


def test_a_reopened_blend_renders_the_same_auto_frame(tmp_path, repo_root):
    """Precompute with AUTO (every candidate), F12, save; the .blend opened in a new
    process renders a bit-identical frame and AUTO reads no clock there."""
    auto_scene(method="AUTO")
    first = scenes.render_exr(tmp_path / "first.exr")
    blend = tmp_path / "auto.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    script = tmp_path / "reopen.py"
    script.write_text(_REOPEN)
    again_path = tmp_path / "again.exr"
    proc = subprocess.run([sys.executable, str(script), str(repo_root), str(blend),
                           str(again_path)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and again_path.exists(), proc.stderr[-3000:]
    again = scenes.read_exr(again_path)
    assert np.array_equal(first, again), (
        f"max difference {np.abs(first - again).max()}", proc.stdout[-2000:])
    assert "AUTO clock reads: 0" in proc.stdout, proc.stdout[-2000:]


def test_the_stored_choice_holds_until_the_scene_or_the_target_changes(monkeypatch):
    """Precompute with AUTO stores its choice for the scene camera; frames use it without
    timing while the world turns; a new target, lighting strength or moved object makes it
    out of date (the frame is chosen live and nothing is written) until Choose or
    Precompute chooses again."""
    fewer_candidates(monkeypatch)
    auto_scene(method="AUTO", rotation_z=0.3)
    scene = bpy.context.scene
    record = stored_choice()
    assert record["camera"] == "Camera" and record["size"] == [64, 48]
    assert [c["object"] for c in record["objects"]] == ["Ground", "Suzanne"]
    assert all(c["method"] in ("REFERENCE", "SH", "WAVELET") for c in record["objects"])
    eye = np.array(scene.camera.matrix_world.translation)
    real_time = auto_measure.time
    _untimed(monkeypatch)
    state = synced_state("AUTO")
    assert _drawn_with_stored(state, eye), state.warnings
    assert [(c["object"], c["choice"]) for c in auto.LAST_CHOICES] == \
        [(c["object"], c["choice"]) for c in record["objects"]]
    assert auto_store.stored_status(scene.prt) == ""
    panel = _panel(scene)
    assert "Stored choice, current" in panel and "prt.auto_choose" in panel
    assert "Chosen for camera 'Camera' at 64×48" in panel
    assert all(any(t.startswith(f"{c['object']}: {c['choice']}") for t in panel)
               for c in record["objects"]), panel
    # the same environment turned keeps the choice
    mapping = next(n for n in scene.world.node_tree.nodes if n.type == "MAPPING")
    mapping.inputs["Rotation"].default_value[2] = 1.4
    assert _drawn_with_stored(synced_state("AUTO"), eye)
    stored = scene.prt.auto_choice

    monkeypatch.setattr(auto_measure, "time", real_time)
    # a stored choice naming a method no longer registered is out of date
    scene.prt.auto_choice = json.dumps(dict(record, objects=[
        dict(c, method="GONE") for c in record["objects"]]))
    state = synced_state("AUTO")
    assert not _drawn_with_stored(state, eye)
    assert any("no longer present" in w for w in state.warnings), state.warnings
    scene.prt.auto_choice = stored
    for change, part in ((lambda: setattr(scene.prt, "auto_error_target", 0.05), "target"),
                         (lambda: setattr(scene.world.node_tree.nodes["Background"]
                                          .inputs["Strength"], "default_value", 2.0),
                          "lighting"),
                         (lambda: setattr(bpy.data.objects["Suzanne"].location, "z", 1.3),
                          "geometry")):
        change()
        state = synced_state("AUTO")
        assert not _drawn_with_stored(state, eye)
        assert any(w.startswith("AUTO choice is out of date (") and part in w
                   for w in state.warnings), state.warnings
        assert any(w.startswith("AUTO:") for w in state.warnings)    # chosen live
        assert scene.prt.auto_choice == stored                         # and not written
        assert part in auto_store.stored_status(scene.prt)
        assert any(t.startswith("AUTO choice is out of date") and part in t
                   for t in _panel(scene))
        if part == "target":
            assert bpy.ops.prt.auto_choose() == {"FINISHED"}
            assert stored_choice()["key"]["target"] == pytest.approx(0.05)
            assert _drawn_with_stored(synced_state("AUTO"), eye)
            stored = scene.prt.auto_choice
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert scene.prt.auto_choice != stored
    _untimed(monkeypatch)
    assert _drawn_with_stored(synced_state("AUTO"), eye)


def test_clear_removes_the_stored_choice(monkeypatch):
    fewer_candidates(monkeypatch)
    auto_scene(method="AUTO")
    scene = bpy.context.scene
    assert stored_choice()["objects"]
    assert bpy.ops.prt.clear() == {"FINISHED"}
    assert scene.prt.auto_choice == ""
    assert "No stored choice: press Choose (or Precompute)" in _panel(scene)
    state = synced_state("AUTO")
    state.shade(np.array(scene.camera.matrix_world.translation))
    assert any(w.startswith("AUTO has no stored choice") for w in state.warnings)


def test_choose_stores_the_choice_for_the_scene_camera(monkeypatch):
    """Choose weighs errors in the scene camera's image: with Suzanne out of the frame it
    stores Suzanne's fastest measured option (it shows no pixel).  The camera is not part
    of the key: moving it keeps the stored choice until Choose is pressed again."""
    fewer_candidates(monkeypatch)
    monkeypatch.setattr(auto_assign, "UNIFORM_TRIED", 0)      # the mix only: no timing decides
    auto_scene()
    scene = bpy.context.scene
    scene.prt.method = "AUTO"
    assert scene.prt.auto_choice == ""                  # a REFERENCE precompute chose nothing
    cam = scene.camera                                  # above the grid's corner, looking down
    cam.data.type, cam.data.ortho_scale = "ORTHO", 1.2
    cam.location, cam.rotation_euler = (2.2, 2.2, 2.0), (0.0, 0.0, 0.0)
    scenes.set_resolution(64, 64)
    auto.CHOICE_CACHE.clear()
    assert bpy.ops.prt.auto_choose() == {"FINISHED"}
    record = stored_choice()
    assert record["camera"] == cam.name and record["size"] == [64, 64]
    chosen = {c["object"]: c for c in record["objects"]}
    measured = {m["object"]: m for m in (v[-1] if isinstance(v, tuple) else v
                                         for v in auto.CHOICE_CACHE.values())}
    fastest = min((o for o in measured["Suzanne"]["options"]
                   if np.isfinite(o[1]) and np.isfinite(o[2])), key=lambda o: o[1])
    suzanne = chosen["Suzanne"]
    assert (suzanne["method"], suzanne["setting"], suzanne["value"]) == fastest[0], suzanne
    assert suzanne["error"] == 0.0
    assert chosen["Ground"]["error"] <= 0.95 * 0.02
    _untimed(monkeypatch)
    cam.location = (0.0, -6.0, 3.0)
    cam.data.type = "PERSP"
    assert _drawn_with_stored(synced_state("AUTO"), np.array(cam.location))


def test_a_textured_object_is_drawn_with_the_stored_choice(monkeypatch):
    """A colour texture on Suzanne: the frame shades the untextured ground and the textured
    Suzanne (at base colour white and black) as parts of the frame, each holding the whole
    frame's stored choice -- nothing is timed or chosen live, and the panel's last choices
    are every object's."""
    fewer_candidates(monkeypatch)
    auto_scene(method="REFERENCE", rotation_z=0.3)
    suzanne = bpy.data.objects["Suzanne"]
    suzanne.data.uv_layers.new(name="UVMap")
    mat = bpy.data.materials.new("Textured")
    nt = mat.node_tree
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    tex = nt.nodes.new("ShaderNodeTexImage")
    y, x = np.mgrid[0:16, 0:16] / 16.0
    tex.image = scenes.float_image("checker", np.stack(
        [0.2 + 0.6 * ((x * 4).astype(int) % 2), 0.5 + 0.0 * x, 0.3 + 0.4 * y], -1))
    nt.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    nt.links.new(diffuse.outputs["BSDF"], nt.nodes["Material Output"].inputs["Surface"])
    suzanne.data.materials.clear()
    suzanne.data.materials.append(mat)
    bpy.context.scene.prt.method = "AUTO"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    record = stored_choice()
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    _untimed(monkeypatch)
    state = synced_state("AUTO")
    assert any(st.textures for st in state.objects)
    assert _drawn_with_stored(state, eye), state.warnings
    assert not any("out of date" in w for w in state.warnings), state.warnings
    assert [c["object"] for c in auto.LAST_CHOICES] == \
        [c["object"] for c in record["objects"]] == ["Ground", "Suzanne"]
