"""Glossy lobes too narrow for the cubemap (mirrors, low roughness): skipped per vertex,
drawn per pixel for every method (core.shading.brdf.is_sharp, addon/gpu/sharp.py)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sphere import envmap

from . import blender_scene as bs

pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET", "AUTO"]


# --------------------------------------------------------------------------- core


# --------------------------------------------------------------------------- GLSL vs quadrature

def _quadrature(img, material, normal, view):
    """sum over the equirect's pixels of L f cos dw (every direction visible)."""
    h, w, _ = img.shape
    dirs, sa = envmap.equirect_directions(h, w, 2)
    px = np.repeat(np.repeat(img, 2, axis=0), 2, axis=1).reshape(-1, 3).astype(np.float64)
    d = dirs.reshape(-1, 3)
    up = d @ normal > 0.0
    f = brdf.reflectance_cosine(material, normal[None], view[None], d[up])[0]    # (D, 3)
    return (f * px[up] * sa.reshape(-1)[up][:, None]).sum(axis=0)


def _smooth_environment(height=256, width=512):
    """A gradient sky with a 6-degree bright blob: smooth next to the lobes tested."""
    dirs, _ = envmap.equirect_directions(height, width, 1)
    blob = np.array([0.0, math.sin(0.8), math.cos(0.8)])
    width6 = 1.0 - math.cos(math.radians(6.0))
    L = 1.0 + 0.5 * dirs[..., :1] + 20.0 * np.exp(-(1.0 - dirs @ blob) / width6)[..., None]
    return (L * np.array([1.0, 0.8, 0.6])).astype(np.float32)


@pytest.mark.parametrize("roughness, tilt, tol", [(0.0, 0.6, 1e-3), (0.1, 0.5, 0.03),
                                                  (0.15, 0.8, 0.03), (0.15, 1.2, 0.03)])
