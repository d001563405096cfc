"""REFERENCE and SSDF_SG against Cycles direct lighting (max_bounces 0), and the F12 pixel
filter against Cycles' at a silhouette: slow, small scenes.

Thresholds: Cycles' own noise at these sample counts is about 1 % rel-L2, and
per-vertex shading of a tessellated scene is 1.6-3.7 % off per-pixel shading
(docs/measurements.md), so 3 % is the bound for the diffuse scene.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("registered_addon")]


def _sphere_under_sun(direction):
    scenes.reset()
    img = scenes.float_image("sun", scenes.sun_image(256, 128, direction, radiance=3000.0))
    scenes.add_world(image=img)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0)
    bpy.ops.object.shade_smooth()
    scenes.add_camera(location=(0.0, -5.0, 0.0), rotation=(np.pi / 2, 0.0, 0.0), resolution=None)
    scenes.set_resolution(48, 48)


@pytest.mark.parametrize("direction", [(1.0, -0.4, 0.3), (0.0, -1.0, 0.0), (-0.6, -0.5, -0.4)])
def test_one_pixel_sun_lights_the_side_facing_it_like_cycles(tmp_path, direction):
    _sphere_under_sun(direction)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ours = scenes.render_exr(tmp_path / "prt.exr")
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err = rel_l2(ours, cycles)
    # Per-vertex shading of the terminator costs a few percent here.
    assert err < 0.12, err
    # The same sun mirrored through the sphere's centre is far off: the test can fail.
    mirrored = scenes.sun_image(256, 128, -np.asarray(direction), radiance=3000.0)
    img = bpy.data.images["sun"]
    rgba = np.ones((128, 256, 4), np.float32)
    rgba[:, :, :3] = mirrored
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.update()
    wrong = scenes.render_exr(tmp_path / "wrong.exr")
    assert np.isfinite(wrong).all()                # rel_l2 of a non-finite image is inf
    assert rel_l2(wrong, cycles) > 0.5


def test_diffuse_scene_within_three_percent_of_cycles(tmp_path):
    scenes.reset()
    scenes.add_world("sunset", rotation_z=0.7)
    scenes.add_ground(size=6.0, cuts=48)
    scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ours = scenes.render_exr(tmp_path / "prt.exr")
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err = rel_l2(ours, cycles)
    print(f"REFERENCE vs Cycles rel-L2: {err:.4f}")
    assert err <= 0.03, err


def test_f12_pixel_filter_matches_cycles_at_a_silhouette(tmp_path):
    """A plane's edge across a transparent film: Cycles resolves its samples with a
    Blackman-Harris filter of Film width 1.5 px, and so does our supersampled F12; the box
    mean over each pixel's own samples (Filter Size 0) is visibly off at the edge."""
    scenes.reset()
    scenes.add_world(image=scenes.float_image("white", np.ones((4, 8, 3), np.float32)))
    bpy.ops.mesh.primitive_plane_add(size=2.0, rotation=(0.0, 0.0, 0.35))
    plane = bpy.context.object
    plane.data.materials.append(scenes.bsdf_material("Plane", "ShaderNodeBsdfDiffuse",
                                                 Color=(0.8, 0.8, 0.8, 1.0)))
    scenes.add_camera(location=(0.9, 0.5, 2.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    scenes.set_resolution(32, 32)
    scene = bpy.context.scene
    assert scene.cycles.pixel_filter_type == "BLACKMAN_HARRIS"
    assert scene.cycles.filter_width == pytest.approx(scene.render.filter_size)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    scene.prt.supersampling = 4
    ours = scenes.render_exr(tmp_path / "prt.exr")
    scene.render.filter_size = 0.0
    box = scenes.render_exr(tmp_path / "box.exr")
    scene.render.filter_size = 1.5
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    edge = (cycles[..., 3] > 0.02) & (cycles[..., 3] < 0.98)
    assert edge.sum() > 20                      # the edge crosses the frame

    def err(img):
        return float(np.linalg.norm((img - cycles)[edge]) / np.linalg.norm(cycles[edge]))
    print(f"edge pixels {edge.sum()}: rel-L2 Blackman-Harris {err(ours):.4f}, box {err(box):.4f}")
    assert err(ours) < 0.05, err(ours)
    assert err(box) > 2.0 * err(ours)
    # Away from the edge the white world lights the open plane to 0.8 in both.
    inside = cycles[..., 3] > 0.999
    assert np.allclose(ours[inside][:, :3], 0.8, rtol=0.03)


def _suzanne_on_ground_with_ssdf_sg(hdri, node_type, **inputs):
    """Suzanne (subdivision 2, one ``node_type`` BSDF with ``inputs``) on a diffuse 0.8
    ground of 48², the bundled ``hdri`` turned 0.6 rad, 80×60, precomputed for SSDF_SG;
    returns Suzanne."""
    scenes.reset()
    scenes.add_world(hdri, rotation_z=0.6)
    ground = scenes.add_ground(size=6.0, cuts=48)
    ground.data.materials.append(scenes.bsdf_material("Ground", "ShaderNodeBsdfDiffuse",
                                                  Color=(0.8, 0.8, 0.8, 1.0)))
    suz = scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    suz.data.materials.append(scenes.bsdf_material("Suzanne", node_type, **inputs))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(80, 60)
    bpy.context.scene.prt.method = "SSDF_SG"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    return suz


def test_ssdf_sg_glossy_within_six_percent_of_cycles(tmp_path):
    """SSDF_SG's glossy goal on a small scene: a Beckmann Glossy BSDF (roughness 0.3)
    Suzanne on a diffuse ground under 'city' (a small sun), SSDF_SG's per-pixel F12
    against Cycles (direct light, 2048 spp: glossy highlights of a small sun are noisy)."""
    suz = _suzanne_on_ground_with_ssdf_sg("city", "ShaderNodeBsdfGlossy",
                                          distribution="BECKMANN", Roughness=0.3)
    ours = scenes.render_exr(tmp_path / "ssdf_sg.exr")
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=2048)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err = rel_l2(ours, cycles)
    # the same frame with the slider at roughness 0.6 (a redraw, no precompute) is far off:
    # the comparison sees the glossy lobe
    node = suz.data.materials[0].node_tree.nodes["Glossy BSDF"]
    node.inputs["Roughness"].default_value = 0.6
    rougher = rel_l2(scenes.render_exr(tmp_path / "rougher.exr"), cycles)
    print(f"SSDF_SG glossy vs Cycles rel-L2: {err:.4f} (roughness 0.6 instead: {rougher:.4f})")
    assert err <= 0.06, err
    assert rougher > 2.0 * err


def test_ssdf_sg_diffuse_within_three_percent_of_cycles(tmp_path):
    """SSDF_SG's diffuse goal on a small scene: diffuse Suzanne (subdivision 2) on a 48²
    ground under 'sunset', SSDF_SG's F12 (scene-fitted lighting, SG7 cosine) against
    Cycles 512 spp and against REFERENCE (measured 2.2 % / 1.9 %; 2.3 % / 2.0 % without the
    default Min Occlusion Kept)."""
    _suzanne_on_ground_with_ssdf_sg("sunset", "ShaderNodeBsdfDiffuse",
                                    Color=(0.8, 0.8, 0.8, 1.0))
    scene = bpy.context.scene
    ours = scenes.render_exr(tmp_path / "ssdf_sg.exr")
    scene.prt.method = "REFERENCE"
    ref = scenes.render_exr(tmp_path / "reference.exr")
    assert ref[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    err_cycles, err_ref = rel_l2(ours, cycles), rel_l2(ours, ref)
    print(f"SSDF_SG diffuse vs Cycles {err_cycles:.4f}, vs REFERENCE {err_ref:.4f}")
    assert err_cycles <= 0.03, err_cycles
    assert err_ref <= 0.025, err_ref
