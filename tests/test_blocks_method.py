"""BLOCKS (Inger et al. 2013) as a method: batched Algorithm 1 against REFERENCE and against the
per-vertex integrator, and the add-on path (precompute, stored varint visibility, F12)."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.blocks import shading as B
from prt_relight.core.methods.blocks import light_tables
from prt_relight.core.methods.blocks import encoding as E
from prt_relight.core.methods.blocks import lobe as Lobe
from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.sphere.envmap import CubeLighting
from prt_relight.core.scene.visibility import unpack_visibility

from . import blocks_oracle as O


def _scene(n, rng, P=40):
    """Random vertices with hemisphere-limited, structured visibility and sharp lighting
    (a few very bright texels, like a sun)."""
    cube = cubemap(n)
    D = cube.size
    nrm = rng.normal(size=(P, 3))
    nrm[:, 2] = np.abs(nrm[:, 2]) + 0.3
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pos = rng.normal(size=(P, 3)) * 0.5
    d = cube.directions
    above = nrm @ d.T > 0.0
    wavy = d[None, :, 2] > 0.15 * np.sin(5 * d[None, :, 0] + rng.uniform(0, 6, (P, 1)))
    vis = above & (wavy | (rng.random((P, 1)) < 0.3))
    vis[0] = above[0]                                      # one fully open vertex
    rad = rng.random((D, 3)).astype(np.float32) * np.where(rng.random((D, 1)) < 0.01, 200.0, 1.0)
    dirs = d * rng.uniform(0.95, 1.0, (D, 1))               # mean light directions, |w| <= 1
    return pos, nrm, np.packbits(vis, axis=1), CubeLighting(rad.astype(np.float32), dirs)


MATERIALS = {
    "glossy beckmann": materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 0.9, 0.8),
                                     roughness=0.25, distribution="BECKMANN"),
    "principled": materials.principled_material(base_color=(0.7, 0.3, 0.2), roughness=0.3),
    "diffuse": materials.Material(diffuse_albedo=(0.8, 0.6, 0.4), specular_color=(0.0, 0.0, 0.0)),
    "metal f82": materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(0.9, 0.6, 0.3),
                               roughness=0.35, distribution="MULTI_GGX", fresnel="F82",
                               f82_tint=(0.8, 0.9, 1.0)),
}


@pytest.mark.parametrize("name", list(MATERIALS))
def test_pixel_basis_equals_reference(name):
    """Every block in the pixel basis: BLOCKS is REFERENCE's sum up to float rounding."""
    n, rng = 32, np.random.default_rng(1)
    pos, nrm, bits, light = _scene(n, rng)
    mats = [MATERIALS[name]]
    eye = np.array([0.3, -4.0, 2.0])
    cube = cubemap(n)
    ref = reference.shade_points(bits, pos, nrm, np.zeros(len(pos), int), mats, eye, cube, light)
    dv = E.encode_visibility(bits, n)
    pairs = light_tables.active_pairs(dv)
    tables = light_tables.light_tables(light, n)
    ours = B.shade_points(pairs, None, tables, pos, nrm, np.zeros(len(pos), int), mats, eye,
                          mode="pixel")
    np.testing.assert_allclose(ours, ref, rtol=2e-5, atol=1e-6 * float(ref.max()))
    # the adaptive rule with the exact Lambert layer stays close
    lv = light_tables.light_vis_sums(pairs, tables)
    np.testing.assert_allclose(light_tables.lambert_irradiance(lv, nrm),
                               reference.diffuse_irradiance(bits, nrm, cube, light), rtol=2e-3)
    errors = []
    for thresholds in (Lobe.DEFAULT_LEVEL_THRESHOLDS, (1e-4, 1e-5, 1e-6, 1e-12)):
        st = B.BlocksStats()
        fast = B.shade_points(pairs, lv, tables, pos, nrm, np.zeros(len(pos), int), mats, eye,
                              thresholds=thresholds, stats=st)
        errors.append(np.linalg.norm(fast - ref) / np.linalg.norm(ref))
        assert st.cases.sum() == dv.count * dv.blocks or name == "diffuse"
    # measured: <= 3.5e-3 (GGX tails under 200x "suns" at 6x32^2), 1e-3 with the tighter rule
    assert errors[0] < 1e-2 and errors[1] <= max(errors[0], 2e-3), errors


