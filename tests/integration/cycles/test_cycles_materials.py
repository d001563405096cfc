"""REFERENCE against Cycles (max_bounces 0) for Cycles' own BSDF models: slow.

What is checked (forest HDRI, Cycles 1024 spp, our F12):

* A ground grid with **no material**.  Cycles' default surface is a Principled
  BSDF with the node defaults (``intern/cycles/scene/shader.cpp``
  ``ShaderManager::add_default``), not Lambert 0.8: its dielectric layer takes
  a view-dependent share from the base (``closure_layering_weight``), so a
  Lambert 0.8 is ~4 % too bright at the default oblique camera.
* An explicit Principled BSDF (metallic 0, roughness 0.3).
* A Glossy BSDF with Multiscatter GGX, roughness 0.4, on a sphere.

Thresholds (measured when written, Cycles seed 0):

========================  =============  =============  ===============
case                      mean (after)   rel-L2 (after)  before (mean/L2)
========================  =============  =============  ===============
no material, oblique      -0.3 %         2.0 %           +4.1 % / 4.7 %
no material, from above   -0.1 %         0.6 %           -0.9 % / 1.6 %
Principled r=0.3, oblique -0.3 %         2.0 %           +0.6 % / 3.5 %
Principled r=0.3, above   -0.1 %         0.7 %           -4.6 % / 4.7 %
Glossy MULTI_GGX sphere   +0.2 %         2.2 %           -3.9 % / 4.5 %
========================  =============  =============  ===============

"before" is Lambert 0.8 / the old Schlick approximation / single-scatter GGX.
The oblique rel-L2 is Cycles' per-pixel noise: averaging the difference over
4 x 4 pixel blocks leaves 0.2 %.  The sphere adds per-vertex tessellation
error of the glossy reflection (128 x 64 UV sphere; 2.8 % at 96 x 48, 5.7 % at
64 x 32), hence its 3.5 % bound.  Means are over pixels Cycles covers.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes
from prt_relight.core.report.metrics import rel_l2


pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("registered_addon")]


ABOVE = dict(location=(0.0, 0.0, 6.0), rotation=(0.0, 0.0, 0.0))


def _ground_scene(camera=None, roughness=None):
    """Ground grid under the forest HDRI; Principled of ``roughness`` or no material."""
    scenes.reset()
    scenes.add_world("forest")
    ground = scenes.add_ground(size=6.0, cuts=48)
    if roughness is not None:
        ground.data.materials.append(_principled(roughness))
    scenes.add_camera(**{'location': (0.0, -6.0, 3.0), 'rotation': (1.15, 0.0, 0.0), 'resolution': None, **(camera or {})})       # default: 66 deg from the ground normal
    scenes.set_resolution(64, 48)
    return ground


def _principled(roughness):
    mat = bpy.data.materials.new("principled")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Metallic"].default_value = 0.0
    p.inputs["Roughness"].default_value = roughness
    return mat


def _compare(tmp_path, samples=1024):
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ours = scenes.render_exr(tmp_path / "prt.exr")
    cycles = scenes.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=samples)
    assert cycles[..., :3].max() > 0.0, "black reference"  # (rel_l2 would be the norm of ours)
    m = cycles[..., 3] > 0.5
    assert m.sum() > 500
    mean = float(ours[m][:, :3].mean() / cycles[m][:, :3].mean() - 1.0)
    err = rel_l2(ours, cycles)
    print(f"mean {mean:+.4f}  rel-L2 {err:.4f}")
    return mean, err


def test_no_material_oblique_is_cycles_default_principled(tmp_path):
    _ground_scene()
    mean, err = _compare(tmp_path)
    assert abs(mean) < 0.01, mean          # Lambert 0.8 was +4.1 %
    assert err < 0.03, err


def test_no_material_from_above(tmp_path):
    _ground_scene(camera=ABOVE)
    mean, err = _compare(tmp_path)
    assert abs(mean) < 0.005, mean         # Lambert 0.8 was -0.9 %
    assert err < 0.012, err                # Lambert 0.8 was 1.6 %


@pytest.mark.parametrize("camera,mean_tol,l2_tol", [(None, 0.01, 0.028), (ABOVE, 0.005, 0.012)],
                         ids=["oblique", "above"])
def test_principled_roughness_03(tmp_path, camera, mean_tol, l2_tol):
    _ground_scene(camera=camera, roughness=0.3)
    mean, err = _compare(tmp_path)
    assert abs(mean) < mean_tol, mean      # old Schlick mapping: +0.6 % / -4.6 %
    assert err < l2_tol, err               # old: 3.5 % / 4.7 %


def test_glossy_multiscatter_sphere(tmp_path):
    scenes.reset()
    scenes.add_world("forest")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0)
    bpy.ops.object.shade_smooth()
    sphere = bpy.context.object
    sphere.data.materials.append(scenes.bsdf_material("glossy", "ShaderNodeBsdfGlossy",
                                                  distribution="MULTI_GGX", Roughness=0.4))
    scenes.add_camera(location=(0.0, -4.0, 0.0), rotation=(np.pi / 2, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    mean, err = _compare(tmp_path)
    assert abs(mean) < 0.01, mean          # single-scatter GGX was -3.9 %
    assert err < 0.035, err                # single-scatter GGX was 4.5 %
