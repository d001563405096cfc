"""core.methods.blocks.encoding (Inger, Farbman, Lischinski 2013, §4): the block layout, the
DCT basis, varints, the differential (eq. 5) and quantized visibility round trips and the
BRDF's projection on the block bases.  No bpy."""

import numpy as np
import pytest

from prt_relight.core.methods.blocks import encoding as E
from prt_relight.core.sphere.directions import cubemap

from . import oracle as O
from .cases import structured_bits


@pytest.mark.parametrize("n", [32, 64, 128])
def test_block_layout_is_a_bijection(n):
    perm = E.block_permutation(n)
    assert perm.shape == (E.block_count(n), 256)
    assert np.array_equal(np.sort(perm.reshape(-1)), np.arange(6 * n * n))
    x = np.random.default_rng(0).random((6 * n * n, 3))
    assert np.array_equal(E.from_blocks(E.to_blocks(x, n), n), x)
    # second block of face 0 = columns 16..31 of rows 0..15
    assert perm[1, 0] == 16 and perm[1, 17] == n + 17
    t = np.arange(0, 6 * n * n, 37)
    blk, k = E.texel_to_block(t, n)
    assert np.array_equal(E.block_to_texel(blk, k, n), t)


def test_dct_orthonormal_and_nested_order():
    c = E.dct_matrix()
    assert np.allclose(c @ c.T, np.eye(16), atol=1e-13)
    phi = E.dct_basis()
    assert np.allclose(phi @ phi.T, np.eye(16), atol=1e-13)
    assert E.DCT_ORDER[0] == (0, 0)
    assert set(E.DCT_ORDER[:4]) == {(0, 0), (0, 1), (1, 0), (1, 1)}
    for l in (1, 2, 4):
        pix, inv = E.projection_system(l)
        S = phi[: l * l][:, pix].T
        assert np.allclose(inv @ S, np.eye(l * l), atol=1e-10)


def test_varint_round_trip():
    rng = np.random.default_rng(1)
    v = np.concatenate([np.arange(300), rng.integers(0, 2 ** 62, 500, dtype=np.int64),
                        [127, 128, 16383, 16384, 2 ** 63 - 1]]).astype(np.uint64)
    buf = E.varint_encode(v)
    assert buf.dtype == np.uint8
    assert np.array_equal(E.varint_decode(buf), v)
    assert np.array_equal(E.varint_decode(buf.tobytes()), v)
    assert list(E.varint_encode([0, 1, 127, 128, 300])) == [0, 1, 127, 0x80, 1, 0xAC, 2]
    with pytest.raises(ValueError):
        E.varint_decode(np.array([0x80], np.uint8))


@pytest.mark.parametrize("n", [32, 64])
def test_differential_visibility_round_trip(n):
    rng = np.random.default_rng(n)
    v, bits = structured_bits(n, rng, P=9)
    dv = E.encode_visibility(bits, n)
    assert dv.binary and dv.kind.shape == (9, E.block_count(n))
    assert (dv.kind[0] == E.ZERO).all() and (dv.kind[1] == E.ONE).all()
    assert (dv.kind[2] == E.MIXED).all()
    assert np.diff(dv.offsets)[: 2 * dv.blocks].sum() == 0      # constants store nothing
    # checkerboard: a change at every pixel except the 15 row starts, where the
    # concatenated rows repeat the previous value (pixel 0 is a 0 -> 1 change)
    assert (np.diff(dv.offsets)[2 * dv.blocks:3 * dv.blocks] == 241).all()
    assert np.array_equal(E.decode_visibility(dv), bits)
    assert np.array_equal(E.decode_levels(dv).astype(bool), v)
    # indices are the nonzeros of D V (eq. 5), per block
    vb = E.to_blocks(v[5].astype(np.int16), n, axis=0)
    d = np.diff(vb, axis=1, prepend=0)
    one = dv.vertex(5)
    for b in np.nonzero(one.kind[0] == E.MIXED)[0][:5]:
        seg = one.indices[one.offsets[b]:one.offsets[b + 1]]
        assert np.array_equal(seg, np.nonzero(d[b])[0])
        assert np.array_equal(one.entry_values()[one.offsets[b]:one.offsets[b + 1]], d[b][seg])
    # varint serialization of the whole thing
    buf = E.serialize_visibility(dv)
    back = E.deserialize_visibility(buf.tobytes())
    assert back.binary and back.resolution == n
    for name in ("kind", "offsets", "indices"):
        assert np.array_equal(getattr(back, name), getattr(dv, name)), name
    assert np.array_equal(E.decode_visibility(back), bits)


