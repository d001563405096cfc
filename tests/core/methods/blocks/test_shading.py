"""core.methods.blocks.shading (Inger, Farbman, Lischinski 2013, Algorithm 1): the per-vertex
oracle (tests/core/methods/blocks/oracle.py) against the pixel-basis sums, then the batched
evaluator against REFERENCE (pixel basis) and against the oracle for every level mode.
No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.blocks import encoding as E
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.methods.blocks import shading as B
from prt_relight.core.methods.blocks import light_tables
from prt_relight.core.methods.blocks import lobe as Lobe
from prt_relight.core.shading import brdf
from prt_relight.core.methods.reference import shading as reference

from . import oracle as O
from .cases import MATERIALS, random_scene, structured_bits


def _sharp_vertex_case(n, rng, P=4):
    D = 6 * n * n
    L = rng.random((D, 3)) * np.where(rng.random((D, 1)) < 0.02, 50.0, 1.0)
    v, bits = structured_bits(n, rng, P=P + 5)
    d = cubemap(n).directions
    nrm = rng.normal(size=3)
    nrm /= np.linalg.norm(nrm)
    cos = np.maximum(d @ nrm, 0.0)
    rho = rng.random((D, 3)) * cos[:, None]            # arbitrary BRDF samples x cos
    return L, v, bits, rho


@pytest.mark.parametrize("n", [32, 64])
def test_integrate_vertex_pixel_basis_equals_reference(n):
    rng = np.random.default_rng(10 + n)
    L, v, bits, rho = _sharp_vertex_case(n, rng)
    light = O.block_lighting(L, n)
    dv = E.encode_visibility(bits, n)
    dw = cubemap(n).solid_angles
    for p in range(dv.count):
        res = O.integrate_vertex(dv.vertex(p), light, rho, mode="pixel")
        want = np.einsum("k,kc,kc->c", v[p] * dw, L, rho)
        np.testing.assert_allclose(res.radiance, want, rtol=1e-6, atol=1e-12)
        counts = res.case_counts()
        assert sum(counts.values()) == E.block_count(n)
        assert counts["light-vis (line 9)"] == 0                  # pixel BRDF is never constant
        if p == 0:
            assert counts["zero (line 2)"] == E.block_count(n)
        if p == 1:
            assert counts["light-brdf (line 6)"] == E.block_count(n)
        if p == 2:
            assert counts["triple (line 11)"] == E.block_count(n)


def test_integrate_vertex_all_cases_exact_for_blockwise_bandlimited_brdf():
    """Adaptive path: a BRDF that is exactly constant / 4- / 16-DCT / arbitrary per
    block reproduces the triple product exactly and uses all four cases."""
    n, rng = 32, np.random.default_rng(11)
    nb = E.block_count(n)
    L, v, bits, _ = _sharp_vertex_case(n, rng)
    lv = rng.integers(0, 4, nb)
    A = rng.normal(size=(nb, 16, 3)) * 0.1
    A[:, 0] += 5.0
    for i, k in enumerate((1, 4, 16)):
        A[lv == i, k:] = 0
    pix = np.einsum("bkc,kp->bpc", A, E.dct_basis())
    pix[lv == 3] = rng.random((int((lv == 3).sum()), 256, 3))
    rho = E.from_blocks(pix, n)
    light = O.block_lighting(L, n)
    dv = E.encode_visibility(bits, n)
    dw = cubemap(n).solid_angles
    seen = np.zeros(4, int)
    for p in range(dv.count):
        res = O.integrate_vertex(dv.vertex(p), light, rho, rel_tol=1e-9, abs_tol=1e-12)
        want = np.einsum("k,kc,kc->c", v[p] * dw, L, rho)
        np.testing.assert_allclose(res.radiance, want, rtol=1e-9)
        np.testing.assert_allclose(res.values, np.einsum("bk,bkc,bkc->bc", E.to_blocks(v[p] * dw, n),
                                                         E.to_blocks(L, n), pix), rtol=1e-8, atol=1e-13)
        active = dv.kind[p] != E.ZERO
        assert np.array_equal(res.levels[active], np.array([1, 4, 16, 256])[lv[active]])
        seen += np.bincount(res.cases, minlength=4)
    assert (seen > 0).all(), seen


def test_integrate_vertex_material_adaptive_close_to_reference():
    from prt_relight.core.shading.brdf import reflectance_cosine
    from prt_relight.core.shading.materials import Material
    n, rng = 32, np.random.default_rng(12)
    L, v, bits, _ = _sharp_vertex_case(n, rng)
    light = O.block_lighting(L, n)
    dv = E.encode_visibility(bits, n)
    mat = Material()
    nrm, view = np.array([0.0, 0.3, 1.0]), np.array([0.5, 0.0, 1.0])
    nrm /= np.linalg.norm(nrm)
    view /= np.linalg.norm(view)
    f = O.material_sampler(mat, nrm, view, n)
    rho = reflectance_cosine(mat, nrm[None], view[None], cubemap(n).directions)[0].astype(float)
    dw = cubemap(n).solid_angles
    p = 4
    res = O.integrate_vertex(dv.vertex(p), light, f)
    want = np.einsum("k,kc,kc->c", v[p] * dw, L, rho)
    np.testing.assert_allclose(res.radiance, want, rtol=0.02)
    exact = O.integrate_vertex(dv.vertex(p), light, f, mode="pixel")
    np.testing.assert_allclose(exact.radiance, want, rtol=1e-6)
    assert sum(res.level_counts().values()) == int((dv.kind[p] != E.ZERO).sum())


@pytest.mark.parametrize("name", list(MATERIALS))
def test_pixel_basis_equals_reference(name):
    """Every block in the pixel basis: BLOCKS is REFERENCE's sum up to float rounding."""
    n, rng = 32, np.random.default_rng(1)
    pos, nrm, bits, light = random_scene(n, rng)
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
    pos, nrm, bits, light = random_scene(n, rng, P=12)
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
