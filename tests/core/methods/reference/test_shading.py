# SPDX-License-Identifier: GPL-3.0-or-later
"""core.methods.reference.shading (Inger et al. 2013, eq. 1): the pixel-basis triple product
against explicit python loops over texels, uniform white worlds (albedo, half-blocked),
material slots and view directions, a fine hemisphere quadrature (white furnace), the
coarse-edge share and the point views.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.methods.reference import shading as reference
from ...scene.geometry import LAMBERT, N, shade, trace, unit, wall_triangles, white_world


def test_shade_lambert_uniform_white():
    cube = directions.cubemap(N)
    light = white_world()
    pts = np.zeros((2, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    bits_open, vis_open = trace(np.zeros((0, 3, 3)), pts, nrm)
    np.testing.assert_array_equal(vis_open[0], cube.directions[:, 2] > 0)
    out = shade(bits_open, pts, nrm, light, LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (2, 1)), atol=1e-3)
    irr = reference.diffuse_irradiance(bits_open, nrm, cube, light)
    np.testing.assert_allclose(irr, np.pi, rtol=1e-4)
    bits_wall, _ = trace(wall_triangles(), pts, nrm)
    out = shade(bits_wall, pts, nrm, light, LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (2, 1)) / 2, atol=5e-3)


def test_shade_lambert_uniform_white_random_normals():
    # Unoccluded, arbitrary normal: albedo to the horizon-straddling error (< 2e-3 * albedo/pi)
    rng = np.random.default_rng(4)
    nrm = unit(rng.normal(size=(20, 3)))
    pts = rng.normal(size=(20, 3))
    bits, _ = trace(np.zeros((0, 3, 3)), pts, nrm)
    out = shade(bits, pts, nrm, white_world(), LAMBERT)
    np.testing.assert_allclose(out, np.tile(LAMBERT.diffuse_albedo, (20, 1)), atol=1e-3)


# --------------------------------------------------------------------------- #
# reference vs brute force
# --------------------------------------------------------------------------- #

def brute_visible(tris, origin_base, offset, dirs):
    """Möller-Trumbore in float64 for each direction; also returns ambiguity margin."""
    tris = np.asarray(tris, float)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    vis = np.ones(len(dirs), bool)
    margin = np.full(len(dirs), np.inf)
    for k, d in enumerate(dirs):
        o = origin_base + offset * d
        pvec = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = o - v0
        u = np.einsum("ij,ij->i", tvec, pvec) * inv
        q = np.cross(tvec, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        m = np.minimum(np.minimum(u, v), 1.0 - u - v)
        front = ok & (t > 0)
        hit = front & (m >= 0)
        vis[k] = not hit.any()
        if front.any():
            margin[k] = np.abs(m[front]).min()
    return vis, margin


def _occluded_points(n=16):
    """Three ground points under a few random triangles, traced: (cube, triangles, points,
    normals, bits, visibility, ray offset, rng)."""
    cube = directions.cubemap(n)
    rng = np.random.default_rng(12)
    tris = rng.uniform(-0.8, 0.8, size=(5, 3, 3)) + [0, 0, 1.0]
    tris[:, :, 2] = np.abs(tris[:, :, 2]) + 0.2
    pts = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [-0.3, 0.25, 0.0]])
    nrm = unit(np.array([[0.0, 0.0, 1.0], [0.2, 0.1, 1.0], [-0.3, 0.0, 1.0]]))
    offset = 1e-4
    bits, vis = trace(tris, pts, nrm, n=n, offset=offset)
    return cube, tris, pts, nrm, bits, vis, offset, rng


def test_reference_matches_brute_force_loops():
    n = 16
    cube, tris, pts, nrm, bits, vis, offset, rng = _occluded_points(n)

    # visibility vs float64 brute force, ignoring texels grazing a triangle edge or the horizon
    for p in range(len(pts)):
        bv, margin = brute_visible(tris, pts[p] + offset * nrm[p], offset, cube.directions)
        bv &= (cube.directions @ nrm[p]) > 0
        # the hemisphere test is float32 (visibility.hemisphere_mask): skip the horizon
        sure = (margin > 1e-4) & (np.abs(cube.directions @ nrm[p]) > 1e-6)
        np.testing.assert_array_equal(vis[p][sure], bv[sure])
        assert sure.sum() > 0.98 * cube.size
    assert 0 < vis.sum() < (nrm @ cube.directions.T > 0).sum()   # some texels are blocked

    # random coloured environment
    img = rng.uniform(0.0, 3.0, size=(32, 64, 3)).astype(np.float32)
    img[5, 20] = 500.0                                              # a bright spot
    light = envmap.WorldLighting(img, strength=0.8).to_cubemap(n)
    mat = materials.Material(diffuse_albedo=(0.6, 0.3, 0.1), specular_color=(0.9, 0.7, 0.5),
                        roughness=0.3, distribution="BECKMANN")
    spec_only = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=mat.specular_color,
                              roughness=0.3, distribution="BECKMANN")
    eye = np.array([1.5, -2.0, 3.0])
    got = reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [mat], eye, cube,
                                 light)
    unit_dirs = light.unit_directions
    for p in range(len(pts)):
        view = unit(eye - pts[p])
        acc = np.zeros(3)
        for k in range(cube.size):
            if not vis[p, k]:
                continue
            L = light.radiance[k].astype(np.float64)
            cos_mean = max(0.0, float(nrm[p] @ light.directions[k]))
            diffuse = np.array(mat.diffuse_albedo) / np.pi * cos_mean
            spec = brdf.reflectance_cosine(spec_only, nrm[p][None], view[None],
                                           unit_dirs[k][None])[0, 0].astype(np.float64)
            acc += L * (diffuse + spec) * cube.solid_angles[k]
        np.testing.assert_allclose(got[p], acc, rtol=1e-4)
    assert np.all(got > 0)

    # diffuse-only material: shade = albedo/pi * diffuse_irradiance
    irr = reference.diffuse_irradiance(bits, nrm, cube, light)
    lam = reference.shade_points(bits, pts, nrm, np.zeros(len(pts), np.int64), [LAMBERT], eye,
                                 cube, light)
    np.testing.assert_allclose(lam, irr * np.array(LAMBERT.diffuse_albedo) / np.pi, rtol=1e-5)


def test_part_metal_principled_glossy_matches_brute_force_loops():
    """A Principled slot with metallic between 0 and 1 keeps both lobes (its metal and its
    dielectric terms share the bare lobe: summing one must not change the other)."""
    cube, _tris, pts, nrm, bits, vis, _offset, rng = _occluded_points()
    img = rng.uniform(0.0, 3.0, size=(32, 64, 3)).astype(np.float32)
    light = envmap.WorldLighting(img).to_cubemap(cube.resolution)
    mat = materials.principled_material(base_color=(0.8, 0.5, 0.3), metallic=0.3, roughness=0.4)
    eye = np.array([1.5, -2.0, 3.0])
    got = reference.specular_radiance(bits, pts, nrm, eye, cube, light, mat)
    for p in range(len(pts)):
        view = unit(eye - pts[p])
        f = brdf.specular_cosine(mat, nrm[p][None], view[None], light.unit_directions)[0]
        want = ((f * light.radiance) * (vis[p] * cube.solid_angles)[:, None]).sum(axis=0)
        np.testing.assert_allclose(got[p], want, rtol=1e-4)


def test_reference_material_slots_and_view_dirs():
    cube = directions.cubemap(N)
    pts = np.zeros((4, 3))
    nrm = np.tile([0, 0, 1.0], (4, 1))
    bits, _ = trace(np.zeros((0, 3, 3)), pts, nrm)
    light = white_world()
    m0 = materials.Material(diffuse_albedo=(0.2, 0.2, 0.2))
    m1 = materials.Material(diffuse_albedo=(0.9, 0.1, 0.4))
    out = reference.shade_points(bits, pts, nrm, np.array([0, 1, 0, 7]), [m0, m1],
                                 np.array([0, 0, 5.0]), cube, light)
    np.testing.assert_allclose(out[0], m0.diffuse_albedo, atol=1e-3)
    np.testing.assert_allclose(out[1], m1.diffuse_albedo, atol=1e-3)
    # a slot past the table is the last one (Cycles clamps the material index)
    np.testing.assert_allclose(out[3], m1.diffuse_albedo, atol=1e-3)
    # view_dirs overrides eye
    glossy = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=0.5)
    vd = np.tile([0.0, 0.0, 1.0], (4, 1))
    a = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [glossy],
                               np.array([100.0, 0, 0.01]), cube, light, view_dirs=vd)
    b = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [glossy],
                               np.array([0, 0, 5.0]), cube, light)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    # white furnace: the cubemap sum equals the lobe's directional albedo computed
    # with a fine equal-area hemisphere quadrature (independent directions)
    hd, hw = directions.hemisphere_uniform(512)
    for rough, view in [(0.5, [0.0, 0.0, 1.0]), (0.7, [0.6, 0.0, 0.8]), (0.7, [0.0, -0.96, 0.28])]:
        g = materials.Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=rough)
        albedo = (brdf.specular_cosine(g, nrm[:1], np.array([view]), hd)[0].astype(np.float64)
                  * hw).sum()
        got = reference.shade_points(bits, pts, nrm, np.zeros(4, np.int64), [g], None, cube,
                                     light, view_dirs=np.tile(view, (4, 1)))
        np.testing.assert_allclose(got, albedo, rtol=2e-3)


def test_coarse_edge_share_counts_edges_across_a_shadow_edge():
    """A 4 x 4 grid whose points at x < 0 see no sky and the others all of it: the edges
    that join the two halves jump by 1, the others by 0; counted by hand."""
    g = mesh.grid(2.0, 4)
    pts = mesh.shading_points(g)
    cube = directions.cubemap(8)
    open_bits = np.packbits(visibility.hemisphere_mask(pts.normals, cube), axis=1)
    bits = np.where((pts.positions[:, 0] < -1e-9)[:, None], 0, open_bits).astype(np.uint8)
    tri_points = pts.point_of_corner[g.triangles]
    shaded = pts.positions[:, 0] < -1e-9
    edges = np.concatenate([tri_points[:, [0, 1]], tri_points[:, [1, 2]], tri_points[:, [2, 0]]])
    want = float(np.mean(shaded[edges[:, 0]] != shaded[edges[:, 1]]))
    assert 0.0 < want < 1.0
    got = reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner, g.triangles, cube)
    assert got == pytest.approx(want)
    # a jump of exactly the whole sky is over any threshold below 1, none at 1
    assert reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner, g.triangles,
                                       cube, jump=1.0) == 0.0
    assert reference.coarse_edge_share(bits, pts.normals, pts.point_of_corner,
                                       np.zeros((0, 3), np.int64), cube) == 0.0


def test_point_views():
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]])
    np.testing.assert_allclose(reference.point_views(pos, eye=np.array([0.0, 0.0, 3.0])),
                               [[0.0, 0.0, 1.0], np.array([-1.0, -2.0, 1.0]) / np.sqrt(6.0)])
    ortho = reference.point_views(pos, eye=None, view_dir=np.array([0.0, 1.0, 0.0]))
    assert ortho.shape == (2, 3) and np.all(ortho == [0.0, 1.0, 0.0])


def test_bent_normals_and_open_sky_against_quadrature():
    """Open: the bent normal is the normal, the open sky 1.  The +x half of the sky
    blocked (a mask, no geometry): half the sky, and the bent normal along the clamped
    cosine's first moment over the -x half, (-2/3, 0, pi/3) by the integrals below."""
    cube = directions.cubemap(N)
    nrm = np.array([[0.0, 0.0, 1.0]] * 2)
    up = cube.directions[:, 2] > 0
    open_ = np.packbits(up)[None]
    half = np.packbits(up & (cube.directions[:, 0] < 0))[None]
    bits = np.concatenate([open_, half])
    bent = reference.bent_normals(bits, nrm, cube)
    sky = reference.sky_visibility(bits, nrm, cube)
    np.testing.assert_allclose(bent[0], (0.0, 0.0, 1.0), atol=1e-6)
    np.testing.assert_allclose(sky, (1.0, 0.5), atol=2e-3)
    # x: ∫cos φ dφ over the half (-2) times ∫cos θ sin² θ dθ (1/3); z: π ∫cos² θ sin θ dθ
    want = np.array([-2.0 / 3.0, 0.0, np.pi / 3.0])
    np.testing.assert_allclose(bent[1], want / np.linalg.norm(want), atol=5e-3)