def test_glsl_lobe_matches_quadrature_of_the_environment(roughness, tilt, tol):
    """A Glossy plane seen at ``tilt`` from the zenith through an orthographic camera:
    every pixel has the same normal and view, so each is the lobe integral over the
    equirect (numpy quadrature of core.shading.brdf; at roughness 0 the bilinear mirror
    reflection, as Cycles' singular lobe reads the texture)."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.frame.state import FrameState

    bs.reset()
    img = _smooth_environment()
    bs.add_world(image=bs.float_image("env", img))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    plane.data.materials.append(bs.bsdf_material("G", "ShaderNodeBsdfGlossy",
                                                 Roughness=roughness, distribution="GGX"))
    v = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    cam = bs.add_camera(location=tuple(6.0 * v), rotation=(tilt, 0.0, 0.0))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.0
    bs.set_resolution(8, 8)
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()                      # gives the gpu module a context in -b
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = FrameState()
    state.sync(depsgraph)
    assert state.objects[0].materials[0].per_pixel_lobe
    cam_eval = cam.evaluated_get(depsgraph)
    pixels = render_pixels(state, cam_eval.matrix_world.inverted(),
                           cam_eval.calc_matrix_camera(depsgraph, x=8, y=8), 8, 8, True, False)
    got = pixels[..., :3].reshape(-1, 3).mean(axis=0)
    if roughness == 0.0:
        r = np.array([0.0, math.sin(tilt), math.cos(tilt)])
        u, vv = envmap.direction_to_equirect_uv(r)
        hh, ww, _ = img.shape
        x, y = u * ww - 0.5, vv * hh - 0.5
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0

        def px(yy, xx):
            return img[min(max(yy, 0), hh - 1), xx % ww].astype(np.float64)

        expected = 0.8 * ((px(y0, x0) * (1 - fx) + px(y0, x0 + 1) * fx) * (1 - fy)
                          + (px(y0 + 1, x0) * (1 - fx) + px(y0 + 1, x0 + 1) * fx) * fy)
    else:
        material = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.8, 0.8),
                                 roughness=roughness, distribution="GGX")
        expected = _quadrature(img, material, np.array([0.0, 0.0, 1.0]), v)
    np.testing.assert_allclose(got, expected, rtol=tol)


# --------------------------------------------------------------------------- scenes

def _mirror_ball(kind="glossy", roughness=0.0, hdri="courtyard", size=(64, 48), ground=True):
    bs.reset()
    bs.add_world(path=bs.hdri_path(hdri))
    if ground:
        bs.add_ground(size=6.0, cuts=24)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 1.0), radius=0.8, segments=48,
                                         ring_count=24)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    if kind == "glossy":
        mat = bs.bsdf_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=roughness)
    else:
        mat = bs.bsdf_material("Metal", "ShaderNodeBsdfPrincipled", Roughness=roughness,
                               Metallic=1.0)
    ball.data.materials.append(mat)
    bs.add_camera(location=(0.0, -5.0, 2.2), rotation=(1.3, 0.0, 0.0))
    bs.set_resolution(*size)
    return ball


def test_every_method_draws_the_mirror_ball_alike(tmp_path):
    """The ball is a pure Glossy BSDF at roughness 0: no Lambert base, so every method's
    pixels are the per-pixel lobe alone (and none is negative or blotchy)."""
    _mirror_ball(size=(48, 36), ground=False)
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.render.filter_size = 0.0
    frames = {}
    for method in METHODS:
        scene.prt.method = method
        frames[method] = bs.render_exr(tmp_path / f"{method}.exr")
    ref = frames["REFERENCE"]
    ball = ref[..., 3] > 0.5
    for method, frame in frames.items():
        assert np.isfinite(frame).all() and frame.min() >= 0.0, method
    bright = ref[..., :3].max(axis=-1) > 0.05
    assert (ball & bright).sum() > 50                       # the sky is reflected, not black
    for method, frame in frames.items():
        sel = ball & bright
        np.testing.assert_allclose(frame[sel], ref[sel], rtol=2e-4, atol=1e-5, err_msg=method)


@pytest.mark.slow
@pytest.mark.parametrize("kind, limit", [("glossy", 0.08), ("metal", 0.09)])
def test_mirror_ball_matches_cycles(tmp_path, kind, limit):
    """Glossy and Principled metallic at roughness 0 reflect the environment as Cycles
    does (they rendered black with a few white blobs, 1.8 rel-L2 off)."""
    _mirror_ball(kind)
    bpy.context.scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    ours = bs.render_exr(tmp_path / "ours.exr")
    truth = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=256)
    assert bs.rel_l2(ours, truth) < limit


@pytest.mark.slow
def test_smooth_shaded_sharp_edged_part_under_studio_matches_cycles(tmp_path):
    """Issue 15: a Glossy (Beckmann 0.15) 24-segment cylinder shaded smooth, caps and
    all (sharp edges with interpolated normals), standing on a ground under 'studio'.
    Its bottom ring's normals point 43 degrees into the ground; its visibility was traced
    from under it and mixed up the side, so the softboxes' rim highlights came out 24 %
    dark (22.8 % rel-L2 for every method; core.scene.visibility.contact_origins)."""
    bs.reset()
    bs.add_world(path=bs.hdri_path("studio"), rotation_z=2.2)
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=0.8, depth=1.2,
                                        location=(0.0, 0.0, 0.6))
    part = bpy.context.object
    bpy.ops.object.shade_smooth()
    part.data.materials.append(bs.bsdf_material("G", "ShaderNodeBsdfGlossy", Roughness=0.15,
                                                distribution="BECKMANN"))
    bs.add_ground(size=5.0, cuts=16)
    bs.add_camera(location=(0.0, -4.5, 3.0), rotation=(1.0, 0.0, 0.0))
    bs.set_resolution(80, 60)
    scene = bpy.context.scene
    scene.prt.supersampling = 3
    bpy.ops.prt.precompute()
    truth = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=2048)
    for method in ("REFERENCE", "SSDF_SG"):
        scene.prt.method = method
        ours = bs.render_exr(tmp_path / f"{method}.exr")
        # 3.9 % now; the brightest highlight within 5 % (75 / 87 / 98 against 77 / 89 / 100)
        assert bs.rel_l2(ours, truth) < 0.05, method
        top = np.unravel_index(truth[..., 1].argmax(), truth.shape[:2])
        np.testing.assert_allclose(ours[top][:3], truth[top][:3], rtol=0.05, err_msg=method)
