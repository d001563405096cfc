"""Hard or bad input an artist hits, each with what must happen: a clear message and the
scene unchanged, or a correct finite frame (docs/reliability.md lists every case with
the test that checks it, here or in another test file)."""

from __future__ import annotations

import errno
import json

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
from prt_relight.addon.blender import storage
from prt_relight.bench import scenes


pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET"]


def _scene(hdri="sunset", cuts=8):
    """A 4 m ground, a coarse smooth ball above it (no material), a camera: ~350 points."""
    scenes.reset()
    scenes.add_world(hdri)
    scenes.add_ground(size=4.0, cuts=cuts)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 1.0), radius=0.8, segments=12,
                                         ring_count=6)
    bpy.ops.object.shade_smooth()
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 24)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    return scene


def _sync():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def _stored():
    """Every object's stored blobs by name: what a refused operation must leave as it was."""
    out = {}
    for ob in bpy.data.objects:
        store = ob.get(storage.STORE)
        out[ob.name] = {} if store is None else {n: bytes(store[n]["blob"]) for n in store.keys()}
    return out


def _data_counts():
    """How many datablocks of each kind (Blender's own Render Result image left out)."""
    counts = {kind: len(getattr(bpy.data, kind)) for kind in
              ("objects", "meshes", "materials", "worlds", "scenes", "cameras")}
    counts["images"] = sum(i.type != "RENDER_RESULT" for i in bpy.data.images)
    return counts


def _frame(path, low=0.02, high=50.0):
    """F12 of the scene camera: finite, non-negative, something lit and nothing absurd."""
    frame = scenes.render_exr(path)
    assert np.isfinite(frame).all()
    assert frame.min() >= 0.0
    lit = frame[..., 3] > 0.5
    assert lit.mean() > 0.2
    assert low < frame[lit][:, :3].mean() < high, frame[lit][:, :3].mean()
    return frame


def _refused(match):
    """``prt.precompute`` refuses with ``match`` in its message and changes nothing."""
    before, counts = _stored(), _data_counts()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.prt.precompute()
    assert _stored() == before and _data_counts() == counts
    assert bpy.context.scene.prt.precompute_id == ""


# --------------------------------------------------------------------------- geometry

def test_non_manifold_faces_and_a_loose_edge_render_finite(tmp_path):
    """Three faces on one edge, two faces of opposite winding on another, a loose edge."""
    _scene()
    mesh = bpy.data.meshes.new("non-manifold")
    mesh.from_pydata([(0, 0, 2), (1, 0, 2), (0.5, 1, 2), (0.5, -1, 2), (0.5, 0, 3),
                      (2, 2, 2), (2, 2, 3)], [(5, 6)],
                     [(0, 1, 2), (1, 0, 3), (0, 1, 4), (2, 1, 0)])
    ob = bpy.data.objects.new("NonManifold", mesh)
    bpy.context.scene.collection.objects.link(ob)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = _sync()
    assert {st.name: st.status for st in state.objects}["NonManifold"] == "ok"
    assert all(np.isfinite(st.points.normals).all() for st in state.objects)
    _frame(tmp_path / "a.exr")


def test_zero_normals_are_repaired_not_nan(tmp_path):
    """A smooth triangle collapsed to a point has zero corner normals, and an object
    scaled to 0 along its normal axis has a singular matrix: both give unit normals and
    a finite frame."""
    _scene()
    mesh = bpy.data.meshes.new("collapsed")
    mesh.from_pydata([(0, 0, 2.5)] * 3 + [(1, 0, 2.5), (0, 1, 2.5)], [],
                     [(0, 1, 2), (0, 3, 4)])
    for poly in mesh.polygons:
        poly.use_smooth = True
    ob = bpy.data.objects.new("Collapsed", mesh)
    bpy.context.scene.collection.objects.link(ob)
    bpy.data.objects["Sphere"].scale = (1.0, 1.0, 0.0)          # flattened to a disc
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state = _sync()
    assert state.error is None
    for st in state.objects:
        n = st.points.normals
        assert np.isfinite(n).all() and np.allclose(np.linalg.norm(n, axis=1), 1.0), st.name
    for method in ("REFERENCE", "SH"):
        bpy.context.scene.prt.method = method
        _frame(tmp_path / f"{method}.exr")


