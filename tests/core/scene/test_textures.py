"""core.scene.textures: sampling as Blender's Image Texture node (texel centres, extension
modes, the cubic B-spline), the Mapping transform and Mix, scalar inputs per point, and the
Normal Map and Bump nodes' perturbed normal (NormalSource) against the frame rotation and
the displaced surface, with Cycles' bump-map correction and terminator factor.  No bpy."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from prt_relight.core.scene import textures


# --------------------------------------------------------------------------- core

def _tex(pixels, **kw):
    return textures.ImageTexture(np.asarray(pixels, np.float32), **kw)


def test_sampling_hits_texel_centres_and_interpolates_between():
    px = np.zeros((2, 4, 4), np.float32)
    px[..., 0] = np.arange(4)[None, :]          # red = column index
    px[..., 1] = np.arange(2)[:, None]          # green = row index (row 0 at v = 0)
    tex = _tex(px, extension="EXTEND")
    centres = np.array([[(i + 0.5) / 4, (j + 0.5) / 2] for j in range(2) for i in range(4)])
    got = textures.sample(tex, centres)
    np.testing.assert_allclose(got[:, 0], np.tile(np.arange(4), 2), atol=1e-12)
    np.testing.assert_allclose(got[:, 1], np.repeat(np.arange(2), 4), atol=1e-12)
    mid = textures.sample(tex, [[0.5, 0.5]])           # between columns 1 and 2, rows 0/1
    np.testing.assert_allclose(mid[0, :2], [1.5, 0.5], atol=1e-12)
    closest = textures.sample(_tex(px, interpolation="CLOSEST", extension="EXTEND"),
                              [[0.30, 0.8]])
    np.testing.assert_allclose(closest[0, :2], [1.0, 1.0])


def test_extension_modes():
    px = np.zeros((1, 4, 4), np.float32)
    px[0, :, 0] = [1.0, 2.0, 3.0, 4.0]
    uv = np.array([[1.125, 0.5], [-0.125, 0.5]])        # a quarter texel past each edge
    rep = textures.sample(_tex(px, extension="REPEAT", interpolation="CLOSEST"), uv)[:, 0]
    ext = textures.sample(_tex(px, extension="EXTEND", interpolation="CLOSEST"), uv)[:, 0]
    mir = textures.sample(_tex(px, extension="MIRROR", interpolation="CLOSEST"), uv)[:, 0]
    clip = textures.sample(_tex(px, extension="CLIP"), uv)[:, 0]
    np.testing.assert_array_equal(rep, [1.0, 4.0])
    np.testing.assert_array_equal(ext, [4.0, 1.0])
    np.testing.assert_array_equal(mir, [4.0, 1.0])
    np.testing.assert_array_equal(clip, [0.0, 0.0])


def test_cubic_b_spline_keeps_constants_and_linear_ramps():
    const = _tex(np.full((8, 8, 4), 0.3, np.float32), interpolation="CUBIC")
    uv = np.random.default_rng(1).random((50, 2))
    np.testing.assert_allclose(textures.sample(const, uv), 0.3, atol=1e-12)
    ramp = np.zeros((1, 16, 4), np.float32)
    ramp[0, :, 0] = np.arange(16)
    tex = _tex(ramp, interpolation="CUBIC", extension="EXTEND")
    x = np.linspace(0.2, 0.8, 7)                       # away from the clamped ends
    got = textures.sample(tex, np.stack([x, np.full(7, 0.5)], axis=1))[:, 0]
    np.testing.assert_allclose(got, x * 16 - 0.5, atol=1e-9)   # B-splines reproduce lines


def test_mapping_transform_and_mix():
    px = np.zeros((1, 2, 4), np.float32)
    px[0, 1, 0] = 1.0
    shifted = _tex(px, interpolation="CLOSEST", transform=[[1.0, 0.0, 0.5], [0.0, 1.0, 0.0]])
    assert textures.sample(shifted, [[0.1, 0.5]])[0, 0] == 1.0      # 0.1 + 0.5 -> column 1
    src = textures.ColorSource(mix=("MULTIPLY", 0.5, (0.2, 0.4, 1.0), True))
    np.testing.assert_allclose(src.combine([1.0, 1.0, 1.0]), [0.6, 0.7, 1.0])
    src = textures.ColorSource(mix=("MIX", 0.25, (0.0, 0.0, 0.0), False))
    np.testing.assert_allclose(src.combine([1.0, 0.5, 0.0]), [0.25, 0.125, 0.0])


def test_scalar_inputs_per_point_and_their_variants():
    """A scalar input is the colour's luminance, clamped; a point's value is the mean of its
    corners'; variants quantize within half a step and rebuild the material at the values."""
    from types import SimpleNamespace
    from prt_relight.core.shading import materials
    grey = _tex(np.array([[[0.2, 0.2, 0.2, 1.0], [2.0, 0.0, 0.0, 1.0]]], np.float32),
                interpolation="CLOSEST", extension="EXTEND")
    rough = textures.ScalarSource(textures.ColorSource(texture=grey), "Roughness")
    uv = np.array([[0.1, 0.5], [0.9, 0.5], [0.1, 0.5], [0.9, 0.5]])
    got = textures.point_values(rough, uv, np.array([0, 0, 1, 2]), 3)
    np.testing.assert_allclose(got, [(0.2 + 2.0 * 0.2126) / 2, 0.2, 2.0 * 0.2126])
    rng = np.random.default_rng(3)
    values = rng.random(200)
    grid, idx = textures.quantize(values, 9)
    assert np.abs(grid[idx] - values).max() <= 0.5 * (grid[1] - grid[0]) + 1e-12
    base = materials.principled_material(base_color=(0.5, 0.4, 0.3), roughness=0.5)
    points = SimpleNamespace(materials=np.zeros(200, np.int64))
    mats, point_mat, slot_of = textures.point_variants(
        [base], points, {0: {"Roughness": values}}, {}, levels=9)
    assert len(mats) == 1 + len(np.unique(idx)) and set(slot_of[1:]) == {0}
    np.testing.assert_allclose([mats[k].roughness for k in point_mat], grid[idx])
    constants = {"IOR": 1.45, "Specular Tint": (1.0, 1.0, 1.0), "distribution": "MULTI_GGX"}
    level = textures.material_at(base, {"Specular IOR Level": 0.25}, constants)
    ref = materials.principled_material(base_color=(0.5, 0.4, 0.3), roughness=0.5, ior=1.45,
                                   specular_ior_level=0.25)
    assert level == ref