@pytest.mark.parametrize("material", ["principled", "glossy beckmann"])
@pytest.mark.parametrize("mode", [1, 4, 16, "pixel"])
def test_batched_equals_per_vertex_integrator(mode, material):
    """glossy_blocks (all vertices at once, grouped by block) = integrate_vertex (Algorithm 1
    one vertex at a time) for each fixed BRDF representation; the float32 frame path
    (Beckmann: the fused dense lobe) within float rounding of it."""
    n, rng = 32, np.random.default_rng(2)
    pos, nrm, bits, light = _scene(n, rng, P=12)
    mat = MATERIALS[material]
    views = reference.view_directions(pos, np.array([0.0, -3.0, 1.5]))
    dv = E.encode_visibility(bits, n)
    pairs = light_tables.active_pairs(dv)
    tables = light_tables.light_tables(light, n)
    lv = light_tables.light_vis_sums(pairs, tables)
    lobe = Lobe.GlossyLobe(mat, np.float64).prepare(nrm, views)
    st = B.BlocksStats()
    batched = B.glossy_blocks(pairs, lv, tables, lobe, np.arange(len(pos)), mode=mode, stats=st)
    fast = B.glossy_blocks(pairs, lv, tables, Lobe.GlossyLobe(mat).prepare(nrm, views),
                           np.arange(len(pos)), mode=mode)             # float32 frame path
    assert np.linalg.norm(fast - batched) <= 2e-3 * np.linalg.norm(batched)
    some = np.arange(1, len(pos), 3)                   # vertices that are not one run
    part = B.glossy_blocks(pairs, lv, tables, Lobe.GlossyLobe(mat, np.float64).prepare(
        nrm[some], views[some]), some, mode=mode)
    np.testing.assert_allclose(part, batched[some], rtol=1e-9, atol=1e-12 * np.abs(batched).max())
    block_light = O.block_lighting(light.radiance, n)
    unit = light.unit_directions
    for p in range(len(pos)):
        rho = brdf.specular_cosine(mat, nrm[p:p + 1], views[p:p + 1], unit)[0].astype(np.float64)
        if rho.ndim == 1:                   # scalar lobe (no Fresnel): colour not included
            rho = rho[:, None] * np.asarray(mat.specular_color)[None, :]
        want = O.integrate_vertex(dv.vertex(p), block_light, rho, mode=mode)
        np.testing.assert_allclose(batched[p], want.radiance, rtol=1e-6,
                                   atol=1e-9 * np.abs(batched).max())
    active = int((dv.kind != E.ZERO).sum())
    assert st.cases[1:].sum() == active
    assert st.levels[E.PIXEL if mode == "pixel" else mode] == active