def test_one_vertex_mesh_is_skipped_and_alone_is_refused():
    _scene()
    mesh = bpy.data.meshes.new("one")
    mesh.from_pydata([(0.0, 0.0, 3.0)], [], [])
    one = bpy.data.objects.new("OneVertex", mesh)
    bpy.context.scene.collection.objects.link(one)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    assert not storage.has(one, storage.VISIBILITY)
    assert storage.has(bpy.data.objects["Sphere"], storage.VISIBILITY)
    assert "OneVertex" not in {st.name for st in _sync().objects}
    # only that mesh in the scene: nothing to precompute, said so, nothing written
    scenes.reset()
    scenes.add_world("sunset")
    mesh = bpy.data.meshes.new("one")
    mesh.from_pydata([(0.0, 0.0, 3.0)], [], [])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("OneVertex", mesh))
    _refused("Nothing to precompute: no visible mesh object has faces")


def test_empty_scene_is_refused_and_renders_an_empty_frame(tmp_path):
    scenes.reset()
    scenes.add_world("sunset")
    _refused("Nothing to precompute")
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(16, 12)
    frame = scenes.render_exr(tmp_path / "empty.exr")
    assert np.isfinite(frame).all() and frame.max() == 0.0      # transparent film, nothing


def test_every_object_hidden_from_renders_is_refused():
    _scene()
    for ob in bpy.data.objects:
        ob.hide_render = True
    _refused("no visible mesh object has faces")


def test_whole_scene_scaled_by_1e_4_or_1e4_draws_the_same_frame(tmp_path):
    """Select all, scale by 1e-4 or 1e4 (camera included, clip range with it): the ray
    offset is relative to the scene's size and the camera's scale is no part of its view
    (Blender renders it so), so the frame is the unit-scale frame."""
    _scene()
    bpy.ops.prt.precompute()
    unit = _frame(tmp_path / "unit.exr")
    for s in (1e-4, 1e4):
        _scene()
        for ob in bpy.data.objects:
            ob.location = [c * s for c in ob.location]
            ob.scale = [c * s for c in ob.scale]
        cam = bpy.context.scene.camera.data
        cam.clip_start *= s
        cam.clip_end *= s
        assert bpy.ops.prt.precompute() == {"FINISHED"}
        frame = _frame(tmp_path / f"{s}.exr")
        np.testing.assert_allclose(frame, unit, atol=2e-3 * unit.max())


def test_mirrored_open_mesh_is_shaded_as_the_unmirrored_one(tmp_path):
    """Negative scale flips the winding; an open mesh (the ground, symmetric in y but
    for its quads' diagonals) under a ball is drawn as before the mirror."""
    _scene()
    bpy.ops.prt.precompute()
    plain = _frame(tmp_path / "plain.exr")
    bpy.data.objects["Ground"].scale = (1.0, -1.0, 1.0)
    bpy.ops.prt.precompute()
    mirrored = _frame(tmp_path / "mirrored.exr")
    # the same up to the quads' diagonals, which the mirror turns the other way
    assert abs(mirrored[..., :3].mean() - plain[..., :3].mean()) < 0.01 * plain[..., :3].mean()
    assert (np.abs(mirrored - plain) > 0.02 * plain.max()).mean() < 0.01


# --------------------------------------------------------------------------- materials

