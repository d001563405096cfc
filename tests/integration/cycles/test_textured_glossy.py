"""Glossy Principled objects against converged Cycles (several seeds, their variance
subtracted: core.report.metrics.rel_l2_converged): a Roughness image and a Normal Map of an image
(issue 16's glossy case; SSDF_SG reads both per pixel, Wang et al. 2009 §4, §7), and the
dielectric's view-dependent layering of its Lambert base."""

from __future__ import annotations

import bpy
import pytest

from prt_relight.core.report import metrics as report
from prt_relight.bench import scenes

from ...cases.glossy import glossy_object


pytestmark = pytest.mark.usefixtures("registered_addon")


def _converged_cycles_and_ssdf_sg(tmp_path, spp):
    """The camera of tests/integration/cycles/test_textures.py's sphere (64x64, 3x3 supersamples); Cycles
    direct light with four seeds of ``spp``; SSDF_SG precomputed: ``(frames, error of
    SSDF_SG's frame against them, the mean's noise)``."""
    scenes.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 64)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    frames = []
    for seed in range(4):
        scene.cycles.seed = seed
        frames.append(scenes.render_exr(tmp_path / f"cycles{seed}.exr", engine="CYCLES",
                                    samples=spp))
    scene.prt.method = "SSDF_SG"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _, noise, err = report.rel_l2_converged(scenes.render_exr(tmp_path / "ours.exr"), frames)
    return frames, err, noise


@pytest.mark.slow
@pytest.mark.parametrize("shape, metallic, bound", [("SUZANNE", 0.0, 0.035),
                                                    ("SPHERE", 1.0, 0.04),
                                                    ("SUZANNE", 1.0, 0.06)])
def test_roughness_texture_and_normal_map_against_converged_cycles(tmp_path, shape, metallic,
                                                                   bound):
    """Suzanne (subdivided twice) or a UV sphere under 'forest', 64x64: SSDF_SG against
    Cycles direct light converged (four seeds x 1024 spp, their variance subtracted), within
    the issue's 6 % (measured 2.4 % dielectric Suzanne, 2.4 % metal sphere, 4.9 % metal
    Suzanne: its concave parts need eq. 41's light read at the visible part of each lobe,
    docs/measurements.md "The visible part's light"); drawn with the roughness's mean and
    without the normal map it is further off."""
    scenes.reset()
    scenes.add_world("forest")
    bsdf = glossy_object(metallic, shape)
    frames, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 1024)
    nt = bsdf.id_data
    for socket in ("Roughness", "Normal"):
        nt.links.remove(bsdf.inputs[socket].links[0])
    bsdf.inputs["Roughness"].default_value = 0.45
    _, _, plain = report.rel_l2_converged(scenes.render_exr(tmp_path / "plain.exr"), frames)
    print(f"{shape} metallic {metallic}: SSDF_SG {100 * err:.2f} % (Cycles' mean's noise "
          f"{100 * noise:.2f} %), untextured {100 * plain:.2f} %")
    assert err < bound and plain > 3 * err, (err, plain)


@pytest.mark.slow
@pytest.mark.parametrize("roughness", [0.15, 0.3])
def test_principled_dielectric_sphere_against_converged_cycles(tmp_path, roughness):
    """A Principled dielectric sphere under 'forest' (64x64): Cycles' Lambert base is
    weighted per view by what the specular layer takes (closure_layering_weight), up to 40 %
    less at grazing views at r 0.3; SSDF_SG draws that weight per pixel (measured 0.8 / 1.0 %
    at r 0.15 / 0.3; with the weight's mean over views 6.0 / 4.7 %, the rim too bright)."""
    scenes.reset()
    scenes.add_world("forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(scenes.bsdf_material(
        "dielectric", "ShaderNodeBsdfPrincipled", Roughness=roughness,
        **{"Base Color": (0.9, 0.7, 0.5, 1.0)}))
    _, err, noise = _converged_cycles_and_ssdf_sg(tmp_path, 512)
    print(f"dielectric r {roughness}: SSDF_SG {100 * err:.2f} % (noise {100 * noise:.2f} %)")
    assert err < 0.02, err