@pytest.mark.parametrize("roughness", [0.1, 0.25, 0.6, 1.0])
def test_fused_beckmann_lobe_equals_the_general_formula(roughness):
    """GlossyLobe.dense's fused float32 Beckmann path (matrix products with the sums folded
    in) against the float64 general formula, at directions all around the sphere: below
    the horizon (0), grazing light (Lambda_i > 0), grazing and backward views, wi = -wo."""
    rng = np.random.default_rng(7)
    P, D = 64, 400
    nrm = rng.normal(size=(P, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    views = rng.normal(size=(P, 3))
    views[:8] = -nrm[:8] + 0.01 * rng.normal(size=(8, 3))     # views from below: bent
    views[8:16] -= nrm[8:16] * np.einsum("ij,ij->i", views[8:16], nrm[8:16])[:, None]
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    d = rng.normal(size=(D, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:P // 4] = -views[:P // 4]                              # wi = -wo for a few vertices
    mat = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 0.9, 0.8),
                        roughness=roughness, distribution="BECKMANN")
    fast = Lobe.GlossyLobe(mat).prepare(nrm, views)
    assert fast._fused is not None
    slow = Lobe.GlossyLobe(mat, np.float64).prepare(nrm, views)
    with np.errstate(all="ignore"):
        got = sum(f[:, :, None] * w[:, None, :] for f, w in fast.dense(np.arange(P), d))
        want = sum(f[:, :, None] * w[:, None, :] for f, w in slow.dense(np.arange(P), d))
    assert np.isfinite(got).all() and (got >= 0.0).all()
    scale = float(np.abs(want).max())
    # float32 rounding of 1 / cos_h^2 moves the exponent by ~3e-7 / alpha^2; where
    # |wo + wi|^2 < 0.05 (wi ~ -wo, grazing views) float32 cannot resolve the half-vector,
    # nor the horizon at |cos_i| < 1e-5: only finite there
    v = Lobe.GlossyLobe(mat).prepare(nrm, views).v
    resolved = ((2.0 + 2.0 * v @ d.T) > 0.05) & (np.abs(nrm @ d.T) > 1e-5)
    np.testing.assert_allclose(got[resolved], want[resolved], rtol=2e-4 + 1e-6 / mat.alpha ** 2,
                               atol=1e-6 * scale)
    assert (got[(nrm @ d.T) < -1e-5] == 0.0).all()


@pytest.mark.parametrize("n", [32, 64])
def test_pairs_off_the_horizon_have_every_direction_above_the_cut(n):
    """near_horizon is conservative: a (vertex, block) pair it lets skip the horizon and
    grazing-light checks has every sample direction (the lighting's unit directions) above
    the lobe's horizon_cos; and most pairs well above the horizon are let through."""
    rng = np.random.default_rng(11)
    P = 300
    nrm = rng.normal(size=(P, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    mat = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 1.0, 1.0),
                        roughness=0.25, distribution="BECKMANN")
    lobe = Lobe.GlossyLobe(mat).prepare(nrm, nrm)
    cube = cubemap(n)
    light = CubeLighting(np.ones((cube.size, 3), np.float32),
                         cube.directions * rng.uniform(0.9, 1.0, (cube.size, 1)))
    tables = light_tables.light_tables(light, n)
    geometry = E.block_geometry(n)
    nb = geometry.centre.shape[0]
    p = np.repeat(np.arange(P), nb)
    b = np.tile(np.arange(nb), P)
    edge = Lobe.near_horizon(lobe, p, b, geometry)
    cos_min = np.einsum("kc,kjc->kj", lobe.n32[p], tables.unit_dirs32[b]).min(axis=1)
    assert (cos_min[~edge] > lobe.horizon_cos()).all()
    assert (~edge[cos_min > 0.5]).mean() > 0.9


def test_cached_decoded_blocks_equal_the_differential_decode():
    """The per-frame unpack of cached decoded blocks == decoding V_d again == the bits."""
    rng = np.random.default_rng(11)
    n = 32
    pos, nrm, bits, light = _scene(n, rng)
    dv = E.encode_visibility(bits, n)
    pairs = light_tables.active_pairs(dv)
    sel = np.arange(pairs.count)[::-1]
    fresh = light_tables.decompress(pairs, sel, np.float32, cached=False)
    assert (~pairs.one).any() and pairs.decoded_bits()[0].shape[1] == 32
    np.testing.assert_array_equal(light_tables.decompress(pairs, sel, np.float32), fresh)
    dense = E.to_blocks(unpack_visibility(bits, 6 * n * n).T, n)       # (blocks, 256, P)
    np.testing.assert_array_equal(fresh, dense[pairs.b[sel], :, pairs.p[sel]])


def test_level_rule_follows_the_lobe():
    """Pixel basis around the mirror direction, coarser further away, skipped far away."""
    n = 64
    nrm = np.array([[0.0, 0.0, 1.0]])
    view = np.array([[np.sin(0.5), 0.0, np.cos(0.5)]])
    mat = MATERIALS["glossy beckmann"]
    lobe = Lobe.GlossyLobe(mat).prepare(nrm, view)
    geo = E.block_geometry(n)
    blocks = np.arange(E.block_count(n))
    levels = Lobe.glossy_levels(lobe, np.zeros(blocks.size, int), blocks, geo,
                             Lobe.DEFAULT_LEVEL_THRESHOLDS)
    mirror = np.array([-np.sin(0.5), 0.0, np.cos(0.5)])
    angle = np.arccos(np.clip(geo.centre @ mirror, -1, 1))
    assert (levels[angle < 0.05] == E.PIXEL).all()
    assert levels[np.argmin(angle)] == E.PIXEL
    # far from the lobe (and from -wo, where the half-vector of a nearby direction can
    # swing anywhere and the rule stays conservative) the block is skipped
    far = (angle > np.pi / 2) & (geo.centre @ view[0] > -0.5)
    assert far.sum() > 20 and (levels[far] == 0).all()
    # more coefficients closer to the lobe (monotone on average)
    front = geo.centre @ view[0] > -0.5
    means = [angle[front & (levels == lv)].mean() for lv in (E.PIXEL, 16, 4, 1, 0)
             if (front & (levels == lv)).any()]
    assert means == sorted(means)
    # the skipped blocks really are negligible: the lobe's largest value there
    d = geo.texel_dirs[levels == 0].reshape(-1, 3)
    f = brdf.specular_cosine(mat, nrm, view, d)
    assert f.max() < 1e-6 * brdf.specular_cosine(mat, nrm, view, mirror[None]).max()


# ---------------------------------------------------------------------------- add-on

def _blocks_scene(resolution):
    import bpy
    from . import blender_scene as bs
    bs.reset()
    bs.add_world(path=bs.hdri_path("city"), rotation_z=0.6)
    ground = bs.add_ground(size=6.0, cuts=16)
    ground.data.materials.append(bs.bsdf_material("diffuse", "ShaderNodeBsdfDiffuse"))
    ob = bs.add_suzanne(subdiv=1)
    ob.data.materials.append(bs.bsdf_material("glossy", "ShaderNodeBsdfGlossy",
                                              distribution="BECKMANN", Roughness=0.25))
    bs.add_camera()
    bs.set_resolution(64, 48)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.prt.resolution = str(resolution)
    scene.prt.method = "BLOCKS"
    return scene


def _psnr(a, ref):
    m = ref[..., 3] > 0.5
    mse = float(np.mean((a[m][:, :3] - ref[m][:, :3]) ** 2))
    return 10.0 * np.log10(float(ref[m][:, :3].max()) ** 2 / max(mse, 1e-30))


@pytest.mark.usefixtures("registered_addon")
def test_addon_blocks_f12_matches_reference_and_survives_reload(tmp_path):
    import bpy
    from prt_relight.addon.frame import state as runtime
    from prt_relight.addon.methods.blocks import shading as method
    from . import blender_scene as bs
    scene = _blocks_scene(64)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    from prt_relight.addon.blender import storage
    assert storage.has(bpy.data.objects["Suzanne"], method.BLOB)
    ours = bs.render_exr(tmp_path / "blocks.exr")
    assert method.LAST_STATS["sources"] == ["stored", "stored"]
    stats = method.LAST_STATS["stats"]
    assert stats.levels[E.PIXEL] > 0 and stats.cases[3] > 0 and stats.cases[2] > 0
    scene.prt.method = "REFERENCE"
    ref = bs.render_exr(tmp_path / "ref.exr")
    assert np.isfinite(ours).all()
    psnr = _psnr(ours, ref)
    err = bs.rel_l2(ours, ref)
    print(f"BLOCKS vs REFERENCE F12 PSNR {psnr:.2f} dB rel-L2 {err:.2e}")
    assert psnr > 90.0 and err < 1e-4, (psnr, err)      # measured 109 dB, 7.8e-6

    # the stored stream is the lossless differential form of the stored bits
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    by_name = {st.name: st for st in state.objects}
    for name in ("Suzanne", "Grid"):
        st = by_name[name]
        stored = storage.get(bpy.data.objects[name], method.BLOB)[0]["stream"]
        dv = E.deserialize_visibility(stored.tobytes())
        assert np.array_equal(E.decode_visibility(dv), st.bits)
        assert stored.size < st.bits.nbytes / 2          # compressed

    blend = tmp_path / "blocks.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bs.reset()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    scene.prt.method = "BLOCKS"
    method.STORED.clear()
    again = bs.render_exr(tmp_path / "blocks2.exr")
    assert method.LAST_STATS["sources"] == ["stored", "stored"]
    np.testing.assert_allclose(again, ours, rtol=1e-5, atol=1e-6)


@pytest.mark.usefixtures("registered_addon")
def test_addon_blocks_at_32_notes_and_draws(tmp_path):
    import bpy
    from prt_relight.addon.frame import state as runtime
    from . import blender_scene as bs
    scene = _blocks_scene(32)
    scene.prt.method = "REFERENCE"                  # no BLOCKS stream: encoded from the bits
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    ref = bs.render_exr(tmp_path / "ref.exr")
    scene.prt.method = "BLOCKS"
    ours = bs.render_exr(tmp_path / "blocks.exr")
    from prt_relight.addon.methods.blocks import shading as method
    assert method.LAST_STATS["sources"] == ["encoded", "encoded"]
    assert any("6x64x64" in m for m in runtime.LAST_MESSAGES), runtime.LAST_MESSAGES
    psnr, err = _psnr(ours, ref), bs.rel_l2(ours, ref)
    print(f"BLOCKS at 6x32^2 vs REFERENCE F12 PSNR {psnr:.2f} dB rel-L2 {err:.2e}")
    assert psnr > 45.0 and err < 2e-2, (psnr, err)      # measured 49.9 dB, 7.2e-3