def test_roughness_0_and_1_render_finite_with_every_method(tmp_path):
    """Glossy roughness 1 on the ball, Principled metal roughness 1 on the ground, a
    Glossy mirror (roughness 0) beside them: every method draws a finite frame; SH says
    it leaves the glossy part out."""
    scene = _scene()
    bpy.data.objects["Sphere"].data.materials.append(
        scenes.bsdf_material("Rough glossy", "ShaderNodeBsdfGlossy", Roughness=1.0))
    bpy.data.objects["Ground"].data.materials.append(
        scenes.bsdf_material("Rough metal", "ShaderNodeBsdfPrincipled", Roughness=1.0,
                         Metallic=1.0))
    bpy.ops.mesh.primitive_uv_sphere_add(location=(1.3, 1.0, 0.5), radius=0.4, segments=12,
                                         ring_count=6)
    bpy.context.object.data.materials.append(
        scenes.bsdf_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=0.0))
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    means = {}
    for method in METHODS:
        scene.prt.method = method
        frame = scenes.render_exr(tmp_path / f"{method}.exr")
        assert np.isfinite(frame).all() and frame.min() >= 0.0, method
        means[method] = frame[..., :3].mean()
        if method == "SH":
            assert any("SH draws diffuse transfer only" in w and "Sphere" in w
                       for w in runtime.LAST_MESSAGES), runtime.LAST_MESSAGES
    assert all(0.05 * means["REFERENCE"] < m < 2.0 * means["REFERENCE"]
               for k, m in means.items() if k != "SH"), means


def test_anisotropy_1_to_16(tmp_path):
    """Principled Anisotropic is warned (drawn isotropic); SSDF_SG's own anisotropic
    Ward of alpha 0.8 : 0.05 and Ashikhmin-Shirley of 10 : 160 draw finite frames."""
    scene = _scene()
    mat = scenes.bsdf_material("Brushed", "ShaderNodeBsdfPrincipled", Roughness=0.4,
                           Metallic=1.0, Anisotropic=0.9)
    bpy.data.objects["Sphere"].data.materials.append(mat)
    bpy.ops.prt.precompute()
    assert any("'Brushed'" in w and "anisotropy" in w and "not modelled" in w
               for w in _sync().warnings)
    _frame(tmp_path / "principled.exr")
    scene.prt.method = "SSDF_SG"
    sg = mat.prt_sg
    sg.use_blender_material = False
    for model, a, b in (("WARD_ANISO", 0.8, 0.05), ("ASHIKHMIN_SHIRLEY", 10.0, 160.0)):
        sg.model = model
        if model == "WARD_ANISO":
            sg.alpha_x, sg.alpha_y = a, b
        else:
            sg.nu, sg.nv = a, b
        _frame(tmp_path / f"{model}.exr")


def test_empty_material_slots_draw_as_no_material(tmp_path):
    """0 slots and two empty slots are both Cycles' default surface: the same frame."""
    _scene()
    bpy.ops.prt.precompute()
    none = _frame(tmp_path / "none.exr")
    sphere = bpy.data.objects["Sphere"]
    sphere.data.materials.append(None)
    sphere.data.materials.append(None)
    for poly in sphere.data.polygons:
        poly.material_index = poly.index % 2
    bpy.ops.prt.precompute()
    empty = _frame(tmp_path / "empty.exr")
    np.testing.assert_allclose(empty, none, atol=1e-5)


def test_missing_texture_image_warns_and_draws_the_default_colour(tmp_path):
    _scene()
    bpy.ops.prt.precompute()
    plain = _frame(tmp_path / "plain.exr")
    mat = bpy.data.materials.new("Textured")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(scenes.hdri_path("forest")))
    tex.image.filepath = str(tmp_path / "gone.png")
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    bpy.data.objects["Sphere"].data.materials.append(mat)
    state = _sync()
    assert state.error is None
    assert any("'Textured'" in w and "cannot be read" in w and "gone.png" in w
               and "default colour" in w for w in state.warnings), state.warnings
    frame = _frame(tmp_path / "missing.exr")
    np.testing.assert_allclose(frame, plain, atol=1e-5)     # the default Principled colour


# --------------------------------------------------------------------------- world

def test_world_without_nodes_is_refused_and_a_colour_world_lights(tmp_path):
    scene = _scene()
    nt = scene.world.node_tree
    for node in list(nt.nodes):
        nt.nodes.remove(node)
    _refused(f"World '{scene.world.name}' has no World Output with a Surface link")
    assert "no World Output" in (_sync().error or "")
    with pytest.raises(RuntimeError, match="no World Output"):
        scenes.render_exr(tmp_path / "x.exr")
    # a Background colour without any texture: a uniform sky
    scene = _scene()
    nt = scene.world.node_tree
    nt.nodes.remove(nt.nodes["Environment Texture"])
    nt.nodes["Background"].inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    frame = _frame(tmp_path / "grey.exr")
    assert frame[..., :3].max() < 0.5 + 1e-3          # never brighter than the sky