def _frame(seed=0):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q[:, 0], q[:, 1], np.cross(q[:, 0], q[:, 1])


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def test_tangent_space_decode_is_the_frame_rotation():
    T, B, N = _frame(1)
    rng = np.random.default_rng(2)
    local = rng.normal(size=(200, 3))
    local[:, 2] = np.abs(local[:, 2]) + 0.2
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    colour = 0.5 * (local + 1.0)
    for sign in (1.0, -1.0):
        # B = sign N x T: with sign -1 the map's green axis is -B
        want = local[:, :1] * T + local[:, 1:2] * (sign * B) + local[:, 2:3] * N
        got = textures.tangent_space_normals(colour, N, T, np.full(200, sign))
        assert np.max(_angle(got, want)) < 1e-4
    flat = textures.tangent_space_normals(colour, N, T, np.ones(200), strength=0.0)
    assert np.max(_angle(flat, N[None])) < 1e-4
    half = textures.tangent_space_normals(colour, N, T, np.ones(200), strength=0.5)
    n1 = textures.tangent_space_normals(colour, N, T, np.ones(200))
    want = (N + 0.5 * (n1 - N)) / np.linalg.norm(N + 0.5 * (n1 - N), axis=1, keepdims=True)
    assert np.max(_angle(half, want)) < 1e-4


def _height_field(u, v, amp=1.0):
    h = amp * np.sin(2 * np.pi * 2 * u) * np.cos(2 * np.pi * 3 * v)
    hu = amp * 2 * np.pi * 2 * np.cos(2 * np.pi * 2 * u) * np.cos(2 * np.pi * 3 * v)
    hv = -amp * 2 * np.pi * 3 * np.sin(2 * np.pi * 2 * u) * np.sin(2 * np.pi * 3 * v)
    return h, hu, hv


def _height_texture(res, interpolation="LINEAR"):
    c = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(c, c)                     # row j at v = c[j]
    h = _height_field(u, v)[0]
    px = np.ones((res, res, 4), np.float32)
    px[..., :3] = h[..., None]                   # grey: luminance = h
    return textures.ColorSource(texture=textures.ImageTexture(px, interpolation=interpolation))


