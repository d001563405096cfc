"""Normal Map and Bump nodes (core/scene/textures.py NormalSource): the perturbed normal against
brute force (the geometric normal of the displaced surface by finite differences, a rotated
tangent frame)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.scene import textures


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


# --------------------------------------------------------------------------- Blender

def _ridges(res=128, amp=0.08, k=4):
    """A tangent-space normal image of ridges along v (h = amp sin(2 pi k u) on a unit
    UV square), top row first, and the height itself."""
    u = (np.arange(res) + 0.5) / res
    hu = amp * 2 * np.pi * k * np.cos(2 * np.pi * k * u)
    n = np.stack([-hu, np.zeros(res), np.ones(res)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    img = np.ones((res, res, 3), np.float32)
    img[:] = 0.5 * (n[None, :, :] + 1.0)
    h = np.repeat((amp * np.sin(2 * np.pi * k * u))[None, :, None], 3, axis=2)
    return img, np.ascontiguousarray(np.broadcast_to(h, (res, res, 3)), np.float32)


def _mapped_plane(kind, size=2.0, **node_inputs):
    """A grid with a Principled material whose Normal is a Normal Map or Bump node on a
    generated Non-Color image (None: no link, drawn flat)."""
    import bpy
    from . import blender_scene as bs
    plane = bs.add_ground(size=size, cuts=8)
    mat = bpy.data.materials.new("mapped")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    normal_img, height = _ridges()
    if kind is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = bs.float_image(kind, normal_img if kind == "NORMAL_MAP" else height)
        node = nt.nodes.new("ShaderNodeNormalMap" if kind == "NORMAL_MAP" else "ShaderNodeBump")
        for key, value in node_inputs.items():
            node.inputs[key].default_value = value
        nt.links.new(tex.outputs["Color"], node.inputs["Color" if kind == "NORMAL_MAP"
                                                       else "Height"])
        nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    plane.data.materials.append(mat)
    return plane


def _low_sun_world():
    """One bright pixel 20° above the horizon, toward -x, over a dim sky."""
    from . import blender_scene as bs
    el = math.radians(20.0)
    sky = bs.sun_image(256, 128, (-math.cos(el), 0.0, math.sin(el)), radiance=2e4)
    sky += 0.02
    bs.add_world(image=bs.float_image("sky", sky))


def _broad_sky_world():
    """A smooth sky, brightest 30° above the horizon toward -x (no compact source is split
    off: every method shades all of it from its transfer)."""
    from . import blender_scene as bs
    h, w = 64, 128
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)      # u = 0.5 - atan2(y, x) / 2 pi
    d = np.stack(np.broadcast_arrays(np.sin(theta)[:, None] * np.cos(phi)[None],
                                     np.sin(theta)[:, None] * np.sin(phi)[None],
                                     np.cos(theta)[:, None]), axis=-1)
    s = np.array([-math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    sky = 0.05 + 2.0 * np.maximum(d @ s, 0.0) ** 2
    bs.add_world(image=bs.float_image("sky", np.repeat(sky[..., None], 3, axis=2)))


@pytest.mark.slow
@pytest.mark.usefixtures("registered_addon")
@pytest.mark.parametrize("kind,world", [("NORMAL_MAP", "sun"), ("BUMP", "sun"),
                                        ("NORMAL_MAP", "sky")])
def test_mapped_plane_against_cycles(tmp_path, kind, world):
    """Direct light only; the ridges face toward and away from a 20° sun (drawn per pixel
    by the sources' pass for every method) or a broad sky (SSDF_SG per pixel, REFERENCE
    per vertex: the normal map ignored): drawn with the mapped normal the frame follows
    Cycles', drawn flat it does not."""
    import bpy
    from . import blender_scene as bs
    bs.reset()
    (_low_sun_world if world == "sun" else _broad_sky_world)()
    # the bump's distance makes the same ridges as the normal image (its height in UV units
    # over a plane 2 units wide: distance 1 / 2 in world units per UV unit)
    plane = _mapped_plane(kind, **({"Distance": 2.0} if kind == "BUMP" else {}))
    bs.add_camera(location=(0.0, 0.0, 3.0), rotation=(0.0, 0.0, 0.0))
    bs.set_resolution(64, 64)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    truth = bs.render_exr(tmp_path / "cycles.exr", engine="CYCLES", samples=1024)
    errors = {}
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method] = bs.rel_l2(bs.render_exr(tmp_path / f"{method}.exr"), truth)
    # drawn flat: the Normal link removed
    links = plane.active_material.node_tree.links
    links.remove(plane.active_material.node_tree.nodes["Principled BSDF"].inputs["Normal"]
                 .links[0])
    for method in ("REFERENCE", "SSDF_SG"):
        bpy.context.scene.prt.method = method
        errors[method + " flat"] = bs.rel_l2(bs.render_exr(tmp_path / f"{method}f.exr"),
                                             truth)
    print(kind, world, {k: round(v, 4) for k, v in errors.items()})
    # the figures: docs/measurements.md, Normal Map and Bump nodes
    bound = {("NORMAL_MAP", "sun"): 0.02, ("BUMP", "sun"): 0.03,
             ("NORMAL_MAP", "sky"): 0.05}[kind, world]
    flat = 0.6 if world == "sun" else 0.55
    for method in ("REFERENCE", "SSDF_SG") if world == "sun" else ("SSDF_SG",):
        assert errors[method] < bound, errors
        assert errors[method + " flat"] > flat, errors


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


