"""WAVELET in headless Blender (addon/methods/wavelet/shading.py): F12 with all lighting
terms and full transport reproduces REFERENCE's diffuse image; truncated, it stays close."""

import numpy as np

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


def test_wavelet_method_renders_near_reference(registered_addon, tmp_path):
    """F12 with WAVELET: all lighting terms and full transport reproduce REFERENCE's
    diffuse image; 1 % glossy triple product stays close; fewer terms err more."""
    import bpy

    scenes.reset()
    scenes.add_world("courtyard", rotation_z=0.4)
    ground = scenes.add_ground(size=6.0, cuts=16)
    monkey = scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    ground.data.materials.append(scenes.bsdf_material("diffuse", "ShaderNodeBsdfDiffuse"))
    monkey.data.materials.append(scenes.bsdf_material("glossy", "ShaderNodeBsdfGlossy",
                                                  Roughness=0.35))
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ref = scenes.render_exr(tmp_path / "ref.exr")
    assert ref[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    scene.prt.method = "WAVELET"
    scene.prt.wavelet_terms = 6 * 32 * 32
    scene.prt.wavelet_transfer_percent = 100.0
    scene.prt.wavelet_glossy_percent = 100.0
    exact = scenes.render_exr(tmp_path / "exact.exr")
    assert rel_l2(exact, ref) < 2e-3
    # Ng 04: 1 % / 10 % of the lighting and BRDF coefficients (measured 9.8 % / 0.7 %)
    glossy = []
    for percent in (1.0, 10.0):
        scene.prt.wavelet_glossy_percent = percent
        glossy.append(rel_l2(scenes.render_exr(tmp_path / f"g{percent}.exr"), ref))
    assert 0.01 < glossy[0] < 0.2 and glossy[1] < 0.3 * glossy[0]
    # Ng 03: 16 lighting terms blur the courtyard's light (measured 22.6 %); 10 % transport
    scene.prt.wavelet_glossy_percent = 100.0
    scene.prt.wavelet_transfer_percent = 10.0
    scene.prt.wavelet_terms = 16
    img = scenes.render_exr(tmp_path / "w16.exr")
    assert np.isfinite(img).all()
    assert rel_l2(img, ref) > 0.1