def _bump_case(res, distance, strength=1.0, n=400, seed=3):
    """Our bump normal and the displaced plane's normal by finite differences."""
    e1, e2, N = _frame(seed)
    su, sv = 2.0, 0.7                            # world length per unit u, v
    rng = np.random.default_rng(seed)
    uv = rng.random((n, 2))
    src = textures.NormalSource("BUMP", _height_texture(res), strength, distance)
    # a triangle's edges: not orthogonal in UV, any basis of the plane does
    duv = np.array([[0.01, 0.002], [-0.003, 0.012]])
    dp = duv[:, :1] * su * e1 + duv[:, 1:] * sv * e2
    got = textures.perturbed_normals(src, uv, np.tile(N, (n, 1)),
                                     dp=np.broadcast_to(dp, (n, 2, 3)),
                                     duv=np.broadcast_to(duv, (n, 2, 2)))

    def surface(u, v):                           # the plane displaced by d h along N
        return (u * su)[:, None] * e1 + (v * sv)[:, None] * e2 + \
            (distance * _height_field(u, v)[0])[:, None] * N
    eps = 1e-6
    u, v = uv[:, 0], uv[:, 1]
    pu = (surface(u + eps, v) - surface(u - eps, v)) / (2 * eps)
    pv = (surface(u, v + eps) - surface(u, v - eps)) / (2 * eps)
    brute = np.cross(pu, pv)
    brute /= np.linalg.norm(brute, axis=1, keepdims=True)
    if strength != 1.0:
        brute = strength * brute + (1 - strength) * N
        brute /= np.linalg.norm(brute, axis=1, keepdims=True)
    return got, brute, N


@pytest.mark.parametrize("res,bound", [(64, 1.0), (256, 0.07), (1024, 0.005)])
def test_bump_against_the_displaced_surface(res, bound):
    """UV-space central differences of the bilinear texture against the exact normal of
    the displaced plane (it equals Cycles' bump of the exact height on a plane)."""
    got, brute, N = _bump_case(res, distance=0.05)
    err = _angle(got, brute)
    tilt = _angle(brute, N[None])
    print(f"{res}²: max {err.max():.3f}°, mean {err.mean():.4f}° "
          f"(tilt up to {tilt.max():.1f}°)")
    assert tilt.max() > 20.0                     # the bumps are not negligible
    assert err.max() < bound


def test_bump_strength_inversion_and_flat_height():
    got, brute, N = _bump_case(512, distance=0.05, strength=0.4)
    assert np.max(_angle(got, brute)) < 0.2
    up, _, _ = _bump_case(512, distance=0.05)
    down, _, _ = _bump_case(512, distance=-0.05)     # inverted: mirrored about N
    mirrored = 2 * (up @ N)[:, None] * N - up
    assert np.max(_angle(down, mirrored)) < 1e-4
    flat = textures.ColorSource(texture=textures.ImageTexture(np.full((8, 8, 4), 0.3,
                                                                      np.float32)))
    e1, e2, N = _frame(5)
    n = textures.perturbed_normals(textures.NormalSource("BUMP", flat), np.random.rand(9, 2),
                                   np.tile(N, (9, 1)), dp=np.broadcast_to(np.stack([e1, e2]),
                                                                          (9, 2, 3)),
                                   duv=np.broadcast_to(np.eye(2), (9, 2, 2)))
    assert np.max(_angle(n, N[None])) < 1e-9


def test_bump_map_correction_is_the_least_turn_that_lifts_the_reflection():
    """Against a scan of normals in the plane of (ng, n): the steepest one whose mirror
    reflection of the view is at the threshold above the surface."""
    rng = np.random.default_rng(7)
    ng = np.array([0.0, 0.0, 1.0])
    checked = 0
    for _ in range(200):
        o = rng.normal(size=3)
        o[2] = abs(o[2]) + 0.05
        o /= np.linalg.norm(o)
        n = rng.normal(size=3)
        n[2] = abs(n[2])
        n /= np.linalg.norm(n)
        got = textures.valid_reflection_normal(ng[None], o[None], n[None])[0]
        r = 2 * (n @ o) * n - o
        t = min(0.9 * o[2], 0.01)
        if r[2] >= t:
            assert np.allclose(got, n)
            continue
        checked += 1
        x = n - n[2] * ng
        x /= np.linalg.norm(x)
        tilt = np.linspace(0.0, np.arccos(n[2]), 20001)
        cand = np.sin(tilt)[:, None] * x + np.cos(tilt)[:, None] * ng
        lift = (2 * (cand @ o)[:, None] * cand - o)[:, 2]
        best = cand[np.nonzero(lift >= t)[0].max()]
        assert np.degrees(np.arccos(min(got @ best, 1.0))) < 0.05
        assert (2 * (got @ o) * got - o)[2] == pytest.approx(t, abs=1e-6)
    assert checked > 30