def test_diffuse_irradiance_of_the_seen_points_only():
    """With a mask (core.scene.mesh.seen_points), the masked points get the sums of every
    point (the same dense sum on fewer rows) and the others 0."""
    rng = np.random.default_rng(5)
    nrm = unit(rng.normal(size=(40, 3)))
    pts = rng.normal(size=(40, 3))
    bits, _ = trace(wall_triangles(), pts, nrm)
    cube, light = directions.cubemap(N), white_world()
    seen = rng.random(40) < 0.5
    every = reference.diffuse_irradiance(bits, nrm, cube, light)
    some = reference.diffuse_irradiance(bits, nrm, cube, light, seen=seen)
    assert every[seen].min() > 0.0 and not some[~seen].any()
    np.testing.assert_allclose(some[seen], every[seen], rtol=1e-5, atol=1e-6)


def test_diffuse_irradiance_keeps_the_clamp_where_the_light_lies_off_centre():
    """The linear sum and its horizon correction equal the clamped sum texel by texel, with
    lights whose mean direction lies anywhere in its texel (a one-pixel sun near an edge),
    farther than the pairs' band (every point checked), opposite its centre or absent, and
    with bits set below a point's horizon (a turned object's posed bits)."""
    rng = np.random.default_rng(11)
    cube = directions.cubemap(8)
    k = cube.size
    nrm = unit(rng.normal(size=(300, 3)))
    bits = np.packbits(rng.random((300, k)) < 0.6, axis=1)
    # light directions: the centre tilted by up to a texel's size, a few far off centre
    tilt = rng.normal(size=(k, 3)) * rng.choice([0.01, 0.1, 0.3], size=(k, 1), p=[.6, .3, .1])
    dirs = unit(cube.directions + tilt) * rng.uniform(0.5, 1.0, size=(k, 1))
    dirs[:5] = -cube.directions[:5]
    dirs[5:9] = 0.0
    radiance = rng.uniform(0.0, 2.0, size=(k, 3)).astype(np.float32)
    light = envmap.CubeLighting(radiance, dirs.astype(np.float32))
    vis = visibility.unpack_visibility(bits, k).astype(np.float64)
    cos = np.maximum(nrm @ dirs.T, 0.0)
    want = (vis * cos) @ (radiance * cube.solid_angles[:, None])
    got = reference.diffuse_irradiance(bits, nrm, cube, light)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
    # the linear sum alone misses the clamp by far more than that
    linear = (vis * (nrm @ dirs.T)) @ (radiance * cube.solid_angles[:, None])
    assert np.abs(linear - want).max() > 1e-3 * want.max()
    # the pairs made once (cached by callers) give the same sums, on a subset too
    pairs = reference.horizon_pairs(bits, nrm, cube)
    seen = rng.random(300) < 0.5
    some = reference.diffuse_irradiance(bits, nrm, cube, light, seen=seen, pairs=pairs)
    np.testing.assert_allclose(some[seen], want[seen], rtol=1e-5, atol=1e-6 * want.max())
    assert not some[~seen].any()


def test_diffuse_irradiance_at_a_fine_cubemap():
    """At 6x128^2 (texel indices past 16 bits, a narrower band) the sums with the pairs
    equal the clamped texel loop too."""
    rng = np.random.default_rng(12)
    cube = directions.cubemap(128)
    nrm = unit(rng.normal(size=(40, 3)))
    vis = ((nrm @ cube.directions.T) > 0) & (rng.random((40, cube.size)) < 0.7)
    dirs = unit(cube.directions + rng.normal(size=(cube.size, 3)) * 0.004)
    radiance = rng.uniform(0.0, 2.0, size=(cube.size, 3)).astype(np.float32)
    light = envmap.CubeLighting(radiance, dirs.astype(np.float32))
    want = (vis * np.maximum(nrm @ dirs.T, 0.0)) @ (radiance * cube.solid_angles[:, None])
    pairs = reference.horizon_pairs(np.packbits(vis, axis=1), nrm, cube)
    assert pairs.texels.dtype == np.uint32 and len(pairs.texels) > 0
    got = reference.diffuse_irradiance(np.packbits(vis, axis=1), nrm, cube, light, pairs=pairs)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())
