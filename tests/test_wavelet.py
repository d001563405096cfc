"""WAVELET (Ng 03 double product, Ng 04 triple product) against the pixel-basis sums."""

import numpy as np


RNG = np.random.default_rng(7)


def test_wavelet_method_renders_near_reference(registered_addon, tmp_path):
    """F12 with WAVELET: all lighting terms and full transport reproduce REFERENCE's
    diffuse image; 1 % glossy triple product stays close; fewer terms err more."""
    import bpy
    from . import blender_scene as bs

    bs.reset()
    bs.add_world(path=bs.hdri_path("courtyard"), rotation_z=0.4)
    ground = bs.add_ground(size=6.0, cuts=16)
    monkey = bs.add_suzanne(subdiv=1)
    bs.add_camera()
    bs.set_resolution(64, 48)
    ground.data.materials.append(bs.bsdf_material("diffuse", "ShaderNodeBsdfDiffuse"))
    monkey.data.materials.append(bs.bsdf_material("glossy", "ShaderNodeBsdfGlossy",
                                                  Roughness=0.35))
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ref = bs.render_exr(tmp_path / "ref.exr")
    scene.prt.method = "WAVELET"
    scene.prt.wavelet_terms = 6 * 32 * 32
    scene.prt.wavelet_transfer_percent = 100.0
    scene.prt.wavelet_glossy_percent = 100.0
    exact = bs.render_exr(tmp_path / "exact.exr")
    assert bs.rel_l2(exact, ref) < 2e-3
    # Ng 04: 1 % / 10 % of the lighting and BRDF coefficients (measured 9.8 % / 0.7 %)
    glossy = []
    for percent in (1.0, 10.0):
        scene.prt.wavelet_glossy_percent = percent
        glossy.append(bs.rel_l2(bs.render_exr(tmp_path / f"g{percent}.exr"), ref))
    assert 0.01 < glossy[0] < 0.2 and glossy[1] < 0.3 * glossy[0]
    # Ng 03: 16 lighting terms blur the courtyard's light (measured 22.6 %); 10 % transport
    scene.prt.wavelet_glossy_percent = 100.0
    scene.prt.wavelet_transfer_percent = 10.0
    scene.prt.wavelet_terms = 16
    img = bs.render_exr(tmp_path / "w16.exr")
    assert np.isfinite(img).all()
    assert bs.rel_l2(img, ref) > 0.1