_THETA = (np.arange(2000) + 0.5) / 2000 * (np.pi / 2)
_PHI = (np.arange(360) + 0.5) / 360 * (2 * np.pi)


@functools.lru_cache(maxsize=None)
def _ggx_microfacets(alpha):
    """The microfacet normals of a 2000 x 360 midpoint grid over the hemisphere and
    D(m) dm of GGX there (made once per alpha; every light direction reuses them)."""
    t, p = np.meshgrid(_THETA, _PHI, indexing="ij")
    m = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    a2 = alpha * alpha
    D = a2 / (np.pi * np.cos(t) ** 4 * (a2 + np.tan(t) ** 2) ** 2)
    d_dm = D * np.sin(t) * (np.pi / 2 / 2000) * (2 * np.pi / 360)
    assert np.sum(d_dm * np.cos(t)) == pytest.approx(1.0, abs=2e-3)
    return m, d_dm


def _ggx_g1_by_quadrature(alpha, i):
    """Smith G1 of GGX (Heitz 2014: the visible projected area of the microfacets is the
    macro surface's): cos(i) / integral of D(m) max(0, m.i) over the hemisphere."""
    m, d_dm = _ggx_microfacets(alpha)
    return i[2] / np.sum(d_dm * np.maximum(m @ i, 0.0))


def test_terminator_factor_is_the_masking_of_a_bump_roughness():
    """Conty Estevez et al. 2019 as Cycles 5.0 applies it to a diffuse closure: GGX's G1 of
    the light direction about the smooth normal, alpha^2 = tan^2(tilt) / 8 (at most 1)."""
    ns = np.array([[0.0, 0.0, 1.0]])
    factors = []
    for tilt in (20.0, 45.0, 63.0, 75.0):
        d = np.radians(tilt)
        n = np.array([[np.sin(d), 0.0, np.cos(d)]])
        alpha = math.sqrt(min(math.tan(d) ** 2 / 8.0, 1.0))
        for elev, az in ((5.0, 0.0), (20.0, 0.0), (20.0, 1.2), (50.0, 2.5)):
            e = np.radians(elev)
            i = np.array([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), np.sin(e)])
            got = textures.bump_shadowing(ns, n, i[None])[0]
            if n[0] @ i <= 0.0:                    # behind the mapped normal: no light
                assert got == 0.0
                continue
            want = _ggx_g1_by_quadrature(alpha, i)
            assert got == pytest.approx(want, abs=2e-3), (tilt, elev, az)
            factors.append(got)
    assert len(factors) > 10 and min(factors) < 0.5 and max(factors) > 0.99
    assert textures.bump_shadowing(ns, ns, np.array([[0.0, 0.6, 0.8]]))[0] == 1.0  # unmapped
    # light under the smooth normal's horizon, in front of the mapped normal: none
    n = np.array([[0.0, 0.8, 0.6]])
    assert textures.bump_shadowing(ns, n, np.array([[0.0, 0.99, -0.14]]))[0] == 0.0


def test_dilate_fills_a_margin_from_covered_neighbours():
    img = np.zeros((8, 8, 3), np.float32)
    covered = np.zeros((8, 8), bool)
    covered[3:5, 3:5] = True
    img[3:5, 3:5] = (1.0, 2.0, 3.0)
    img[0, 0] = 9.0                        # not covered: overwritten, never read
    out, done = textures.dilate(img, covered, 2)
    # two 4-neighbour steps: every texel within Manhattan distance 2 of the block
    i, j = np.mgrid[0:8, 0:8]
    reach = np.maximum(np.maximum(3 - i, i - 4), 0) + np.maximum(np.maximum(3 - j, j - 4), 0)
    assert np.array_equal(done, reach <= 2)
    np.testing.assert_allclose(out[done], np.tile((1.0, 2.0, 3.0), (done.sum(), 1)))
    assert out[0, 0, 0] == 9.0 and np.array_equal(out[covered], img[covered])
    same, _ = textures.dilate(img, covered, 0)
    np.testing.assert_array_equal(same, img)
