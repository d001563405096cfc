"""REFERENCE's glossy GLSL pass (shaders/methods/reference_sums_frag.glsl) against
core.methods.reference.shading.specular_radiance in numpy."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.methods.reference import shading as reference

from ..core.methods.rsl.scenes import occluded_grid, sky_with_sun

bpy = pytest.importorskip("bpy")

from ..viewport import gpu_context  # noqa: E402

CUBE = directions.cubemap(32)

#: every Fresnel kind, both distributions, the multiscatter factor, a metal and a mix
MATERIALS = (
    materials.Material(),                                            # diffuse only: no glossy
    materials.principled_material(metallic=0.3, roughness=0.4),
    materials.principled_material(base_color=(0.9, 0.6, 0.2), metallic=1.0, roughness=0.25),
    materials.Material(specular_color=(0.9, 0.5, 0.2), roughness=0.3, distribution="BECKMANN",
                       fresnel="SCHLICK"),
    materials.Material(specular_color=(0.7, 0.7, 0.7), roughness=0.5, distribution="GGX"),
    materials.Material(specular_color=(0.8, 0.4, 0.3), roughness=0.35, distribution="MULTI_GGX",
                       fresnel="F82"),
)


@pytest.mark.slow
def test_glsl_glossy_sums_equal_numpy(registered_addon):
    from prt_relight.addon.methods.reference import gpu as method
    from prt_relight.addon.frame.engine import in_render
    gpu_context()
    pos, nrm, bits = occluded_grid(8)
    lighting = envmap.WorldLighting(image=sky_with_sun(),
                                    rotation=envmap.euler_xyz_matrix(0.1, 0.2, 0.7)
                                    ).to_cubemap(32)
    eye = np.array([2.0, -3.0, 2.0])
    views = reference.view_directions(pos, eye)
    point_mat = np.arange(len(nrm)) % len(MATERIALS)           # every material in one pass
    st = SimpleNamespace(name="grid", bits=bits)

    got = in_render(bpy.context.scene, lambda _d: method.specular_radiance(
        st, nrm, point_mat, list(MATERIALS), CUBE, lighting, views, ("test",)))
    want = np.zeros_like(got)
    for m, mat in enumerate(MATERIALS):
        sel = point_mat == m
        want[sel] = reference.specular_radiance(bits[sel], pos[sel], nrm[sel], eye, CUBE,
                                                lighting, mat, view_dirs=views[sel])
    assert np.isfinite(got).all()
    assert np.abs(want).max() > 0.0 and not want[point_mat == 0].any()
    # float32 sums in another order
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-4 * np.abs(want).max())


@pytest.mark.slow
def test_glsl_glossy_sums_with_a_signature_compiled_in_equal_numpy(registered_addon):
    """A pass over one material compiles its distribution, lobe count and Fresnel kinds in
    (core.shading.microfacet.lobe_signature): each kind and distribution alone, as numpy sums it."""
    from prt_relight.addon.methods.reference import gpu as method
    from prt_relight.addon.frame.engine import in_render
    gpu_context()
    pos, nrm, bits = occluded_grid(6)
    lighting = envmap.WorldLighting(image=sky_with_sun(),
                                    rotation=envmap.euler_xyz_matrix(0.3, 0.1, 1.7)
                                    ).to_cubemap(32)
    eye = np.array([-2.0, -3.0, 2.5])
    views = reference.view_directions(pos, eye)
    point_mat = np.zeros(len(nrm), np.int64)
    for k, mat in enumerate(MATERIALS[1:]):
        st = SimpleNamespace(name=f"one {k}", bits=bits)
        got = in_render(bpy.context.scene, lambda _d: method.specular_radiance(
            st, nrm, point_mat, [mat], CUBE, lighting, views, ("one", k)))
        want = reference.specular_radiance(bits, pos, nrm, eye, CUBE, lighting, mat,
                                           view_dirs=views)
        assert np.abs(want).max() > 0.0, k
        np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-4 * np.abs(want).max(),
                                   err_msg=str(k))


@pytest.mark.slow
def test_glsl_irradiance_equals_numpy(registered_addon):
    from prt_relight.addon.frame.engine import in_render
    from prt_relight.addon.methods.reference import gpu as method
    gpu_context()
    pos, nrm, bits = occluded_grid(8)
    rng = np.random.default_rng(5)
    nrm = nrm + 0.3 * rng.normal(size=nrm.shape)               # tilted: texels below horizons
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
    st = SimpleNamespace(name="grid", bits=bits)
    got = in_render(bpy.context.scene, lambda _d: method.irradiance(st, nrm, CUBE, lighting))
    want = reference.diffuse_irradiance(bits, nrm, CUBE, lighting)
    assert np.isfinite(got).all() and want.max() > 0.0
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6 * np.abs(want).max())


def test_glsl_sums_drawn_a_block_of_rows_at_a_time(registered_addon, monkeypatch):
    """Points drawn in several draws (one row of 4x4 blocks each here) give the one draw's
    sums: each draw reads its own rows of the points; the environment's texels read from
    rows of another width give the same sums."""
    from prt_relight.addon.frame.engine import in_render
    from prt_relight.addon.methods.reference import gpu as method
    gpu_context()
    pos, nrm, bits = occluded_grid(8)
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
    views = reference.view_directions(pos, np.array([2.0, -3.0, 2.0]))
    mats = [MATERIALS[1]]
    point_mat = np.zeros(len(nrm), np.int64)

    def sums(_d, key):
        st = SimpleNamespace(name="grid", bits=bits)
        return (method.specular_radiance(st, nrm, point_mat, mats, CUBE, lighting, views, key),
                method.irradiance(st, nrm, CUBE, lighting))

    whole = in_render(bpy.context.scene, lambda d: sums(d, ("whole",)))
    monkeypatch.setattr(method, "WIDTH", 16)    # 81 points: eight rows of 16, two draws
    monkeypatch.setattr(method, "CHUNK_ROWS", 4)
    monkeypatch.setattr(method, "ENV_WIDTH", 256)     # the texels in 24 rows, not 6
    rows = in_render(bpy.context.scene, lambda d: sums(d, ("rows",)))
    for a, b in zip(whole, rows):
        assert np.abs(a).max() > 0.0
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-7 * np.abs(a).max())


def test_glsl_sums_of_the_seen_points_only(registered_addon):
    """With a mask of the points the camera may see, those points get the sums of the whole
    pass (each reads its own visibility row) and the others 0."""
    from prt_relight.addon.frame.engine import in_render
    from prt_relight.addon.methods.reference import gpu as method
    gpu_context()
    pos, nrm, bits = occluded_grid(8)
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
    views = reference.view_directions(pos, np.array([2.0, -3.0, 2.0]))
    point_mat = np.arange(len(nrm)) % len(MATERIALS)
    seen = np.random.default_rng(2).random(len(nrm)) < 0.4
    st = SimpleNamespace(name="grid", bits=bits)

    def sums(_d, key, mask):
        return method.specular_radiance(st, nrm, point_mat, list(MATERIALS), CUBE, lighting,
                                        views, key, mask)
    whole = in_render(bpy.context.scene, lambda d: sums(d, ("all",), None))
    some = in_render(bpy.context.scene, lambda d: sums(d, ("seen",), seen))
    assert np.abs(whole[seen]).max() > 0.0 and not some[~seen].any()
    # one shader on the same inputs: equal up to how a driver orders float work
    np.testing.assert_allclose(some[seen], whole[seen], rtol=1e-4,
                               atol=1e-6 * np.abs(whole).max())


def test_points_fill_four_by_four_blocks_the_shader_reads_back():
    """tiled_pixels puts each point on its own pixel, 16 consecutive points in one 4x4 block,
    and reference_sums_frag.glsl's point_of (written out here) reads each pixel's point back;
    the rows are whole blocks."""
    from prt_relight.addon.methods.reference import gpu as method
    for count, width in ((1, 16), (81, 16), (5000, 1024)):
        pix, rows = method.tiled_pixels(count, width)
        assert rows % 4 == 0 and rows * width >= count
        assert len(np.unique(pix)) == count and pix.max() < rows * width
        x, y = pix % width, pix // width
        back = 16 * ((y >> 2) * (width >> 2) + (x >> 2)) + 4 * (y & 3) + (x & 3)
        np.testing.assert_array_equal(back, np.arange(count))
        block = (y // 4) * (width // 4) + x // 4
        assert np.all(block == np.arange(count) // 16)