def test_16k_world_is_drawn_from_a_halved_texture(tmp_path, monkeypatch):
    """A 16384 x 8192 world made F12 fail (a 2 GiB RGBA32F texture: gpu.texture.new
    failed).  Wider than envmap.DISPLAY_MAX_WIDTH the background and sharp lobes draw
    from halvings that keep the energy; the lighting is still resampled from the full
    image.  Checked with the limit at 64 on a 256-wide sky (the 16k image itself: by
    hand, docs/reliability.md)."""
    from prt_relight.core.sphere import envmap
    rng = np.random.default_rng(1)
    sky = rng.uniform(0.1, 1.0, (128, 256, 3)).astype(np.float32)
    halved = envmap.halve_equirect(sky, rows=7)             # in bands of rows, as for 16k
    edges = np.cos(np.linspace(0.0, np.pi, 129))
    band = (edges[:-1] - edges[1:])[:, None]
    e_full = (sky * band[..., None]).sum(axis=(0, 1)) / 256
    e2 = np.cos(np.linspace(0.0, np.pi, 65))
    e_half = (halved * (e2[:-1] - e2[1:])[:, None, None]).sum(axis=(0, 1)) / 128
    np.testing.assert_allclose(e_half, e_full, rtol=1e-5)
    assert envmap.display_equirect(sky, 64).shape == (32, 64, 3)
    assert envmap.display_equirect(sky) is sky

    scene = _scene()
    scene.world.node_tree.nodes["Environment Texture"].image = scenes.float_image("sky", sky)
    scene.render.film_transparent = False
    bpy.data.objects["Sphere"].data.materials.append(
        scenes.bsdf_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=0.0))
    bpy.ops.prt.precompute()
    full = scenes.render_exr(tmp_path / "full.exr", transparent=False)
    monkeypatch.setattr(envmap, "DISPLAY_MAX_WIDTH", 64)
    shown = scenes.render_exr(tmp_path / "shown.exr", transparent=False)
    assert np.isfinite(shown).all()
    # the same mean radiance, the background blurred to 64 columns
    np.testing.assert_allclose(shown[..., :3].mean(), full[..., :3].mean(), rtol=0.05)


def test_an_8bit_srgb_world_of_255_lights_as_1(tmp_path):
    """An LDR (8-bit sRGB PNG) world of 255 everywhere reads as linear 1, so a diffuse
    white-ish ground under it is lit as by a sky of radiance 1 (finite, ≤ 1)."""
    path = tmp_path / "white.png"
    img = bpy.data.images.new("white", 64, 32, alpha=False)
    img.pixels.foreach_set(np.ones(64 * 32 * 4, np.float32))
    img.filepath_raw = str(path)
    img.file_format = "PNG"
    img.save()
    scene = _scene()
    world_img = bpy.data.images.load(str(path))
    assert world_img.colorspace_settings.name == "sRGB" and not world_img.is_float
    scene.world.node_tree.nodes["Environment Texture"].image = world_img
    bpy.ops.prt.precompute()
    frame = _frame(tmp_path / "ldr.exr")
    assert frame[..., :3].max() <= 1.0 + 1e-3


# --------------------------------------------------------------------------- camera

