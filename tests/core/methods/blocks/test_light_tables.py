"""core.methods.blocks.light_tables (Inger, Farbman, Lischinski 2013, §4.3): the lighting per
block in its DCT, suffix-sum and pixel bases and the light-visibility products, against the
pixel sums of tests/core/methods/blocks/oracle.py; the cached decoded blocks against the
differential decode; the line-9 sums, the exact Lambert layer and the DCT light-visibility
products against brute-force sums over every pixel and REFERENCE.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.blocks import encoding as E
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.methods.blocks import light_tables
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.scene.visibility import unpack_visibility

from . import oracle as O
from .cases import random_scene, structured_bits


@pytest.mark.parametrize("grey", [False, True])
def test_light_vis_product_equals_pixel_sum(grey):
    n, rng = 32, np.random.default_rng(4)
    L = rng.random((6 * n * n, 3)) * np.where(rng.random((6 * n * n, 1)) < 0.01, 100.0, 1.0)
    light = O.block_lighting(L, n)
    v, bits = structured_bits(n, rng, P=7)
    if grey:
        g = np.where(v, rng.random(v.shape), 0.0)
        dv = E.encode_quantized_visibility(g, n)
        vis = E.decode_levels(dv) / 63.0
    else:
        dv = E.encode_visibility(bits, n)
        vis = v.astype(float)
    dw = cubemap(n).solid_angles
    for p in range(len(vis)):
        got = O.light_vis_product(light, dv.vertex(p))
        want = np.einsum("bk,bkc->bc", E.to_blocks(vis[p] * dw, n), E.to_blocks(L, n))
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-14)


def test_lighting_representations():
    n, rng = 32, np.random.default_rng(5)
    L = rng.random((6 * n * n, 3))
    light = O.block_lighting(L, n)
    cube = cubemap(n)
    pix = E.to_blocks(L * cube.solid_angles[:, None], n)
    np.testing.assert_allclose(light.pixel, pix)                    # solid-angle corrected
    np.testing.assert_allclose(light.integral[:, 0], pix.sum(axis=1))
    np.testing.assert_allclose(light.integral[:, 255], pix[:, 255])
    # DCT coefficients: projection on the orthonormal basis
    np.testing.assert_allclose(light.dct, np.einsum("kp,bpc->bkc", E.dct_basis(), pix))


def test_cached_decoded_blocks_equal_the_differential_decode():
    """The per-frame unpack of cached decoded blocks == decoding V_d again == the bits."""
    rng = np.random.default_rng(11)
    n = 32
    pos, nrm, bits, light = random_scene(n, rng)
    dv = E.encode_visibility(bits, n)
    pairs = light_tables.active_pairs(dv)
    sel = np.arange(pairs.count)[::-1]
    fresh = light_tables.decompress(pairs, sel, np.float32, cached=False)
    assert (~pairs.one).any() and pairs.decoded_bits()[0].shape[1] == 32
    np.testing.assert_array_equal(light_tables.decompress(pairs, sel, np.float32), fresh)
    dense = E.to_blocks(unpack_visibility(bits, 6 * n * n).T, n)       # (blocks, 256, P)
    np.testing.assert_array_equal(fresh, dense[pairs.b[sel], :, pairs.p[sel]])


@pytest.mark.parametrize("grey", [False, True])
def test_line_9_sums_and_the_lambert_layer_against_pixel_sums(grey):
    """light_vis_sums over the stored change indices only (eq. 6) against the sums over
    every pixel of each active block of L~ V (and L~ w V); the Lambert layer against
    REFERENCE's diffuse irradiance of the same visibility; dct_light_vis against the
    projection of L~ V on the block's DCT functions."""
    n, rng = 16, np.random.default_rng(7)
    pos, nrm, bits, light = random_scene(n, rng, P=12)
    cube = cubemap(n)
    vis = unpack_visibility(bits, cube.size).astype(np.float64)
    if grey:                                   # quantized (grey) visibility: 63 levels
        vis = np.round(vis * rng.random(vis.shape) * 63.0) / 63.0
        dv = E.encode_quantized_visibility(vis, n)
    else:
        dv = E.encode_visibility(bits, n)
    pairs = light_tables.active_pairs(dv)
    tables = light_tables.light_tables(light, n)
    sums = light_tables.light_vis_sums(pairs, tables)
    pix = E.to_blocks(light.radiance * cube.solid_angles[:, None], n)        # (B, 256, 3)
    vb = E.to_blocks(vis.T, n)                                               # (B, 256, P)
    want = np.einsum("bkp,bkc->pbc", vb, pix)[pairs.p, pairs.b]
    np.testing.assert_allclose(sums.S, want, rtol=2e-5, atol=1e-6 * want.max())
    kept = np.zeros((len(vis), E.block_count(n)), bool)
    kept[pairs.p, pairs.b] = True
    assert not np.einsum("bkp->pb", vb)[~kept].any()       # the pairs left out see nothing
    irr = light_tables.lambert_irradiance(sums, nrm)
    np.testing.assert_allclose(irr, _lambert(vis, nrm, light, cube), rtol=1e-6, atol=1e-9)
    if not grey:
        np.testing.assert_allclose(irr, reference.diffuse_irradiance(bits, nrm, cube, light),
                                   rtol=1e-6, atol=1e-9)
    for k in (1, 4, 16):
        got = light_tables.dct_light_vis(pairs, tables, np.arange(pairs.count), k, np.float64)
        proj = np.einsum("kq,bqp,bqc->pbkc", E.dct_basis()[:k], vb, pix)[pairs.p, pairs.b]
        np.testing.assert_allclose(got, proj, rtol=1e-9, atol=1e-12 * np.abs(proj).max())


def _lambert(vis, normals, light, cube):
    """REFERENCE's diffuse irradiance for a grey visibility: sum over texels of
    V L (n . w) dw with w the lighting's mean direction per texel."""
    cos = normals @ np.asarray(light.directions, dtype=np.float64).T
    return np.einsum("pd,pd,dc,d->pc", vis, cos, np.asarray(light.radiance, np.float64),
                     cube.solid_angles)
