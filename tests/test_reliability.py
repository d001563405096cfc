"""Hard or bad input an artist hits, each with what must happen: a clear message and the
scene unchanged, or a correct finite frame (docs/reliability.md lists every case with
the test that checks it, here or in another test file)."""

from __future__ import annotations

import errno
import json

import bpy
import numpy as np
import pytest

from prt_relight.addon import runtime, storage

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET"]


def _scene(hdri="sunset", cuts=8):
    """A 4 m ground, a coarse smooth ball above it (no material), a camera: ~350 points."""
    bs.reset()
    bs.add_world(path=bs.hdri_path(hdri))
    bs.add_ground(size=4.0, cuts=cuts)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 1.0), radius=0.8, segments=12,
                                         ring_count=6)
    bpy.ops.object.shade_smooth()
    bs.add_camera()
    bs.set_resolution(32, 24)
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
    frame = bs.render_exr(path)
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


# --------------------------------------------------------------------------- camera

def test_no_camera_precomputes_refuses_f12_and_auto_chooses_at_its_probes(monkeypatch):
    """Without a camera the precompute runs, F12 is refused by Blender's own message,
    and AUTO chooses at its probe views.  In -b its GPU passes first needed a Workbench
    render, which failed with "Cannot render, no camera": the choice was never made."""
    from prt_relight.addon import drawing
    from prt_relight.addon.methods import auto
    scene = _scene()
    bpy.data.objects.remove(bpy.data.objects["Camera"])
    assert scene.camera is None
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    with pytest.raises(RuntimeError, match="no camera"):
        bpy.ops.render.render()
    every = auto.AutoMethod.candidates
    monkeypatch.setattr(auto.AutoMethod, "candidates", staticmethod(
        lambda: [c for c in every() if c[0].id in ("SH",)]))
    monkeypatch.setattr(drawing, "_GPU_READY", False)       # as in a fresh `blender -b`
    scene.prt.method = "AUTO"
    counts = _data_counts()
    assert bpy.ops.prt.auto_choose() == {"FINISHED"}
    record = json.loads(scene.prt.auto_choice)
    assert record["camera"] is None and record["objects"]
    assert _data_counts() == counts                # the temporary context scene is gone


def test_16k_world_is_drawn_from_a_halved_texture(tmp_path, monkeypatch):
    """A 16384 x 8192 world made F12 fail (a 2 GiB RGBA32F texture: gpu.texture.new
    failed).  Wider than envmap.DISPLAY_MAX_WIDTH the background and sharp lobes draw
    from halvings that keep the energy; the lighting is still resampled from the full
    image.  Checked with the limit at 64 on a 256-wide sky (the 16k image itself: by
    hand, docs/reliability.md)."""
    from prt_relight.core import envmap
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
    scene.world.node_tree.nodes["Environment Texture"].image = bs.float_image("sky", sky)
    scene.render.film_transparent = False
    bpy.data.objects["Sphere"].data.materials.append(
        bs.bsdf_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=0.0))
    bpy.ops.prt.precompute()
    full = bs.render_exr(tmp_path / "full.exr", transparent=False)
    monkeypatch.setattr(envmap, "DISPLAY_MAX_WIDTH", 64)
    shown = bs.render_exr(tmp_path / "shown.exr", transparent=False)
    assert np.isfinite(shown).all()
    # the same mean radiance, the background blurred to 64 columns
    np.testing.assert_allclose(shown[..., :3].mean(), full[..., :3].mean(), rtol=0.05)
