"""Textured inputs against Cycles: a textured statue on a textured ground, SSDF_SG's textured
error equal to its untextured one, a Roughness checker on a glossy sphere: slow."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2

from ...cases.textures import rough_principled, texture_image, textured_material


pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "RSL", "BLOCKS", "SH", "WAVELET"]


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- Blender

def _checker(n=32, cells=4):
    yy, xx = np.mgrid[0:n, 0:n]
    chk = ((xx // (n // cells) + yy // (n // cells)) % 2).astype(np.float32)
    rgba = np.ones((n, n, 4), np.float32)
    rgba[..., 0] = 0.1 + 0.8 * chk
    rgba[..., 1] = 0.5
    rgba[..., 2] = 0.9 - 0.8 * chk
    return rgba


@pytest.mark.slow
def test_textured_statue_on_a_textured_ground_matches_cycles(tmp_path):
    scenes.reset()
    scenes.add_world("forest")
    ground = scenes.add_ground(size=6.0, cuts=48)
    img = texture_image("checker", _checker(64, 8))
    ground.data.materials.append(textured_material("Ground", img, node="ShaderNodeBsdfPrincipled"))
    suzanne = scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    photo = np.ones((32, 32, 4), np.float32)
    yy, xx = np.mgrid[0:32, 0:32] / 32.0
    photo[..., 0] = 0.5 + 0.4 * np.sin(9 * xx)
    photo[..., 1] = 0.4 + 0.3 * np.cos(7 * yy)
    photo[..., 2] = 0.3 + 0.2 * xx * yy
    suzanne.data.materials.append(textured_material("Statue", texture_image("photo", photo, "sRGB")))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(96, 72)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=512)
    assert truth[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    errors = {}
    for method in METHODS:
        bpy.context.scene.prt.method = method
        errors[method] = rel_l2(scenes.render_exr(tmp_path / f"{method}.exr"), truth)
    assert errors["REFERENCE"] < 0.02, errors
    assert all(e < 0.08 for e in errors.values()), errors


def _photo(n=32):
    photo = np.ones((n, n, 4), np.float32)
    yy, xx = np.mgrid[0:n, 0:n] / float(n)
    photo[..., 0] = 0.5 + 0.4 * np.sin(9 * xx)
    photo[..., 1] = 0.4 + 0.3 * np.cos(7 * yy)
    photo[..., 2] = 0.3 + 0.2 * xx * yy
    return photo


@pytest.mark.slow
def test_ssdf_sg_textured_error_is_its_untextured_error(tmp_path):
    """A textured statue on a textured ground under an HDRI: SSDF_SG's distance to REFERENCE
    (exact for a textured Lambert base) is within half a point of the same scene drawn with
    each texture's mean colour."""
    scenes.reset()
    scenes.add_world("forest")
    ground = scenes.add_ground(size=6.0, cuts=48)
    suzanne = scenes.add_suzanne(subdiv=2, location=(0.0, 0.0, 1.0))
    checker, photo = _checker(64, 8), _photo()
    textured = {ground: textured_material("Ground", texture_image("checker", checker)),
                suzanne: textured_material("Statue", texture_image("photo", photo),
                                   node="ShaderNodeBsdfPrincipled")}
    plain = {ground: scenes.bsdf_material("GroundMean", "ShaderNodeBsdfDiffuse",
                                      Color=(*checker[..., :3].mean(axis=(0, 1)), 1.0)),
             suzanne: scenes.bsdf_material("StatueMean", "ShaderNodeBsdfPrincipled",
                                       **{"Base Color": (*photo[..., :3].mean(axis=(0, 1)),
                                                         1.0)})}
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(96, 72)
    scene = bpy.context.scene
    scene.prt.supersampling = 2
    errors = {}
    for kind, mats in (("textured", textured), ("plain", plain)):
        for ob, mat in mats.items():
            ob.data.materials.clear()
            ob.data.materials.append(mat)
        frames = {}
        for method in ("REFERENCE", "SSDF_SG"):
            scene.prt.method = method
            bpy.ops.prt.precompute()
            frames[method] = scenes.render_exr(tmp_path / f"{kind}_{method}.exr")
        assert frames["REFERENCE"][..., :3].max() > 0.0, "black reference"
        errors[kind] = rel_l2(frames["SSDF_SG"], frames["REFERENCE"])
    print("SSDF_SG vs REFERENCE", errors)
    assert errors["textured"] < errors["plain"] + 0.005, errors
    assert errors["plain"] < 0.04, errors