def test_single_run_and_edge_blocks():
    n = 32
    D = 6 * n * n
    v = np.zeros((3, D), bool)
    perm = E.block_permutation(n)
    v[0, perm[3, 200:]] = True            # one change, at 200: mixed, 1 index
    v[1, perm[3, :255]] = True            # changes at 0 and 255
    v[2, perm[3, 255]] = True             # single last pixel
    dv = E.encode_visibility(np.packbits(v, axis=1), n)
    assert dv.kind[0, 3] == E.MIXED and list(dv.vertex(0).indices) == [200]
    assert list(dv.vertex(1).indices) == [0, 255]
    assert list(dv.vertex(2).indices) == [255]
    back = E.deserialize_visibility(E.serialize_visibility(dv))
    assert np.array_equal(E.decode_levels(back).astype(bool), v)


def test_quantized_visibility_round_trip():
    n, rng = 32, np.random.default_rng(3)
    fine = np.stack([rng.random(6 * 128 * 128) < 0.5,
                     np.repeat(cubemap(128).directions[:, 2] > 0.1, 1)])
    gray = E.downsample_visibility(np.packbits(fine, axis=1), 128, 4)
    gray = np.concatenate([gray, np.zeros((1, gray.shape[1])), np.ones((1, gray.shape[1])),
                           np.full((1, gray.shape[1]), 0.5), rng.random((1, gray.shape[1]))])
    dv = E.encode_quantized_visibility(gray, n, bits=6)
    assert not dv.binary and dv.levels == 63
    q = E.quantize_visibility(gray, 6)
    assert np.array_equal(E.decode_levels(dv), q)
    assert (dv.kind[2] == E.ZERO).all() and (dv.kind[3] == E.ONE).all()
    assert (dv.kind[4] == E.MIXED).all()       # constant 0.5: one index, value 32
    assert np.abs(q / 63 - gray).max() <= 0.5 / 63 + 1e-12
    back = E.deserialize_visibility(E.serialize_visibility(dv))
    assert back.levels == 63 and np.array_equal(back.values, dv.values)
    assert np.array_equal(E.decode_levels(back), q)
    with pytest.raises(ValueError):
        E.decode_visibility(dv)


def test_projection_exact_for_band_limited_brdf():
    n, rng = 32, np.random.default_rng(6)
    nb = E.block_count(n)
    for l in (1, 2, 4):
        A = np.zeros((nb, 16, 3))
        A[:, : l * l] = rng.normal(size=(nb, l * l, 3))
        rho = E.from_blocks(np.einsum("bkc,kp->bpc", A, E.dct_basis()), n)
        levels, coeffs, _ = O.project_brdf(rho, np.arange(nb), n, mode="adaptive", rel_tol=1e-9,
                                           abs_tol=1e-12)
        assert (levels == l * l).all()
        np.testing.assert_allclose(coeffs, A, atol=1e-10)
    # a lobe a few pixels wide is not band limited -> pixel basis; constant -> 1
    perm = E.block_permutation(n)
    yy, xx = np.divmod(np.arange(256), 16)
    rho = np.zeros((6 * n * n, 1))
    rho[perm[7], 0] = np.exp(-((yy - 6.3) ** 2 + (xx - 9.6) ** 2) / 4.0)
    rho[perm[8]] = 0.5
    rho[perm[9, 100]] = 1.0                      # one-pixel spike between the check samples
    levels, _, pixels = O.project_brdf(rho, np.array([7, 8, 9]), n)
    assert list(levels) == [256, 1, 1]           # the spike is missed by sampling alone ...
    d = cubemap(n).directions[perm[9, 100]]
    force = O.highlight_blocks(d, n)
    assert force.sum() == 1 and force[9]
    levels, _, pixels = O.project_brdf(rho, np.array([7, 8, 9]), n, force_pixel=force)
    assert list(levels) == [256, 1, 256]         # ... and caught by the highlight hint
    assert pixels[2, 100, 0] == 1.0
    assert O.highlight_blocks(d, n, angle=0.3).sum() > 1
