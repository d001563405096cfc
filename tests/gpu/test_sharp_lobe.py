"""The per-pixel sharp lobe (shaders/sharp_lobe_*.glsl, addon/gpu/sharp.py) against the
quadrature of the environment: a Glossy plane seen through an orthographic camera, every
pixel the lobe's integral."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sphere import envmap
from prt_relight.bench import scenes


pytestmark = pytest.mark.usefixtures("registered_addon")


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


def _bilinear(img, r):
    """The equirect bilinearly at world direction ``r`` (as Cycles' singular lobe reads it)."""
    u, vv = envmap.direction_to_equirect_uv(r)
    hh, ww, _ = img.shape
    x, y = u * ww - 0.5, vv * hh - 0.5
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0

    def px(yy, xx):
        return img[min(max(yy, 0), hh - 1), xx % ww].astype(np.float64)

    return ((px(y0, x0) * (1 - fx) + px(y0, x0 + 1) * fx) * (1 - fy)
            + (px(y0 + 1, x0) * (1 - fx) + px(y0 + 1, x0 + 1) * fx) * fy)


def _smooth_environment(height=256, width=512):
    """A gradient sky with a 6-degree bright blob: smooth next to the lobes tested."""
    dirs, _ = envmap.equirect_directions(height, width, 1)
    blob = np.array([0.0, math.sin(0.8), math.cos(0.8)])
    width6 = 1.0 - math.cos(math.radians(6.0))
    L = 1.0 + 0.5 * dirs[..., :1] + 20.0 * np.exp(-(1.0 - dirs @ blob) / width6)[..., None]
    return (L * np.array([1.0, 0.8, 0.6])).astype(np.float32)


def _ortho_mean(v, tilt):
    """The scene's plane seen along ``v`` (``tilt`` from the zenith) by an 8x8 orthographic
    camera, precomputed and drawn with its sharp lobe: the pixels' mean RGB."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.frame.state import FrameState
    cam = scenes.add_camera(location=tuple(6.0 * v), rotation=(tilt, 0.0, 0.0), resolution=None)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.0
    scenes.set_resolution(8, 8)
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
    return pixels[..., :3].reshape(-1, 3).mean(axis=0)


@pytest.mark.parametrize("roughness, tilt, tol", [(0.0, 0.6, 1e-3), (0.1, 0.5, 0.03),
                                                  (0.15, 0.8, 0.03), (0.15, 1.2, 0.03)])
def test_glsl_lobe_matches_quadrature_of_the_environment(roughness, tilt, tol):
    """A Glossy plane seen at ``tilt`` from the zenith through an orthographic camera:
    every pixel has the same normal and view, so each is the lobe integral over the
    equirect (numpy quadrature of core.shading.brdf; at roughness 0 the bilinear mirror
    reflection, as Cycles' singular lobe reads the texture)."""

    scenes.reset()
    img = _smooth_environment()
    scenes.add_world(image=scenes.float_image("env", img))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    plane.data.materials.append(scenes.bsdf_material("G", "ShaderNodeBsdfGlossy",
                                                 Roughness=roughness, distribution="GGX"))
    v = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    got = _ortho_mean(v, tilt)
    if roughness == 0.0:
        expected = 0.8 * _bilinear(img, np.array([0.0, math.sin(tilt), math.cos(tilt)]))
    else:
        material = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.8, 0.8),
                                 roughness=roughness, distribution="GGX")
        expected = _quadrature(img, material, np.array([0.0, 0.0, 1.0]), v)
    np.testing.assert_allclose(got, expected, rtol=tol)


def test_glsl_lobe_reads_a_roughness_image_per_pixel():
    """A Glossy plane whose Roughness image is 0.06 on its left half and 0.16 on its right
    (Closest; both below the sharp limit), seen as above at the blob's mirror direction:
    each half is the lobe integral at its own roughness (the pass drew both at the mean)."""
    from prt_relight.addon.frame.engine import render_pixels
    from prt_relight.addon.frame.state import FrameState

    scenes.reset()
    img = _smooth_environment()
    scenes.add_world(image=scenes.float_image("env", img))
    bpy.ops.mesh.primitive_plane_add(size=4.0)          # u = 0.5 + x / 4
    plane = bpy.context.object
    mat = scenes.bsdf_material("G", "ShaderNodeBsdfGlossy", distribution="GGX",
                               Color=(0.8, 0.8, 0.8, 1.0))
    glossy = next(n for n in mat.node_tree.nodes if n.type == "BSDF_GLOSSY")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = scenes.float_image("halves", np.array([[[0.06] * 3, [0.16] * 3]], np.float32))
    tex.interpolation = "Closest"
    mat.node_tree.links.new(tex.outputs["Color"], glossy.inputs["Roughness"])
    plane.data.materials.append(mat)
    tilt = 0.8
    v = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    cam = scenes.add_camera(location=tuple(6.0 * v), rotation=(tilt, 0.0, 0.0), resolution=None)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.0
    scenes.set_resolution(8, 8)
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()                      # gives the gpu module a context in -b
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = FrameState()
    state.sync(depsgraph)
    assert all(m.per_pixel_lobe for m in state.objects[0].materials)
    cam_eval = cam.evaluated_get(depsgraph)
    pixels = render_pixels(state, cam_eval.matrix_world.inverted(),
                           cam_eval.calc_matrix_camera(depsgraph, x=8, y=8), 8, 8, True, False)
    for columns, r in ((slice(0, 3), 0.06), (slice(5, 8), 0.16)):
        got = pixels[:, columns, :3].reshape(-1, 3).mean(axis=0)
        material = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(0.8, 0.8, 0.8),
                                      roughness=r, distribution="GGX")
        expected = _quadrature(img, material, np.array([0.0, 0.0, 1.0]), v)
        np.testing.assert_allclose(got, expected, rtol=0.03, err_msg=f"roughness {r}")


def test_glsl_lobe_of_a_bent_normal_reflects_above_the_triangle():
    """A plane whose custom normals lean 50 degrees from its face, seen at 70 degrees from
    the side they lean away from: the mirror direction of the bent normal points under the
    plane.  Cycles turns such a normal (ensure_valid_specular_reflection) until the
    reflection clears the triangle; the pass does the same, so each pixel is the lobe
    reflection of the view about the corrected normal (core.scene.textures.
    valid_reflection_normal), just above the plane."""
    from prt_relight.core.scene.textures import valid_reflection_normal

    scenes.reset()
    img = _smooth_environment()
    scenes.add_world(image=scenes.float_image("env", img))
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    bent = np.array([0.0, math.sin(math.radians(50.0)), math.cos(math.radians(50.0))])
    plane.data.shade_smooth()
    plane.data.normals_split_custom_set([tuple(bent)] * len(plane.data.loops))
    plane.data.materials.append(scenes.bsdf_material("G", "ShaderNodeBsdfGlossy",
                                                     Roughness=0.0, distribution="GGX"))
    tilt = math.radians(70.0)
    v = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    got = _ortho_mean(v, tilt)
    ng = np.array([0.0, 0.0, 1.0])
    mirror = 2.0 * (bent @ v) * bent - v
    assert mirror @ ng < 0.0                      # the uncorrected reflection is under the plane
    n = valid_reflection_normal(ng[None], v[None], bent[None])[0]
    r = 2.0 * (n @ v) * n - v
    assert 0.0 < r @ ng < 0.02                    # corrected: just above the plane
    np.testing.assert_allclose(got, 0.8 * _bilinear(img, r), rtol=1e-3)