@pytest.mark.slow
def test_roughness_texture_on_a_glossy_sphere_against_cycles(tmp_path):
    """A metal sphere whose Roughness is a Non-Color checker (0.3 / 0.7) under 'forest',
    64x64, against Cycles direct light: SSDF_SG and the sun pass read it per pixel, the
    per-vertex methods per point (quantized variants); each against its error at the two
    constant roughnesses (per vertex: + the band along the checker's edges), and SSDF_SG's
    rough metal (constant 0.7, and the checker) within its measured bound."""
    scenes.reset()
    scenes.add_world("forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    sphere = bpy.context.object
    bpy.ops.object.shade_smooth()
    n = 8
    yy, xx = np.mgrid[0:n, 0:n]
    cells = np.ones((n, n, 4), np.float32)
    cells[..., :3] = np.where((xx + yy) % 2 == 1, 0.7, 0.3)[..., None]
    mat, bsdf = rough_principled("Rough", cells, Metallic=1.0,
                                  **{"Base Color": (0.9, 0.7, 0.5, 1.0)})
    sphere.data.materials.append(mat)
    scenes.add_camera(location=(0.0, -4.0, 1.0), rotation=(1.33, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 64)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    methods = ("REFERENCE", "SSDF_SG", "BLOCKS")

    def frames(tag):
        out = {"CYCLES": scenes.render_exr(tmp_path / f"cycles{tag}.exr", engine="CYCLES",
                                       samples=256)}
        for method in methods:
            scene.prt.method = method
            bpy.ops.prt.precompute()
            out[method] = scenes.render_exr(tmp_path / f"{method}{tag}.exr")
        return out

    def rel(pairs):
        num = sum(np.sum((f[..., :3] - t[..., :3]) ** 2 * (t[..., 3:] > 0.5)) for f, t in pairs)
        den = sum(np.sum(t[..., :3] ** 2 * (t[..., 3:] > 0.5)) for _, t in pairs)
        return float(np.sqrt(num / den))

    textured = frames("")
    mat.node_tree.links.remove(bsdf.inputs["Roughness"].links[0])
    constant = {}
    for v in (0.3, 0.7):
        bsdf.inputs["Roughness"].default_value = v
        constant[v] = frames(f"_{v}")
    errors = {m: (rel([(textured[m], textured["CYCLES"])]),
                  rel([(constant[v][m], constant[v]["CYCLES"]) for v in constant]))
              for m in methods}
    each = {v: rel([(constant[v]["SSDF_SG"], constant[v]["CYCLES"])]) for v in constant}
    print("roughness texture vs Cycles (textured, constant 0.3 and 0.7):", errors,
          "SSDF_SG at 0.3 / 0.7:", each)
    for m, (tex_err, const_err) in errors.items():
        # per vertex: a triangle-wide band along each cell edge (measured + 6.3 points);
        # SSDF_SG + 0.9 (four lobes, against 1024 spp: 4.32 % textured, 4.15 % the constant
        # frames composed by the checker, 4.09 % pooled: the rim's error falls on either)
        assert tex_err < const_err + (0.01 if m == "SSDF_SG" else 0.08), (m, errors)
    # SSDF_SG's GGX view slice as four fitted lobes (docs/measurements.md "SG lobes of a rough
    # metal", "Fitted warp of the GGX lobes", "Four fitted lobes of the GGX view slice"):
    # measured 6.1 % textured, 5.2 % pooled, 6.0 / 2.7 % at 0.3 / 0.7 (E against the open
    # hemisphere's visibility; without: 6.3, 5.6, 6.2 / 4.1 %; two fitted lobes 7.1, 7.2,
    # 7.7 / 6.2 %; plain warp 7.7, 7.8, 8.0 / 7.5 %; a Beckmann lobe 12.8, 13.9, 10.0 / 19.8 %);
    # Cycles' own noise at 256 spp is part of it (REFERENCE: 5.6 % pooled)
    assert errors["SSDF_SG"][0] < 0.07 and errors["SSDF_SG"][1] < 0.06, errors
    assert each[0.3] < 0.07 and each[0.7] < 0.035, each