def test_no_camera_precomputes_refuses_f12_and_auto_chooses_at_its_probes(monkeypatch):
    """Without a camera the precompute runs, F12 is refused by Blender's own message,
    and AUTO chooses at its probe views.  In -b its GPU passes first needed a Workbench
    render, which failed with "Cannot render, no camera": the choice was never made."""
    from prt_relight.addon.gpu import drawing
    from prt_relight.addon.methods.auto import measure as auto_measure
    from prt_relight.addon.methods.auto import measure
    scene = _scene()
    bpy.data.objects.remove(bpy.data.objects["Camera"])
    assert scene.camera is None
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    with pytest.raises(RuntimeError, match="no camera"):
        bpy.ops.render.render()
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in ("SH",)])
    monkeypatch.setattr(drawing, "_GPU_READY", False)       # as in a fresh `blender -b`
    scene.prt.method = "AUTO"
    counts = _data_counts()
    assert bpy.ops.prt.auto_choose() == {"FINISHED"}
    record = json.loads(scene.prt.auto_choice)
    assert record["camera"] is None and record["objects"]
    assert _data_counts() == counts                # the temporary camera is gone


# --------------------------------------------------------------------------- after the precompute

def test_every_method_draws_after_a_reference_precompute(tmp_path):
    """Switching the method after a precompute needs no new one: each draws from the
    stored visibility (deriving what it stores itself) a frame near REFERENCE's."""
    scene = _scene()
    bpy.ops.prt.precompute()
    ref = _frame(tmp_path / "REFERENCE.exr")
    for method in METHODS[1:]:
        scene.prt.method = method
        state = _sync()
        assert all(st.status == "ok" for st in state.objects), method
        assert not any("Not precomputed" in w for w in state.warnings), method
        frame = _frame(tmp_path / f"{method}.exr")
        assert abs(frame[..., :3].mean() - ref[..., :3].mean()) < 0.1 * ref[..., :3].mean()


def test_directions_changed_after_the_precompute_are_named_in_the_panel(tmp_path):
    from prt_relight.addon.ui import panels

    from ..addon.ui.fakes import FakeContext, FakeLayout
    scene = _scene()
    bpy.ops.prt.precompute()
    before = _frame(tmp_path / "a.exr")
    scene.prt.resolution = "64"
    log = []
    panels.draw_settings(FakeLayout(log), FakeContext(scene))
    assert ("label", "Stored data uses 6×32²: precompute again") in log
    state = _sync()
    assert state.resolution == 32 and all(st.status == "ok" for st in state.objects)
    np.testing.assert_array_equal(_frame(tmp_path / "b.exr"), before)


# --------------------------------------------------------------------------- writing files

@pytest.mark.parametrize("where", ["disk full", "not a folder"])
def test_report_that_cannot_be_written_says_why_and_leaves_everything(tmp_path, monkeypatch,
                                                                      where):
    from prt_relight.core.report import metrics as core_report
    scene = _scene()
    bpy.ops.prt.precompute()
    scene.prt.method = "SH"
    scene.prt.sh_order = 3
    before, counts = _stored(), _data_counts()
    if where == "disk full":
        def full(*args, **kwargs):
            raise OSError(errno.ENOSPC, "No space left on device")
        monkeypatch.setattr(core_report, "write_html", full)
        out = tmp_path / "rep"
        message = "No space left on device"
    else:
        (tmp_path / "file").write_text("x")
        out = tmp_path / "file" / "rep"
        message = "Not a directory"
    with pytest.raises(RuntimeError, match=f"PRT report failed: .*{message}"):
        bpy.ops.prt.report(directory=str(out), repeats=1, stability=False, methods="SH")
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ([] if where == "disk full"
                                                          else ["file"])
    assert scene.prt.method == "SH" and scene.prt.sh_order == 3
    assert _stored() == before and _data_counts() == counts


# --------------------------------------------------------------------------- the table

def test_every_test_the_reliability_table_names_exists(repo_root):
    """docs/reliability.md names a test in every row; each one is defined."""
    import re
    text = (repo_root / "docs" / "reliability.md").read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if re.match(r"\| \d+ \|", line)]
    assert len(rows) >= 30
    for row in rows:
        names = re.findall(r"`((?:R|(?:\w+/)*test_\w+\.py)::test_\w+)`", row)
        assert names, row
        for name in names:
            file, func = name.split("::")
            file = "integration/test_reliability.py" if file == "R" else file
            source = (repo_root / "tests" / file).read_text(encoding="utf-8")
            assert re.search(rf"^def {func}\(", source, re.M), name