def _ggx_g1_by_quadrature(alpha, i):
    """Smith G1 of GGX (Heitz 2014: the visible projected area of the microfacets is the
    macro surface's): cos(i) / integral of D(m) max(0, m.i) over the hemisphere."""
    th = (np.arange(2000) + 0.5) / 2000 * (np.pi / 2)
    ph = (np.arange(360) + 0.5) / 360 * (2 * np.pi)
    t, p = np.meshgrid(th, ph, indexing="ij")
    m = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    a2 = alpha * alpha
    D = a2 / (np.pi * np.cos(t) ** 4 * (a2 + np.tan(t) ** 2) ** 2)
    dm = np.sin(t) * (np.pi / 2 / 2000) * (2 * np.pi / 360)
    assert np.sum(D * np.cos(t) * dm) == pytest.approx(1.0, abs=2e-3)
    return i[2] / np.sum(D * np.maximum(m @ i, 0.0) * dm)


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


def _evaluated(ob):
    import bpy
    bpy.context.view_layer.update()
    return ob.evaluated_get(bpy.context.evaluated_depsgraph_get())


@pytest.mark.usefixtures("registered_addon")
def test_export_reads_both_nodes_tangents_and_warns_other_links():
    from prt_relight.addon.blender import texture_export
    from . import blender_scene as bs
    bs.reset()
    plane = _mapped_plane("NORMAL_MAP", Strength=0.7)
    plane.rotation_euler = (0.0, 0.0, math.pi / 2)                 # tangents turn with it
    ob = _evaluated(plane)
    warnings = []
    got = texture_export.slot_normals(ob, warnings)
    src, uvs, tng = got[0]
    assert warnings == [] and src.kind == "NORMAL_MAP" and src.strength == pytest.approx(0.7)
    assert uvs.shape == (len(tng), 2)
    # the grid's u runs along its local x, turned to world y; bitangent sign +1
    np.testing.assert_allclose(tng, np.tile([0.0, 1.0, 0.0, 1.0], (len(tng), 1)), atol=1e-5)
    nt = plane.active_material.node_tree
    bump = nt.nodes.new("ShaderNodeBump")
    bump.invert = True
    bump.inputs["Distance"].default_value = 0.3
    nt.links.new(nt.nodes["Image Texture"].outputs["Color"], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], nt.nodes["Principled BSDF"].inputs["Normal"])
    ob = _evaluated(plane)
    src = texture_export.slot_normals(ob, warnings)[0][0]
    assert src.kind == "BUMP" and src.distance == pytest.approx(-0.3)
    coord = nt.nodes.new("ShaderNodeNewGeometry")
    nt.links.new(coord.outputs["Normal"], nt.nodes["Principled BSDF"].inputs["Normal"])
    ob = _evaluated(plane)
    assert texture_export.slot_normals(ob, warnings) == {}
    assert len(warnings) == 1 and "'Geometry'" in warnings[0], warnings
