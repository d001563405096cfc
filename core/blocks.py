"""BLOCKS: locally adaptive per-block products (seed 004, Inger et al., §4).

The cubemap (6 x N x N, N = 32/64/128, texels flattened ``(face, row, col)``
as in :mod:`.directions`) is split into 16 x 16 *blocks*, ordered
``(face, block_row, block_col)``; inside a block the pixels are concatenated
row by row (row-major, index ``i*16 + j`` in 0..255).  :func:`block_permutation`
maps between the two orders.

Per vertex and block the integral ``B_b = sum_k L_k V_k rho_k dw_k`` (``rho`` is
BRDF x cosine) is evaluated by Algorithm 1 of the paper:

====  ===========================================  ==========================
case  condition                                    product
====  ===========================================  ==========================
0     visibility constant 0 (line 1)               0
1     visibility constant 1 (line 5)               Light-BRDF (DCT or pixel)
2     visibility mixed, BRDF constant (line 8)     rho_1 * L_int . V_d
3     otherwise (line 11)                          decompress-integrate
====  ===========================================  ==========================

Visibility (§4.2, eq. 5).  ``V_d = D V`` with ``V_d[0] = V[0]`` and
``V_d[i] = V[i] - V[i-1]``: only the indices where ``V_d != 0`` are stored
(uint8, "CCITT group 3" style).  For binary maps the values are implied (they
alternate +1, -1, ... because the map starts from an implicit 0); for the
quantized grey-level variant (Fig. 3, ``bits`` = 6 -> levels 0..63) the integer
derivative values are stored alongside.  Blocks that are constant 0 / constant
"fully visible" are flagged and carry no indices.  :func:`serialize_visibility`
writes everything as base-128 varints (LEB128, protocol-buffer style); the
change indices are written as run lengths (gaps to the previous change).

Lighting (§4.3), per block, after the per-pixel solid-angle correction
``L~_k = L_k dw_k`` (so that plain sums are integrals):

(i)   ``dct``: the 16 lowest orthonormal 2-D DCT-II coefficients (u, v < 4),
      ordered as nested squares so that the first 1 / 4 / 16 are the sets
      ``u, v < l`` for l = 1, 2, 4 (:data:`DCT_ORDER`);
(ii)  ``integral``: ``L_int = D^{-T} L~`` (eq. 6), i.e. ``L_int[i] = sum_{j>=i}
      L~_j`` -- *suffix* sums along the concatenated rows (eq. 6's upper
      triangular matrix of ones).  Then ``L~ . V = L_int . V_d`` exactly, a sum
      over the stored change indices only;
(iii) ``pixel``: ``L~`` itself, (block, 256, 3).

BRDF projection (§4.1, eq. 4).  For l in (1, 2, 4) the BRDF x cos is sampled
at an l x l grid of pixels of the block and the l^2 coefficients of the lowest
DCT functions are obtained by multiplying the samples with a precomputed
*inverse* matrix (a square interpolation system -- l^2 equations, l^2
unknowns -- not least squares).  We use the same orthonormal DCT-II basis as
the lighting (eq. 4 as printed writes ``cos(x 2 pi u / N)``, which is not the
basis whose coefficients the lighting is stored in; line 6's dot product needs
both in the same orthonormal basis, so we use DCT-II for both).

Selection rule of the per-vertex reference path (:func:`project_brdf`, used by
:func:`integrate_vertex` for any sampled BRDF; generic and data driven -- the
batched frame path uses the analytic Appendix-A-style rule :func:`glossy_levels`
instead, which needs no extra samples): the BRDF x cos is also sampled on a 5 x 5 *check grid* (pixels 0, 4, 8, 12, 15
in each direction: corners, edges and centre, where a horizon kink or a lobe
shows first).  The chosen representation is the smallest ``l`` in (1, 2, 4)
whose reconstruction matches every check sample (every colour channel) within
``rel_tol * max|samples of the block| + abs_tol``; if none does, the block is
sampled at all 256 pixels (pixel basis).  Like any sample-based test it can
miss a lobe narrower than the check spacing (4 pixels); the analytic half of
Appendix A ("increase the sampling rate in the vicinity of a highlight") is
available as ``force_pixel=highlight_blocks(mirror_dirs, N, angle)``.  ``abs_tol`` defaults to
``abs_rel_tol`` (1e-3) times the largest sample of the whole vertex, so blocks
that contribute negligibly are not refined.  As in the paper the decision
depends on how smooth the BRDF is within the block, not on its magnitude
(except through that absolute floor).  Blocks whose visibility is constant 0
are never sampled (Alg. 1 line 1 comes before line 4).

Batched frame path (:func:`shade_points`, the BLOCKS method): see the section
"batched evaluator" below -- all (vertex, block) pairs of a chunk of vertices at
once, the Lambert layer exactly from line-9 products of the light's first
moment, the glossy layer by Algorithm 1 with the representation chosen by
:func:`glossy_levels`.  Differences from the paper, all measured in
``bench/bench_blocks.py``: (1) Appendix A's Lambert rule (one coefficient per
block) is replaced by the exact linear cosine (3 moment products per block, view
independent, cached per lighting); (2) the microfacet rule adds a fifth class,
"lobe below ``t_skip`` of its peak everywhere in the block": not sampled,
contributes 0 (the paper samples such a block once); (3) the line-9 products
``S_b`` are cached per lighting, so a frame with only the camera moved does not
redo them (a relight frame does); (4) pixel-basis products run as dense matrix
products with occluded pixels multiplied by 0 rather than skipped run by run;
(5) the 4 / 16 coefficient products with mixed visibility (line 11) use eq. 6's
change-index sums on the DCT-projected lighting instead of decompressing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cache import Cache, memo
from .directions import cubemap
from .visibility import unpack_visibility

BLOCK = 16
BLOCK_PIXELS = BLOCK * BLOCK

#: block kinds
ZERO, ONE, MIXED = 0, 1, 2
#: Algorithm 1 cases (returned per block)
CASE_ZERO, CASE_LIGHT_BRDF, CASE_LIGHT_VIS, CASE_TRIPLE = 0, 1, 2, 3
CASE_NAMES = ("zero (line 2)", "light-brdf (line 6)", "light-vis (line 9)", "triple (line 11)")
#: BRDF representations: number of coefficients
BRDF_LEVELS = (1, 4, 16, 256)
PIXEL = 256

_FORMAT_VERSION = 1


# --------------------------------------------------------------------------- layout

def blocks_per_face(resolution: int) -> int:
    n = int(resolution)
    if n < BLOCK or n % BLOCK:
        raise ValueError(f"cubemap resolution must be a multiple of {BLOCK}, got {n}")
    return n // BLOCK


def block_count(resolution: int) -> int:
    return 6 * blocks_per_face(resolution) ** 2


@memo(8)
def block_permutation(resolution: int) -> np.ndarray:
    """(blocks, 256) int64: flat cubemap texel of pixel ``i*16+j`` of each block.

    Blocks are ordered (face, block_row, block_col)."""
    n = int(resolution)
    nb = blocks_per_face(n)
    f, br, bc, i, j = np.meshgrid(np.arange(6), np.arange(nb), np.arange(nb),
                                  np.arange(BLOCK), np.arange(BLOCK), indexing="ij")
    flat = ((f * n + br * BLOCK + i) * n + bc * BLOCK + j).reshape(6 * nb * nb, BLOCK_PIXELS)
    flat.setflags(write=False)
    return flat


@memo(8)
def inverse_block_permutation(resolution: int) -> np.ndarray:
    """(6*N*N,) int64: position in the block-major order of each flat texel."""
    perm = block_permutation(resolution).reshape(-1)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    inv.setflags(write=False)
    return inv


def texel_to_block(texels, resolution: int):
    """Flat texel indices -> (block, index inside the block)."""
    pos = inverse_block_permutation(resolution)[np.asarray(texels, dtype=np.int64)]
    return pos // BLOCK_PIXELS, pos % BLOCK_PIXELS


def block_to_texel(block, index, resolution: int):
    """(block, index inside the block) -> flat texel index."""
    return block_permutation(resolution)[np.asarray(block), np.asarray(index)]


def to_blocks(values: np.ndarray, resolution: int, axis: int = 0) -> np.ndarray:
    """Reorder the texel axis ``axis`` (length 6N^2) into two axes (blocks, 256)."""
    return np.take(np.asarray(values), block_permutation(resolution), axis=axis)


def from_blocks(values: np.ndarray, resolution: int, axis: int = 0) -> np.ndarray:
    """Inverse of :func:`to_blocks`: axes (axis, axis+1) = (blocks, 256) -> 6N^2 texels."""
    v = np.asarray(values)
    axis = axis % v.ndim
    shape = v.shape[:axis] + (v.shape[axis] * v.shape[axis + 1],) + v.shape[axis + 2:]
    return np.take(v.reshape(shape), inverse_block_permutation(resolution), axis=axis)


# --------------------------------------------------------------------------- DCT

@memo(1)
def dct_matrix() -> np.ndarray:
    """(16, 16) orthonormal DCT-II matrix ``C[u, x] = a_u cos(pi (2x+1) u / 32)``."""
    u = np.arange(BLOCK)[:, None]
    x = np.arange(BLOCK)[None, :]
    c = np.cos(np.pi * (2 * x + 1) * u / (2 * BLOCK)) * np.sqrt(2.0 / BLOCK)
    c[0] /= np.sqrt(2.0)
    c.setflags(write=False)
    return c


#: (u, v) of the 16 lowest DCT functions, nested squares: the first l*l are u, v < l.
DCT_ORDER = tuple(sorted(((u, v) for u in range(4) for v in range(4)),
                         key=lambda p: (max(p), p[0], p[1])))


@memo(1)
def dct_basis() -> np.ndarray:
    """(16, 256): the functions of :data:`DCT_ORDER` on the block pixels (row-major).

    ``Phi[k, y*16+x] = C[u_k, y] C[v_k, x]`` (u: vertical / row frequency)."""
    c = dct_matrix()
    phi = np.stack([np.outer(c[u], c[v]).reshape(-1) for u, v in DCT_ORDER])
    phi.setflags(write=False)
    return phi


def _nodes(l: int) -> np.ndarray:
    """Pixel coordinates of the l samples along one block edge (one per stratum)."""
    return np.array([(2 * i + 1) * (BLOCK // 2) // l - 1 for i in range(l)], dtype=np.int64)


@memo(4)
def projection_system(l: int):
    """Precomputed (sample pixels (l*l,), inverse matrix (l*l, l*l)) of eq. 4.

    ``coeffs = inverse @ rho[sample pixels]`` gives the coefficients of the
    first ``l*l`` functions of :data:`DCT_ORDER` interpolating the samples."""
    if l not in (1, 2, 4):
        raise ValueError("l must be 1, 2 or 4")
    nd = _nodes(l)
    pix = (nd[:, None] * BLOCK + nd[None, :]).reshape(-1)
    S = dct_basis()[: l * l][:, pix].T        # rows: samples, columns: functions
    inv = np.linalg.inv(S)
    pix.setflags(write=False)
    inv.setflags(write=False)
    return pix, inv


_CHECK = np.array([0, 4, 8, 12, 15])
#: 5 x 5 check grid used by the selection rule (block pixel indices)
CHECK_PIXELS = (_CHECK[:, None] * BLOCK + _CHECK[None, :]).reshape(-1)


# --------------------------------------------------------------------------- varints

def varint_encode(values) -> np.ndarray:
    """Unsigned LEB128 (protocol-buffer base-128 varints) of every value -> uint8 array."""
    v = np.asarray(values, dtype=np.uint64).reshape(-1)
    if v.size == 0:
        return np.zeros(0, dtype=np.uint8)
    nbytes = np.ones(v.size, dtype=np.int64)
    for k in range(1, 10):
        nbytes += v >= np.uint64(1) << np.uint64(7 * k)
    starts = np.cumsum(nbytes) - nbytes
    out = np.empty(int(nbytes.sum()), dtype=np.uint8)
    for k in range(int(nbytes.max())):
        sel = nbytes > k
        chunk = (v[sel] >> np.uint64(7 * k)) & np.uint64(0x7F)
        cont = np.where(nbytes[sel] - 1 > k, 0x80, 0).astype(np.uint64)
        out[starts[sel] + k] = (chunk | cont).astype(np.uint8)
    return out


def varint_decode(buf) -> np.ndarray:
    """Inverse of :func:`varint_encode`: uint8 array / bytes -> uint64 values."""
    b = np.frombuffer(buf, dtype=np.uint8) if isinstance(buf, (bytes, bytearray, memoryview)) \
        else np.asarray(buf, dtype=np.uint8).reshape(-1)
    if b.size == 0:
        return np.zeros(0, dtype=np.uint64)
    term = (b & 0x80) == 0
    if not term[-1]:
        raise ValueError("truncated varint stream")
    ends = np.nonzero(term)[0]
    starts = np.concatenate([[0], ends[:-1] + 1])
    group = np.concatenate([[0], np.cumsum(term)[:-1]])
    pos = np.arange(b.size) - starts[group]
    if pos.max() > 9:
        raise ValueError("varint longer than 64 bits")
    vals = np.zeros(ends.size, dtype=np.uint64)
    low = (b & 0x7F).astype(np.uint64)
    for k in range(int(pos.max()) + 1):
        sel = pos == k
        vals[group[sel]] |= low[sel] << np.uint64(7 * k)
    return vals


def _zigzag(v):
    v = np.asarray(v, dtype=np.int64)
    return ((v << 1) ^ (v >> 63)).astype(np.uint64)


def _unzigzag(u):
    u = np.asarray(u, dtype=np.uint64)
    return ((u >> np.uint64(1)).astype(np.int64)) ^ -((u & np.uint64(1)).astype(np.int64))


# --------------------------------------------------------------------------- visibility

@dataclass
class DiffVisibility:
    """Differential visibility of P vertices (eq. 5), block by block.

    ``kind`` (P, blocks) uint8: :data:`ZERO`, :data:`ONE` (fully visible) or
    :data:`MIXED`.  Entries of the mixed blocks, vertex-major then block-major:
    ``offsets`` (P*blocks + 1,) int64 into ``indices`` (uint8, change indices in
    0..255, increasing inside a block) and, for grey-level maps, ``values``
    (int16, the quantized derivative ``V_d[index]``).  ``levels`` is 1 for
    binary maps (``values`` is None: +1, -1, +1, ... implied) and ``2**bits - 1``
    for quantized ones (visibility = level / levels).
    """

    resolution: int
    kind: np.ndarray
    offsets: np.ndarray
    indices: np.ndarray
    values: np.ndarray | None = None
    levels: int = 1

    @property
    def count(self) -> int:
        return self.kind.shape[0]

    @property
    def blocks(self) -> int:
        return self.kind.shape[1]

    @property
    def binary(self) -> bool:
        return self.values is None

    def vertex(self, p: int) -> "DiffVisibility":
        """The one-vertex slice (count 1, offsets rebased)."""
        nb = self.blocks
        a, b = int(self.offsets[p * nb]), int(self.offsets[(p + 1) * nb])
        return DiffVisibility(self.resolution, self.kind[p:p + 1], self.offsets[p * nb:(p + 1) * nb + 1] - a,
                              self.indices[a:b], None if self.values is None else self.values[a:b],
                              self.levels)

    def entry_values(self) -> np.ndarray:
        """Integer ``V_d`` at every stored index (binary: alternating +1/-1 per block)."""
        if self.values is not None:
            return self.values.astype(np.int64)
        counts = np.diff(self.offsets)
        blk = np.repeat(np.arange(counts.size), counts)
        pos = np.arange(self.indices.size) - self.offsets[blk]
        return 1 - 2 * (pos & 1)

    def entry_blocks(self) -> np.ndarray:
        """Flat (vertex*blocks + block) of every stored entry."""
        counts = np.diff(self.offsets)
        return np.repeat(np.arange(counts.size), counts)

    @property
    def nbytes(self) -> int:
        return int(self.kind.nbytes + self.indices.nbytes
                   + (0 if self.values is None else self.values.nbytes))


def _encode_levels(q: np.ndarray, levels: int):
    """q (p, blocks, 256) integer levels -> kind, counts, (p,b) rows, indices, values."""
    d = np.diff(q.astype(np.int16), axis=2, prepend=np.int16(0))
    nz = d != 0
    counts = nz.sum(axis=2)
    kind = np.full(counts.shape, MIXED, dtype=np.uint8)
    kind[counts == 0] = ZERO
    kind[(counts == 1) & (d[:, :, 0] == levels)] = ONE
    p_, b_, k_ = np.nonzero(nz)
    keep = kind[p_, b_] == MIXED
    vals = d[p_[keep], b_[keep], k_[keep]]
    counts = np.where(kind == MIXED, counts, 0)
    return kind, counts, k_[keep].astype(np.uint8), vals


def _encode_binary(v: np.ndarray):
    """:func:`_encode_levels` for 0/1 maps (p, blocks, 256) uint8: the changes are where
    a pixel differs from the previous one (pixel 0 from an implicit 0)."""
    nz = np.empty(v.shape, dtype=bool)
    nz[:, :, 0] = v[:, :, 0] != 0
    np.not_equal(v[:, :, 1:], v[:, :, :-1], out=nz[:, :, 1:])
    counts = np.count_nonzero(nz, axis=2)
    kind = np.full(counts.shape, MIXED, dtype=np.uint8)
    kind[counts == 0] = ZERO
    kind[(counts == 1) & nz[:, :, 0]] = ONE
    nz[kind != MIXED] = False
    flat = np.flatnonzero(nz)
    counts = np.where(kind == MIXED, counts, 0)
    return kind, counts, (flat % BLOCK_PIXELS).astype(np.uint8), None


def _assemble(resolution, parts, levels, binary):
    kinds = [p[0] for p in parts]
    counts = np.concatenate([p[1].reshape(-1) for p in parts]) if parts else np.zeros(0, np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    nb = block_count(resolution)
    kind = np.concatenate(kinds) if kinds else np.zeros((0, nb), dtype=np.uint8)
    idx = np.concatenate([p[2] for p in parts]) if parts else np.zeros(0, np.uint8)
    vals = None if binary else (np.concatenate([p[3] for p in parts]).astype(np.int16)
                                if parts else np.zeros(0, np.int16))
    return DiffVisibility(int(resolution), kind, offsets, idx, vals, int(levels))


def encode_visibility(vis_bits: np.ndarray, resolution: int, chunk: int = 1024) -> DiffVisibility:
    """Bit-packed binary visibility (P, 6N^2/8) uint8 (:mod:`.visibility`) -> differential."""
    bits = np.asarray(vis_bits, dtype=np.uint8)
    if bits.ndim == 1:
        bits = bits[None]
    D = 6 * int(resolution) ** 2
    if bits.shape[1] != D // 8:
        raise ValueError(f"visibility has {bits.shape[1]} bytes per point, expected {D // 8}")
    # A block row is 16 consecutive texels = 2 whole bytes: reorder bytes, then unpack.
    byte_perm = block_permutation(resolution)[:, ::8] // 8           # (blocks, 32)
    nb = byte_perm.shape[0]
    parts = []
    for a in range(0, len(bits), chunk):
        v = np.unpackbits(bits[a:a + chunk][:, byte_perm], axis=2).reshape(-1, nb, BLOCK_PIXELS)
        parts.append(_encode_binary(v))
    return _assemble(resolution, parts, 1, True)


def quantize_visibility(gray: np.ndarray, bits: int = 6) -> np.ndarray:
    """Grey-level visibility in [0, 1] -> integer levels 0 .. 2**bits - 1 (int16)."""
    levels = (1 << int(bits)) - 1
    return np.rint(np.clip(np.asarray(gray, dtype=np.float64), 0.0, 1.0) * levels).astype(np.int16)


def downsample_visibility(fine_bits: np.ndarray, fine_resolution: int, factor: int) -> np.ndarray:
    """Fig. 3's grey-level map: a binary map at ``fine_resolution`` box-filtered down
    by ``factor`` (every coarse texel is exactly factor x factor fine texels, since
    texels are uniform in face coordinates) -> (P, 6 (N/factor)^2) float in [0, 1]."""
    n, f = int(fine_resolution), int(factor)
    if n % f:
        raise ValueError("factor must divide the resolution")
    v = unpack_visibility(np.atleast_2d(fine_bits), 6 * n * n).astype(np.float64)
    m = n // f
    return v.reshape(-1, 6, m, f, m, f).mean(axis=(3, 5)).reshape(len(v), -1)


def encode_quantized_visibility(gray: np.ndarray, resolution: int, bits: int = 6,
                                chunk: int = 1024) -> DiffVisibility:
    """Grey-level visibility (P, 6N^2) in [0, 1] -> quantized differential (Fig. 3).

    Stored: the change indices and the integer derivative of the quantized map."""
    if not 1 <= int(bits) <= 8:
        raise ValueError("bits must be in 1..8")
    levels = (1 << int(bits)) - 1
    g = np.atleast_2d(np.asarray(gray))
    perm = block_permutation(resolution)
    parts = []
    for a in range(0, len(g), chunk):
        q = quantize_visibility(g[a:a + chunk], bits)
        parts.append(_encode_levels(q[:, perm], levels))
    return _assemble(resolution, parts, levels, False)


def _dense_levels(dv: DiffVisibility, a: int, b: int) -> np.ndarray:
    """Integer visibility levels of vertices a..b in block order, (b-a, blocks, 256)."""
    nb = dv.blocks
    out = np.zeros(((b - a) * nb, BLOCK_PIXELS), dtype=np.int16)
    lo, hi = int(dv.offsets[a * nb]), int(dv.offsets[b * nb])
    counts = np.diff(dv.offsets[a * nb:b * nb + 1])
    blk = np.repeat(np.arange(counts.size), counts)
    if dv.values is None:
        pos = np.arange(hi - lo) - (dv.offsets[a * nb:b * nb] - lo)[blk]
        vals = (1 - 2 * (pos & 1)).astype(np.int16)
    else:
        vals = dv.values[lo:hi].astype(np.int16)
    out[blk, dv.indices[lo:hi].astype(np.int64)] = vals
    out[dv.kind[a:b].reshape(-1) == ONE, 0] = dv.levels
    np.cumsum(out, axis=1, out=out)
    return out.reshape(b - a, nb, BLOCK_PIXELS)


def decode_levels(dv: DiffVisibility, chunk: int = 1024) -> np.ndarray:
    """(P, 6N^2) int16 visibility levels (0/1 for binary maps), flat texel order."""
    out = np.empty((dv.count, 6 * dv.resolution ** 2), dtype=np.int16)
    inv = inverse_block_permutation(dv.resolution)
    for a in range(0, dv.count, chunk):
        b = min(dv.count, a + chunk)
        out[a:b] = _dense_levels(dv, a, b).reshape(b - a, -1)[:, inv]
    return out


def decode_visibility(dv: DiffVisibility, chunk: int = 1024) -> np.ndarray:
    """Binary differential visibility -> bit-packed (P, 6N^2/8) uint8 (np.packbits order)."""
    if not dv.binary:
        raise ValueError("not a binary visibility; use decode_levels")
    return np.packbits(decode_levels(dv, chunk).astype(bool), axis=1)


def serialize_visibility(dv: DiffVisibility) -> np.ndarray:
    """All of ``dv`` as one uint8 array of base-128 varints (``.tobytes()`` for a .blend).

    Layout: header ``[version, N, P, levels, grey]``; one code per (vertex, block)
    (0: constant 0, 1: constant fully visible, 1 + count: mixed with ``count``
    changes); the change indices as run lengths (first index, then the gap to the
    previous index); for grey maps, the zigzag-coded derivative values."""
    counts = np.diff(dv.offsets)
    codes = np.where(dv.kind.reshape(-1) == MIXED, counts + 1, dv.kind.reshape(-1)).astype(np.uint64)
    idx = dv.indices.astype(np.int64)
    gaps = idx.copy()
    if idx.size:
        gaps[1:] -= idx[:-1]
        gaps[dv.offsets[:-1][counts > 0]] = idx[dv.offsets[:-1][counts > 0]]
    header = np.array([_FORMAT_VERSION, dv.resolution, dv.count, dv.levels, 0 if dv.binary else 1],
                      dtype=np.uint64)
    parts = [header, codes, gaps.astype(np.uint64)]
    if not dv.binary:
        parts.append(_zigzag(dv.values))
    return varint_encode(np.concatenate(parts))


def deserialize_visibility(buf) -> DiffVisibility:
    """Inverse of :func:`serialize_visibility` (bytes or uint8 array)."""
    v = varint_decode(buf)
    if v.size < 5 or int(v[0]) != _FORMAT_VERSION:
        raise ValueError("not a serialized differential visibility")
    n, P, levels, grey = (int(x) for x in v[1:5])
    nb = block_count(n)
    codes = v[5:5 + P * nb].astype(np.int64)
    if codes.size != P * nb:
        raise ValueError("truncated visibility stream")
    kind = np.where(codes >= 2, MIXED, codes).astype(np.uint8).reshape(P, nb)
    counts = np.where(codes >= 2, codes - 1, 0)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    T = int(offsets[-1])
    rest = v[5 + P * nb:]
    if rest.size != T * (2 if grey else 1):
        raise ValueError("visibility stream has the wrong length")
    gaps = rest[:T].astype(np.int64)
    cum = np.cumsum(gaps)
    blk = np.repeat(np.arange(counts.size), counts)
    starts = offsets[:-1][blk]
    base = np.where(starts > 0, cum[np.maximum(starts - 1, 0)], 0)
    idx = cum - base
    if idx.size and (idx.max() >= BLOCK_PIXELS):
        raise ValueError("corrupt visibility stream")
    vals = _unzigzag(rest[T:]).astype(np.int16) if grey else None
    return DiffVisibility(n, kind, offsets, idx.astype(np.uint8), vals, levels)


# --------------------------------------------------------------------------- lighting

@dataclass(frozen=True)
class BlockLighting:
    """The three per-block representations of §4.3 (float64).

    ``pixel`` (blocks, 256, 3): ``L_k dw_k`` with the block rows concatenated;
    ``integral`` (blocks, 256, 3): eq. 6, ``D^{-T}`` of ``pixel`` (suffix sums);
    ``dct`` (blocks, 16, 3): coefficients on :func:`dct_basis` (order :data:`DCT_ORDER`).
    """

    resolution: int
    pixel: np.ndarray
    integral: np.ndarray
    dct: np.ndarray

    @property
    def blocks(self) -> int:
        return self.pixel.shape[0]


def block_lighting(radiance, resolution: int) -> BlockLighting:
    """Per-block lighting from cubemap radiance (D, 3) (or a ``CubeLighting``)."""
    rad = getattr(radiance, "radiance", radiance)
    rad = np.asarray(rad, dtype=np.float64)
    if rad.ndim == 1:
        rad = rad[:, None]
    cube = cubemap(int(resolution))
    if rad.shape[0] != cube.size:
        raise ValueError("radiance does not match the cubemap resolution")
    pix = to_blocks(rad * cube.solid_angles[:, None], resolution)            # (nb, 256, C)
    integral = np.cumsum(pix[:, ::-1], axis=1)[:, ::-1]                      # suffix sums
    dct = np.einsum("kp,bpc->bkc", dct_basis(), pix)
    for a in (pix, integral, dct):
        a.setflags(write=False)
    return BlockLighting(int(resolution), pix, np.ascontiguousarray(integral), dct)


def _sparse_dot(table: np.ndarray, dv: DiffVisibility, rows: np.ndarray) -> np.ndarray:
    """sum_k table[r, idx_k] V_d[idx_k] / levels over the stored entries of blocks ``rows``
    of a one-vertex ``dv``; ``table`` is (len(rows), 256, C).  -> (len(rows), C)."""
    nb = dv.blocks
    where = np.full(nb, -1, dtype=np.int64)
    where[rows] = np.arange(rows.size)
    blk = dv.entry_blocks()
    r = where[blk]
    sel = r >= 0
    r = r[sel]
    w = dv.entry_values()[sel].astype(np.float64) / dv.levels
    contrib = table[r, dv.indices[sel].astype(np.int64)] * w[:, None]
    out = np.zeros((rows.size, table.shape[2]))
    for c in range(table.shape[2]):
        out[:, c] = np.bincount(r, weights=contrib[:, c], minlength=rows.size)
    return out


def light_vis_product(light: BlockLighting, dv: DiffVisibility) -> np.ndarray:
    """Alg. 1 line 9 without the BRDF: ``L_int . V_d`` per block of a one-vertex ``dv``,
    (blocks, 3) = sum_k L_k V_k dw_k over the block."""
    kind = dv.kind[0]
    out = np.zeros((light.blocks, light.pixel.shape[2]))
    one = kind == ONE
    out[one] = light.integral[one, 0]
    mixed = np.nonzero(kind == MIXED)[0]
    out[mixed] = _sparse_dot(light.integral[mixed], dv, mixed)
    return out


# --------------------------------------------------------------------------- BRDF

def as_sampler(rho):
    """A BRDF x cos sampler ``f(flat texel indices) -> (k, C)``; arrays (D, C) are indexed."""
    if callable(rho):
        return rho
    arr = np.asarray(rho, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    return lambda texels: arr[texels]


def material_sampler(material, normal, view, resolution: int, directions=None):
    """Sampler of :func:`.brdf.reflectance_cosine` for one vertex at the texel
    directions (texel centres unless ``directions`` (D, 3) is given)."""
    from .brdf import reflectance_cosine
    dirs = cubemap(int(resolution)).directions if directions is None else np.asarray(directions)
    n = np.asarray(normal, dtype=np.float64).reshape(1, 3)
    v = np.asarray(view, dtype=np.float64).reshape(1, 3)

    def f(texels):
        return reflectance_cosine(material, n, v, dirs[np.asarray(texels).reshape(-1)])[0].astype(np.float64)
    return f


def highlight_blocks(directions, resolution: int, angle: float = 0.0) -> np.ndarray:
    """(blocks,) bool: blocks holding the texel of any of ``directions`` (k, 3) or a
    texel centre within ``angle`` radians of one -- the "vicinity of a highlight"
    (e.g. the mirror direction of the view) whose sampling §4.1 / Appendix A raise.
    Pass it as ``force_pixel`` so narrow lobes between the check samples are not missed."""
    d = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
    n = int(resolution)
    mask = np.zeros(block_count(n), dtype=bool)
    mask[texel_to_block(cubemap(n).texel_index(d), n)[0]] = True
    if angle > 0.0:
        cosines = to_blocks(cubemap(n).directions, n) @ d.T          # (nb, 256, k)
        mask |= (cosines >= np.cos(angle)).any(axis=(1, 2))
    return mask


def project_brdf(rho, blocks: np.ndarray, resolution: int, mode="adaptive",
                 rel_tol: float = 0.02, abs_tol: float | None = None, abs_rel_tol: float = 1e-3,
                 force_pixel=None):
    """ProjectBRDF (Alg. 1 line 4) for ``blocks`` -> (levels (m,), coeffs (m, 16, C), pixels).

    ``levels[i]`` is 1, 4, 16 or 256 (:data:`BRDF_LEVELS`); ``coeffs[i, :levels]``
    are the DCT coefficients when ``levels < 256``; ``pixels`` (m, 256, C) holds the
    full samples of pixel-basis blocks (zeros elsewhere).  ``mode``: "adaptive"
    (the rule of the module docstring), "pixel" (every block 256 samples) or a
    fixed 1 / 4 / 16.  ``force_pixel`` (blocks,) bool (see :func:`highlight_blocks`)
    sends those blocks to the pixel basis in adaptive mode."""
    f = as_sampler(rho)
    blocks = np.asarray(blocks, dtype=np.int64)
    m = blocks.size
    perm = block_permutation(resolution)

    def sample(pix):                       # (m, k) block pixel idx -> (m, k, C)
        t = perm[blocks[:, None], pix[None, :] if pix.ndim == 1 else pix].reshape(-1)
        s = np.asarray(f(t), dtype=np.float64)
        return s.reshape(m, -1, s.shape[-1] if s.ndim > 1 else 1)

    if m == 0:
        C = np.asarray(f(np.zeros(1, dtype=np.int64))).reshape(1, -1).shape[1]
        return np.zeros(0, np.int64), np.zeros((0, 16, C)), np.zeros((0, BLOCK_PIXELS, C))
    if mode == "pixel" or mode == PIXEL:
        px = sample(np.arange(BLOCK_PIXELS))
        C = px.shape[2]
        return np.full(m, PIXEL, dtype=np.int64), np.zeros((m, 16, C)), px
    fixed = {1: 1, 4: 2, 16: 4}
    if mode != "adaptive" and mode not in fixed:
        raise ValueError("mode must be 'adaptive', 'pixel', 1, 4 or 16")
    ls = (1, 2, 4) if mode == "adaptive" else (fixed[mode],)
    fits = {}
    for l in ls:
        pix, inv = projection_system(l)
        fits[l] = np.einsum("ij,mjc->mic", inv, sample(pix))        # (m, l*l, C)
    C = next(iter(fits.values())).shape[2]
    coeffs = np.zeros((m, 16, C))
    levels = np.full(m, PIXEL, dtype=np.int64)
    if mode != "adaptive":
        l = ls[0]
        coeffs[:, :l * l] = fits[l]
        levels[:] = l * l
        return levels, coeffs, np.zeros((m, BLOCK_PIXELS, C))
    check = sample(CHECK_PIXELS)                                      # (m, 25, C)
    scale = np.abs(check).max(axis=(1, 2))
    if abs_tol is None:
        abs_tol = abs_rel_tol * float(scale.max())
    thresh = rel_tol * scale + abs_tol
    undecided = np.ones(m, dtype=bool)
    phi_check = dct_basis()[:, CHECK_PIXELS]                          # (16, 25)
    for l in ls:
        k = l * l
        recon = np.einsum("mkc,kp->mpc", fits[l], phi_check[:k])
        ok = undecided & (np.abs(recon - check).max(axis=(1, 2)) <= thresh)
        coeffs[ok, :k] = fits[l][ok]
        levels[ok] = k
        undecided &= ~ok
    if force_pixel is not None:
        forced = np.asarray(force_pixel, dtype=bool)[blocks]
        coeffs[forced] = 0.0
        levels[forced] = PIXEL
        undecided |= forced
    pixels = np.zeros((m, BLOCK_PIXELS, C))
    rest = np.nonzero(undecided)[0]
    if rest.size:
        t = perm[blocks[rest]].reshape(-1)
        s = np.asarray(f(t), dtype=np.float64)
        pixels[rest] = s.reshape(rest.size, BLOCK_PIXELS, -1)
    return levels, coeffs, pixels


# --------------------------------------------------------------------------- Algorithm 1

@dataclass
class BlockIntegral:
    """Result of :func:`integrate_vertex`: ``radiance`` (C,), per block ``values``
    (blocks, C), ``cases`` (blocks,) int8 (CASE_*), ``levels`` (blocks,) BRDF
    coefficients used (0 where never sampled)."""

    radiance: np.ndarray
    values: np.ndarray
    cases: np.ndarray
    levels: np.ndarray

    def case_counts(self) -> dict:
        return {name: int((self.cases == i).sum()) for i, name in enumerate(CASE_NAMES)}

    def level_counts(self) -> dict:
        return {lv: int((self.levels == lv).sum()) for lv in BRDF_LEVELS}


def integrate_blocks(dv: DiffVisibility, light: BlockLighting, rho, mode="adaptive",
                     rel_tol: float = 0.02, abs_tol: float | None = None,
                     abs_rel_tol: float = 1e-3, force_pixel=None):
    """Algorithm 1 for every block of one vertex (``dv`` with count 1), vectorized.

    ``rho``: BRDF x cos per flat texel, an array (D, C) or a sampler (:func:`as_sampler`).
    Returns (values (blocks, C), cases (blocks,), levels (blocks,))."""
    if dv.count != 1:
        raise ValueError("integrate_blocks takes one vertex (use dv.vertex(p))")
    if dv.resolution != light.resolution:
        raise ValueError("visibility and lighting resolutions differ")
    kind = dv.kind[0]
    nb = light.blocks
    C = light.pixel.shape[2]
    values = np.zeros((nb, C))
    cases = np.zeros(nb, dtype=np.int8)
    levels_all = np.zeros(nb, dtype=np.int64)
    active = np.nonzero(kind != ZERO)[0]                       # line 1
    if active.size == 0:
        return values, cases, levels_all
    levels, coeffs, pixels = project_brdf(rho, active, light.resolution, mode, rel_tol,
                                          abs_tol, abs_rel_tol, force_pixel)   # line 4
    if coeffs.shape[2] != C:
        if coeffs.shape[2] == 1:
            coeffs, pixels = (np.repeat(coeffs, C, axis=2), np.repeat(pixels, C, axis=2))
        else:
            raise ValueError("BRDF and lighting channel counts differ")
    levels_all[active] = levels
    one = kind[active] == ONE
    band = levels < PIXEL
    # line 6: Light-BRDF product, DCT (same orthonormal basis) or pixel basis.
    s = one & band
    if s.any():
        b = active[s]
        values[b] = np.einsum("mkc,mkc->mc", coeffs[s] * (np.arange(16) < levels[s][:, None])[:, :, None],
                              light.dct[b])
    s = one & ~band
    if s.any():
        b = active[s]
        values[b] = np.einsum("mpc,mpc->mc", pixels[s], light.pixel[b])
    cases[active[one]] = CASE_LIGHT_BRDF
    # line 9: constant BRDF: rho_1 * (L_int . V_d).
    s = ~one & (levels == 1)
    if s.any():
        b = active[s]
        rho1 = coeffs[s, 0] * dct_basis()[0, 0]                      # A_00 / 16
        values[b] = rho1 * _sparse_dot(light.integral[b], dv, b)
        cases[b] = CASE_LIGHT_VIS
    # line 11: decompress-integrate in the pixel basis.
    s = ~one & (levels > 1)
    if s.any():
        b = active[s]
        rpix = np.where((levels[s] == PIXEL)[:, None, None], pixels[s],
                        np.einsum("mkc,kp->mpc", coeffs[s], dct_basis()))
        prod = light.pixel[b] * rpix
        values[b] = _sparse_dot(np.cumsum(prod[:, ::-1], axis=1)[:, ::-1], dv, b)
        cases[b] = CASE_TRIPLE
    return values, cases, levels_all


def integrate_vertex(dv: DiffVisibility, light: BlockLighting, rho, mode="adaptive",
                     rel_tol: float = 0.02, abs_tol: float | None = None,
                     abs_rel_tol: float = 1e-3, force_pixel=None) -> BlockIntegral:
    """B = sum over blocks of Algorithm 1 for one vertex (see :func:`integrate_blocks`)."""
    values, cases, levels = integrate_blocks(dv, light, rho, mode, rel_tol, abs_tol, abs_rel_tol,
                                             force_pixel)
    return BlockIntegral(values.sum(axis=0), values, cases, levels)


# --------------------------------------------------------------------------- batched evaluator
#
# The per-vertex :func:`integrate_vertex` above is the readable statement of
# Algorithm 1; what follows evaluates the same cases for many vertices at once
# (numpy over every active (vertex, block) pair of a chunk of vertices; the
# per-level batches and pixel-basis groups shared out to threads -- numpy releases
# the GIL in its array passes).  The BRDF x cos of a material
# (:mod:`.brdf`) is sampled per vertex for the current view at the pixels each
# block's representation needs.
#
# Split of the integrand (what REFERENCE, :func:`.reference.shade_points`, sums):
#
#   B = albedo/pi * W(n, wo) * E  +  G,    E = sum_k L_k V_k max(0, n.w_k) dw_k
#
# * Lambert layer (view independent): in every block the cosine is *linear* in
#   the direction, ``n . w``, so the block integral is ``n . (sum_k L~_k w_k V_k)``
#   -- three Light-Vis products (Alg. 1 line 9, eq. 6: suffix sums of ``L~ w``
#   dotted with ``V_d`` over the change indices; constant-1 blocks read the
#   block total).  Exact (no per-block constant approximation of the cosine:
#   visibility is 0 below the horizon, so the clamp never acts on a visible
#   texel), computed once per lighting and cached like REFERENCE's irradiance.
# * Glossy layer (view dependent, per frame): Algorithm 1 per block with
#   ``rho~ = f_s cos``; the representation (1 / 4 / 16 DCT coefficients or 256
#   pixels) comes from an analytic rule in the spirit of Appendix A
#   (:func:`glossy_levels`): how far the block is from the lobe, measured by the
#   NDF at the block's closest half-vector relative to its peak.
#   Level 1 (constant) blocks of both line 6 and line 9 are ``rho_1 * S_b`` with
#   ``S_b = L_int . V_d`` (line 9's light-vis product, = the block's visible light
#   for constant-1 blocks), cached per lighting; 4/16: eq. 4 fit, lines 6 and 11 as
#   the dot product of the BRDF's coefficients with ``V_d . H_b`` -- the visible
#   light projected on the DCT functions, a sum over the change indices of the
#   suffix sums of ``H_b[p, k] = Phi_k(p) L~_p`` (eq. 6 applied to the DCT
#   lighting: line 11's triple product without decompressing the block; a
#   constant-1 block reads the total, the lighting's DCT); pixel: every pixel,
#   ``(rho * V) @ L~_b`` with the block decompressed (occluded pixels times 0).
#
# Speed (numpy on 2 shared cores, where the passes over (pairs x 256) arrays are
# bound by memory bandwidth): pixel-basis groups are evaluated 1024 pairs at a
# time with the Beckmann lobe's sums folded into matrix products
# (:meth:`GlossyLobe._beckmann_shared`), and pairs whose block is wholly above the
# lobe's horizon_cos skip the per-sample horizon and grazing-light checks.

import os as _os
import threading as _threading
import time as _time
from concurrent.futures import ThreadPoolExecutor as _Pool

from . import brdf as _brdf

_DECODE_LOCK = _threading.Lock()

#: Default rule thresholds on q = D(closest half-vector) / D(peak) (see glossy_levels).
DEFAULT_LEVEL_THRESHOLDS = (1e-2, 1e-3, 1e-4, 1e-9)


@dataclass(frozen=True)
class BlockGeometry:
    """Per-resolution block constants: unit texel directions in block order
    (blocks, 256, 3), block centre directions (blocks, 3), angular radius (blocks,)
    of each block around its centre (texel centres plus one texel diagonal)."""

    resolution: int
    texel_dirs: np.ndarray
    centre: np.ndarray
    radius: np.ndarray

    @property
    def radius32(self) -> np.ndarray:
        return self.radius.astype(np.float32)


@memo(4)
def block_geometry(resolution: int) -> BlockGeometry:
    n = int(resolution)
    d = to_blocks(cubemap(n).directions, n)
    c = d.mean(axis=1)
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    cosines = np.clip(np.einsum("bkc,bc->bk", d, c), -1.0, 1.0)
    radius = np.arccos(cosines.min(axis=1)) + np.sqrt(2.0) * 2.0 / n
    for a in (d, c, radius):
        a.setflags(write=False)
    return BlockGeometry(n, d, c, radius)


@dataclass
class ActivePairs:
    """The (vertex, block) pairs of a :class:`DiffVisibility` whose visibility is
    not constant 0 (Alg. 1 line 1 decided once, view independent), vertex-major.

    ``first`` (P+1,) offsets of each vertex's pairs; ``entry_start``/``entry_count``
    the stored change indices of each pair in ``dv.indices`` (0 for constant-1)."""

    dv: DiffVisibility
    p: np.ndarray
    b: np.ndarray
    one: np.ndarray
    entry_start: np.ndarray
    entry_count: np.ndarray
    first: np.ndarray

    @property
    def count(self) -> int:
        return self.p.size

    def decoded_bits(self):
        """Binary maps only: every mixed pair's block decoded once (§4.4's scatter and
        running sum) and kept bit-packed, (mixed pairs, 32) uint8, with the row of each
        pair (-1: not mixed).  Frames that only move the camera then unpack bits instead
        of decoding the differential stream again; 32 bytes per mixed pair (the bunny
        at 6x64^2: ~20 MB).  None for quantized (grey) visibility."""
        if self.dv.values is not None:
            return None
        cache = self.__dict__.get("_decoded")
        if cache is None:
            with _DECODE_LOCK:
                cache = self.__dict__.get("_decoded")
                if cache is None:
                    mixed = np.nonzero(~self.one)[0]
                    row_of = np.full(self.count, -1, dtype=np.int64)
                    row_of[mixed] = np.arange(mixed.size)
                    bits = np.empty((mixed.size, BLOCK_PIXELS // 8), dtype=np.uint8)
                    for a in range(0, mixed.size, 65536):
                        sel = mixed[a:a + 65536]
                        bits[a:a + sel.size] = np.packbits(
                            _decode_mixed(self, sel, np.float32) > 0.5, axis=1)
                    cache = self.__dict__["_decoded"] = (bits, row_of)
        return cache


def active_pairs(dv: DiffVisibility) -> ActivePairs:
    nb = dv.blocks
    kind = dv.kind.reshape(-1)
    flat = np.nonzero(kind != ZERO)[0]
    p = (flat // nb).astype(np.int64)
    b = (flat % nb).astype(np.int64)
    first = np.searchsorted(p, np.arange(dv.count + 1))
    return ActivePairs(dv, p, b, kind[flat] == ONE, dv.offsets[flat],
                       dv.offsets[flat + 1] - dv.offsets[flat], first.astype(np.int64))


def _entries(pairs: ActivePairs, sel: np.ndarray):
    """Stored change entries of pairs ``sel``: (row in sel, entry index into dv arrays)."""
    counts = pairs.entry_count[sel]
    total = int(counts.sum())
    row = np.repeat(np.arange(sel.size), counts)
    csum = np.cumsum(counts) - counts
    ent = pairs.entry_start[sel][row] + (np.arange(total) - csum[row])
    return row, ent


def _entry_weights(pairs: ActivePairs, sel: np.ndarray, row: np.ndarray, ent: np.ndarray):
    """``V_d / levels`` at entries ``ent`` of pairs ``sel[row]`` (binary: +1, -1, ...
    by position inside the block)."""
    dv = pairs.dv
    if dv.values is not None:
        return dv.values[ent].astype(np.float64) / dv.levels
    pos = ent - pairs.entry_start[sel][row]
    return (1 - 2 * (pos & 1)).astype(np.float64)


def _decode_mixed(pairs: ActivePairs, sel: np.ndarray, dtype) -> np.ndarray:
    """Dense visibility (len(sel), 256) of non-constant pairs ``sel``: the change
    indices scattered and summed along the concatenated rows (§4.4)."""
    row, ent = _entries(pairs, sel)
    w = _entry_weights(pairs, sel, row, ent)
    acc = np.zeros((sel.size, BLOCK_PIXELS), dtype=dtype)
    acc[row, pairs.dv.indices[ent].astype(np.int64)] = w         # indices unique per block
    np.cumsum(acc, axis=1, out=acc)
    return acc


def _decompress(pairs: ActivePairs, sel: np.ndarray, dtype=np.float64,
                cached: bool = True) -> np.ndarray:
    """Dense visibility (len(sel), 256) in [0, 1] of pairs ``sel``: constant-1 blocks
    filled, mixed ones decoded (binary maps: from :meth:`ActivePairs.decoded_bits`
    unless ``cached`` is False)."""
    out = np.zeros((sel.size, BLOCK_PIXELS), dtype=dtype)
    one = pairs.one[sel]
    out[one] = 1.0
    mixed = np.nonzero(~one)[0]
    if mixed.size:
        decoded = pairs.decoded_bits() if cached else None
        if decoded is None:
            out[mixed] = _decode_mixed(pairs, sel[mixed], dtype)
        else:
            bits, row_of = decoded
            out[mixed] = np.unpackbits(bits[row_of[sel[mixed]]], axis=1)
    return out


@dataclass(frozen=True)
class LightTables:
    """Per-block lighting for the batched evaluator (§4.3 plus the Lambert moments).

    ``pixel`` (blocks, 256, 3) ``L~``; ``dct`` (blocks, 16, 3); ``integral12``
    (blocks, 256, 12): eq. 6 suffix sums of ``[L~, L~ w_x, L~ w_y, L~ w_z]`` (w: the
    lighting's mean direction vector per texel, as REFERENCE's diffuse cosine);
    ``unit_dirs`` (blocks, 256, 3) unit directions REFERENCE samples the glossy
    lobe at; ``dct_suffix`` (blocks, 256, 48): eq. 6 suffix sums of
    ``H_b[p, k, c] = Phi_k(p) L~_pc`` (the lighting's product with the 16 DCT
    functions, :data:`DCT_ORDER`, column ``3 k + c``), so that ``V_d . H_b`` of a
    stored differential visibility is a sum over its change indices only."""

    resolution: int
    pixel: np.ndarray
    dct: np.ndarray
    integral12: np.ndarray
    unit_dirs: np.ndarray
    mean_dirs: np.ndarray
    pixel32: np.ndarray = None
    dct_suffix: np.ndarray = None
    unit_dirs32: np.ndarray = None
    integral12_t: np.ndarray = None        # (12, blocks, 256): the same, channel-major

    def dct_suffix_of(self, k: int, dtype=np.float32) -> np.ndarray:
        """:attr:`dct_suffix` for the first ``k`` DCT functions, (blocks, 256, 3k)
        contiguous (cached per ``k`` and dtype)."""
        cache = self.__dict__.setdefault("_suffix_cache", {})
        key = (k, np.dtype(dtype).str)
        if key not in cache:
            cache[key] = np.ascontiguousarray(self.dct_suffix[:, :, :3 * k], dtype=dtype)
        return cache[key]


def light_tables(lighting, resolution: int) -> LightTables:
    """:class:`LightTables` of a :class:`.envmap.CubeLighting` (radiance + directions)."""
    n = int(resolution)
    cube = cubemap(n)
    rad = np.asarray(lighting.radiance, dtype=np.float64)
    if rad.shape != (cube.size, 3):
        raise ValueError("lighting does not match the cubemap resolution")
    if not np.isfinite(rad).all():
        raise ValueError("lighting has NaN/Inf radiance")
    mean_dirs = np.asarray(lighting.directions, dtype=np.float64)
    unit = mean_dirs / np.maximum(np.linalg.norm(mean_dirs, axis=1, keepdims=True), 1e-30)
    pix = to_blocks(rad * cube.solid_angles[:, None], n)
    mb = to_blocks(mean_dirs, n)
    t12 = np.concatenate([pix, (pix[:, :, :, None] * mb[:, :, None, :]).reshape(pix.shape[0], BLOCK_PIXELS, 9)],
                         axis=2)
    integral12 = np.ascontiguousarray(np.cumsum(t12[:, ::-1], axis=1)[:, ::-1])
    integral12_t = np.ascontiguousarray(np.moveaxis(integral12, 2, 0))
    dct = np.einsum("kp,bpc->bkc", dct_basis(), pix)
    # H_b[p, k, c] = Phi_k(p) L~_pc: V . H_b projects the visible light on the DCT
    # functions; its suffix sums along the pixels make that product eq. 6's sum over
    # the change indices
    dct_light = (dct_basis().T[None, :, :, None] * pix[:, :, None, :]).reshape(
        pix.shape[0], BLOCK_PIXELS, 48)
    dct_suffix = np.ascontiguousarray(np.cumsum(dct_light[:, ::-1], axis=1)[:, ::-1])
    ub = to_blocks(unit, n)
    return LightTables(n, pix, dct, integral12, ub, mb, pix.astype(np.float32),
                       dct_suffix, ub.astype(np.float32), integral12_t)


@dataclass
class LightVis:
    """Line-9 products of one lighting: ``S`` (pairs, 3) float32, the visible light
    ``L_int . V_d`` of every active pair (for constant-1 blocks the block total), and
    ``moment`` (P, 3, 3): per vertex ``sum_k L~_k w_k V_k`` (colour x direction),
    whose product with the normal is the Lambert irradiance."""

    S: np.ndarray
    moment: np.ndarray

    @property
    def nbytes(self) -> int:
        return int(self.S.nbytes + self.moment.nbytes)


def light_vis_sums(pairs: ActivePairs, tables: LightTables, chunk: int = 1 << 16) -> LightVis:
    """Alg. 1 line 9's light-vis product ``L_int . V_d`` (eq. 6, a sum over the stored
    change indices only) of ``[L~, L~ w_x, L~ w_y, L~ w_z]`` for every active pair."""
    P = pairs.dv.count
    table = tables.integral12_t                          # (12, blocks, 256)
    vals = np.empty((12, pairs.count))
    one = np.nonzero(pairs.one)[0]
    vals[:, one] = table[:, pairs.b[one], 0]
    mixed_all = np.nonzero(~pairs.one)[0]
    for a in range(0, mixed_all.size, chunk):
        mixed = mixed_all[a:a + chunk]       # every mixed pair has >= 1 entry
        row, ent = _entries(pairs, mixed)
        w = _entry_weights(pairs, mixed, row, ent)
        flat = pairs.b[mixed][row] * BLOCK_PIXELS + pairs.dv.indices[ent]
        e = np.take(table.reshape(12, -1), flat, axis=1)            # (12, E), C order
        e *= w
        vals[:, mixed] = _segment_sums(e, pairs.entry_count[mixed])
    S = np.ascontiguousarray(vals[:3].T, dtype=np.float32)
    # per vertex: pairs are vertex-major, pairs.first delimits each vertex's run
    moment = _segment_sums(vals[3:], np.diff(pairs.first)).T
    return LightVis(S, moment.reshape(P, 3, 3))


def _segment_sums(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Sums of consecutive runs along the *last* axis of ``values`` (C, E) (run i has
    ``counts[i]`` elements, may be 0) -> (C, len(counts)), via one cumulative sum along
    the contiguous axis (much faster than ``reduceat``/``cumsum`` along a strided one)."""
    out = np.zeros(values.shape[:-1] + (counts.size,))
    if values.shape[-1] == 0:
        return out
    cs = np.cumsum(values, axis=-1)
    ends = np.cumsum(counts)
    has = counts > 0
    out[..., has] = cs[..., ends[has] - 1]
    prev = ends - counts - 1
    later = has & (prev >= 0)
    out[..., later] -= cs[..., prev[later]]
    return out


def dct_light_vis(pairs: ActivePairs, tables: LightTables, sel: np.ndarray, k: int,
                  dtype=np.float32) -> np.ndarray:
    """``V_d . H_b`` for the first ``k`` DCT functions of pairs ``sel``, (len(sel), k, 3):
    the visible light projected on the block's DCT functions (Alg. 1 lines 6/11 with
    ``k`` coefficients), as eq. 6 does for line 9 -- a sum over the stored change
    indices of the lighting's suffix sums (:attr:`LightTables.dct_suffix`), so that
    the block is never decompressed; a constant-1 block takes the total."""
    sel = np.asarray(sel, dtype=np.int64)
    suffix = tables.dct_suffix_of(k, dtype)               # (blocks, 256, 3k)
    out = np.empty((sel.size, 3 * k), dtype=dtype)
    one = pairs.one[sel]
    at = np.nonzero(one)[0]
    out[at] = suffix[pairs.b[sel[at]], 0]
    at = np.nonzero(~one)[0]
    if at.size:
        # entry j of every pair with more than j entries, pairs by decreasing count so
        # that those are a prefix: one gather and one add per entry position
        mixed = sel[at]
        count = pairs.entry_count[mixed]
        order = np.argsort(-count, kind="stable")
        mixed, count = mixed[order], count[order]
        start = pairs.entry_start[mixed]
        base = pairs.b[mixed] * BLOCK_PIXELS
        flat = suffix.reshape(-1, 3 * k)
        indices, values = pairs.dv.indices, pairs.dv.values
        acc = np.zeros((mixed.size, 3 * k), dtype=dtype)
        active = np.searchsorted(-count, -np.arange(1, int(count[0]) + 1), side="right")
        for j, n in enumerate(active.tolist()):           # n pairs have > j entries
            ent = start[:n] + j
            term = flat[base[:n] + indices[ent]]
            if values is None:                            # binary: +1, -1, +1, ...
                if j & 1:
                    acc[:n] -= term
                else:
                    acc[:n] += term
            else:
                term *= (values[ent] / pairs.dv.levels).astype(dtype)[:, None]
                acc[:n] += term
        out[at[order]] = acc
    return out.reshape(sel.size, k, 3)


def lambert_irradiance(light_vis: LightVis, normals: np.ndarray) -> np.ndarray:
    """E = n . sum_k L~_k w_k V_k per vertex (P, 3): the Lambert layer's integral
    (REFERENCE's ``diffuse_irradiance``), exact because the cosine is linear in w."""
    n = np.asarray(normals, dtype=np.float64)
    return np.einsum("pcd,pd->pc", light_vis.moment, n)


def _beckmann_grazing_cos(a2) -> float:
    """``cos_i`` above which Beckmann's ``Lambda_i`` is 0 (``a2 tan^2(theta_i) < 0.39``),
    with a margin of 0.1 % for float32 rounding."""
    return float(np.sqrt(float(a2) / (float(a2) + 0.39) * 1.001))


def _beckmann_grazing(val, cos_i, a2, lam_o, lowest):
    """Beckmann's ``G2``: ``val`` computed with ``Lambda_i = 0`` gets
    ``(1 + Lambda_o) / (1 + Lambda_o + Lambda_i)`` where the light is grazing enough for
    ``Lambda_i > 0`` (``a2 tan^2(theta_i) >= 0.39``), in place.  ``lowest``: the
    smallest ``cos_i`` (a float: nothing to do above the cut), or per row of a 2-D
    ``cos_i`` (only the rows that reach below the cut are looked at)."""
    f32 = np.float32
    one = f32(1.0)
    top = f32(_beckmann_grazing_cos(a2))
    shape = np.shape(cos_i)
    if np.ndim(lowest):
        rows = np.flatnonzero(lowest <= top)
        if not rows.size:
            return
        sub = cos_i[rows]
        g = np.flatnonzero((sub <= top) & (sub > 0.0))    # below the horizon: zeroed anyway
        at = (rows[g // shape[1]], g % shape[1])
        g = at[0] * shape[1] + at[1]
    elif lowest > top:
        return
    else:
        ci = np.asarray(cos_i)
        g = np.flatnonzero((ci <= top) & (ci > 0.0))
        at = np.unravel_index(g, shape)
    if g.size:
        ci = np.asarray(cos_i)[at]
        lg = _brdf.lambda_of_t2("BECKMANN", a2 * np.maximum(one / (ci * ci) - one, f32(0.0)))
        lo = np.broadcast_to(lam_o, shape)[at]
        val.reshape(-1)[g] *= (one + lo) / (one + lo + lg)


def microfacet_lobe(distribution: str, a2, cos_i, dot_io, cos_o, lam_o, want_h: bool = True,
                    split: bool = False):
    """``D(h) G2 / (4 cos_o)`` and ``h.wi`` from cosines, float32 -- the formulas of
    :func:`.brdf.microfacet_D`, :func:`.brdf.smith_lambda` and ``brdf._specular_terms``
    (Cycles' ``bsdf_microfacet_eval``) written for float32 arrays of any shape
    (``cos_o``/``lam_o`` broadcast; float64 inputs are computed in float64).
    Zero where ``cos_i <= 0``.  Grazing directions overflow to inf on purpose
    (``G2 -> 0``): callers hold ``np.errstate`` (see :func:`glossy_blocks`).

    ``split``: return ``(val, h, k)`` with the per-vertex factor ``k`` (shape of
    ``cos_o``) left out of ``val`` (the lobe is ``val * k``), so that a caller
    summing ``val`` against the lighting applies it once per vertex; ``k`` is None
    when the distribution has no such factor (GGX: already in ``val``).  ``val`` and
    ``dot_io`` may be overwritten (pass copies to keep them)."""
    f32 = np.float32
    one = f32(1.0)
    floor = f32(_brdf._HALF_LEN2_FLOOR)
    # Nothing is below the horizon (every direction has cos_i > 0, so wi != -wo as cos_o
    # > 0) for most blocks: one minimum spares the masks below.
    lowest = float(cos_i.min()) if np.size(cos_i) else 1.0
    vertex_factor = None
    h = np.sqrt(np.clip(f32(0.5) * (one + dot_io), f32(0.0), one)) if want_h else None
    if distribution == "BECKMANN":
        # D = exp(-tan^2 / a2) / (pi a2 cos^4); G2 = 1 / (1 + Lambda_i + Lambda_o), and
        # Lambda_i = 0 unless t2 = a2 tan^2(theta_i) >= 0.39 (grazing light): the
        # per-vertex part 1 / (pi a2 4 cos_o (1 + Lambda_o)) is one factor, the grazing
        # directions get (1 + Lambda_o) / (1 + Lambda_o + Lambda_i) afterwards.
        # With r = 1 / cos_h^2 = |wo + wi|^2 / (cos_i + cos_o)^2 (clamped to [1, 1e30]):
        # D G2 / (4 cos_o) = exp((1 - r) / a2) r^2 / (pi a2 4 cos_o (1 + Lambda_o)).
        r = np.multiply(dot_io, f32(2.0), out=dot_io if np.ndim(dot_io) else None)
        r += f32(2.0)                               # |wo + wi|^2
        degenerate = None
        if lowest <= 0.0 and r.size and r.min() <= floor:   # wi = -wo: no half-vector
            degenerate = r <= floor
        c = cos_i + cos_o
        c *= c
        r /= c
        np.clip(r, one, f32(1e30), out=r)
        val = np.subtract(one, r)
        val *= one / a2
        np.exp(val, out=val)
        r *= r
        val *= r
        vertex_factor = one / ((f32(np.pi) * a2) * f32(4.0) * cos_o * (one + lam_o))
        _beckmann_grazing(val, cos_i, a2, lam_o, lowest)
        if not split:
            val *= vertex_factor
        if degenerate is not None:
            val[degenerate] = 0.0
    else:
        len2 = dot_io * f32(2.0)
        len2 += f32(2.0)
        degenerate = None
        if lowest <= 0.0 and len2.size and len2.min() <= floor:
            degenerate = len2 <= floor
            np.maximum(len2, floor, out=len2)
        c = cos_i + cos_o
        c *= c
        c /= len2                                   # cos_h^2
        np.minimum(c, one, out=c)
        den = one - c + a2 * c
        val = a2 / (f32(np.pi) * den * den)
        ci = np.clip(cos_i, f32(1e-12), one)
        lam = _brdf.lambda_of_t2("GGX", a2 * np.maximum(one / (ci * ci) - one, f32(0.0)))
        lam += one + lam_o
        lam *= f32(4.0) * cos_o
        val /= lam
        if degenerate is not None:
            val[degenerate] = 0.0
    if lowest <= 0.0:
        val[cos_i <= 0.0] = 0.0
    if split:
        return val, h, vertex_factor
    return val, h


# half-vector angles of a lobe's thresholds per (distribution, alpha, thresholds)
_ANGLE_CACHE = Cache(64)


class GlossyLobe:
    """The glossy part of a :class:`.brdf.Material` as separable terms, sampled at
    *paired* (vertex, direction) samples -- the same formulas as
    :func:`.brdf.specular_terms` (REFERENCE), which evaluates all pairs of a point
    set and a direction set.  ``prepare(normals, views)`` fixes the vertices."""

    def __init__(self, material, dtype=np.float32):
        self.material = material
        self.dtype = np.dtype(dtype).type
        self.distribution = material.lobe_distribution
        self.alpha = material.alpha

    def prepare(self, normals, views):
        m = self.material
        n = _brdf._unit_rows(normals, "normals")
        v = _brdf._unit_rows(views, "views")
        v, cos_o = _brdf._bend_views(n, v)
        self.n, self.v, self.cos_o = n, v, cos_o
        self.lam_o = _brdf.smith_lambda(self.distribution, self.alpha, cos_o)
        col = np.asarray(m.specular_color, dtype=np.float64)
        terms = []                 # (factor kind, per-vertex weight (P, 3))
        fres = m.fresnel

        def f82(f0, tint, weight):
            f0 = np.clip(np.asarray(f0, dtype=np.float64), 0.0, 1.0)
            B = _brdf._metal_B(f0, tint)
            if not np.any(B):
                terms.append(("one", weight * f0[None, :]))
                terms.append(("schlick5", weight * (1.0 - f0)[None, :]))
                return
            for c in range(3):
                onehot = np.zeros_like(weight)
                onehot[:, c] = weight[:, c]
                terms.append((("f82", float(f0[c]), float(B[c])), onehot))

        if fres == "NONE":
            terms.append(("one", _brdf.multiscatter_factor(m, cos_o) * col[None, :]))
        elif fres == "SCHLICK":
            k = _brdf.multiscatter_factor(m, cos_o)
            terms.append(("one", k * col[None, :]))
            terms.append(("schlick5", k * (1.0 - col)[None, :]))
        elif fres == "F82":
            f82(col, m.f82_tint, _brdf.multiscatter_factor(m, cos_o))
        else:
            if m.metallic > 0.0:
                f82(m.diffuse_albedo, m.f82_tint,
                    m.metallic * _brdf.multiscatter_factor(m, cos_o, "metal"))
            if m._has_dielectric_lobe:
                f0 = np.clip(col, 0.0, 1.0)
                k = (1.0 - m.metallic) * _brdf.multiscatter_factor(m, cos_o)
                terms.append(("one", k * f0[None, :]))
                terms.append(("diel", k * (1.0 - f0)[None, :]))
        dt = self.dtype
        self.terms = [(k, np.asarray(w, dtype=dt)) for k, w in terms]
        self.a2 = dt(self.alpha) ** 2
        self.n32, self.v32 = n.astype(dt), v.astype(dt)
        self.cos_o32 = cos_o.astype(dt)
        self.lam_o32 = self.lam_o.astype(dt)
        # a scalar lobe: colour applied per vertex after the sums
        self.scalar = len(terms) == 1 and terms[0][0] == "one"
        self._fused = None
        if self.distribution == "BECKMANN" and dt is np.float32 and self.a2 >= 5e-5 \
                and self.cos_o32.size and float(self.cos_o32.min()) >= 0.5e-4:
            one = np.ones((n.shape[0], 1), dtype=dt)
            self._fused = (np.hstack([self.n32, self.cos_o32[:, None]]),
                           np.hstack([self.v32, one]) * (dt(2.0) / self.a2))
        return self

    def _terms_of(self, val, h, p):
        """[(factor (..., D), per-vertex weight rows (..., 3))] for lobe values ``val``."""
        out = []
        for kind, w in self.terms:
            if kind == "one":
                f = val
            elif kind == "schlick5":
                f = val * np.clip(np.float32(1.0) - h, 0.0, 1.0) ** 5
            elif kind == "diel":
                f = val * _brdf._dielectric_s(h, self.material.ior)
            else:
                f = val * _brdf.fresnel_f82(h, np.array([kind[1]]), np.array([kind[2]]))[..., 0]
            out.append((f.astype(self.dtype, copy=False), w[p]))
        return out

    def sample(self, p, d) -> np.ndarray:
        """Glossy BRDF x cos (M, 3) at paired samples (vertex ``p`` (M,), unit direction
        ``d`` (M, 3))."""
        d = np.asarray(d, dtype=self.dtype)
        cos_i = np.einsum("ij,ij->i", self.n32[p], d)
        dot_io = np.einsum("ij,ij->i", self.v32[p], d)
        val, h = microfacet_lobe(self.distribution, self.a2, cos_i, dot_io, self.cos_o32[p],
                                 self.lam_o32[p], not self.scalar)
        out = np.zeros((val.size, 3), dtype=self.dtype)
        for f, w in self._terms_of(val, h, p):
            out += f[:, None] * w
        return out

    def dense(self, p, d, edge: bool = True):
        """Terms at every (vertex ``p`` (k,), direction) combination, the directions
        shared ``d`` (D, 3) or per vertex ``d`` (k, D, 3): [(factor (k, D) float32,
        weight (k, 3))]; BRDF x cos = sum factor * weight (the per-vertex factor of
        the lobe is on the weights).  ``edge=False`` promises that every direction is
        well above every vertex's horizon (:meth:`horizon_cos` < every ``cos_i``), which
        spares the fused path its horizon and grazing-light checks."""
        d = np.asarray(d, dtype=self.dtype)
        if d.ndim == 2 and self._fused is not None:
            return self._beckmann_shared(p, d, edge)
        if d.ndim == 2:
            dt = np.ascontiguousarray(d.T)
            cos_i = self.n32[p] @ dt
            dot_io = self.v32[p] @ dt
        else:
            cos_i = np.einsum("kc,kjc->kj", self.n32[p], d)
            dot_io = np.einsum("kc,kjc->kj", self.v32[p], d)
        val, h, k = microfacet_lobe(self.distribution, self.a2, cos_i, dot_io,
                                    self.cos_o32[p][:, None], self.lam_o32[p][:, None],
                                    not self.scalar, split=True)
        terms = self._terms_of(val, h, p)
        if k is not None:                   # the per-vertex factor, on the (k, 3) weights
            terms = [(f, w * k) for f, w in terms]
        return terms

    def horizon_cos(self) -> float:
        """``cos_i`` below which a direction needs more than the lobe's main formula
        (Beckmann: the grazing-light ``Lambda_i``; every lobe: zero below the horizon)."""
        return _beckmann_grazing_cos(self.a2) if self.distribution == "BECKMANN" else 1.0

    def _beckmann_shared(self, p, d, edge=True):
        """:meth:`dense` for Beckmann in float32 against shared directions ``d`` (D, 3),
        with the additions folded into matrix products: ``[n, cos_o] . [d, 1]`` is
        ``cos_i + cos_o`` and ``[2 wo, 2] . [d, 1] / a2`` is ``|wo + wi|^2 / a2``, so
        ``r / a2 = |wo + wi|^2 / (a2 (cos_i + cos_o)^2)`` (``r = 1 / cos_h^2``) and
        ``D G2 / (4 cos_o) = exp(1/a2 - r/a2) (r/a2)^2 * a2 / (4 pi cos_o (1 + Lambda_o))``.
        Only for ``a2 >= 5e-5`` and views not below ``cos_o = 0.5e-4`` (:attr:`_fused`),
        where ``(r/a2)^2`` cannot overflow; float32 rounding of ``r`` moves the exponent
        by about ``3e-7 / a2``, as in the general path."""
        f32 = np.float32
        n4, v4 = self._fused
        dt = np.ascontiguousarray(d.T)
        d1 = np.vstack([dt, np.ones((1, dt.shape[1]), dtype=f32)])
        cos_i = self.n32[p] @ dt if edge else None
        c = n4[p] @ d1                                     # cos_i + cos_o
        r = v4[p] @ d1                                     # |wo + wi|^2 / a2
        h = None if self.scalar else np.sqrt(np.clip(r * (self.a2 / f32(4.0)), 0.0, 1.0))
        c *= c
        r /= c                                             # r / a2
        # |wo + wi| >= n.(wo + wi) = cos_i + cos_o >= cos_o where cos_i > 0, so r >= 1
        # holds in float32 unless cos_o is tiny (a bent grazing view, wi ~ -wo): clamp
        # those rows only (cos_i <= 0 is zeroed below)
        low = np.flatnonzero(self.cos_o32[p] < f32(0.05))
        if low.size:
            r[low] = np.maximum(r[low], f32(1.0) / self.a2)
        val = np.subtract(f32(1.0) / self.a2, r, out=c)   # c is not needed any more
        np.exp(val, out=val)
        r *= r
        val *= r
        if edge:
            lowest = cos_i.min(axis=1) if cos_i.size else np.ones(len(p), dtype=f32)
            _beckmann_grazing(val, cos_i, self.a2, self.lam_o32[p][:, None], lowest)
            rows = np.flatnonzero(lowest <= 0.0)
            if rows.size:                      # below the horizon (and wi = -wo: nan)
                g = np.flatnonzero(cos_i[rows] <= 0.0)
                val[rows[g // val.shape[1]], g % val.shape[1]] = 0.0
        k = self.a2 / (f32(4.0 * np.pi) * self.cos_o32[p] * (f32(1.0) + self.lam_o32[p]))
        return [(f, w * k[:, None]) for f, w in self._terms_of(val, h, p)]

    def peak_ratio(self, cos_h) -> np.ndarray:
        """``D(cos_h) / D(1)``: how far a half-vector is from the lobe peak."""
        return _brdf.microfacet_D(self.distribution, self.alpha, cos_h) / \
            _brdf.microfacet_D(self.distribution, self.alpha, 1.0)

    def threshold_angles(self, thresholds) -> np.ndarray:
        """Half-vector angles at which :meth:`peak_ratio` falls to each threshold
        (it decreases monotonically with the angle for Beckmann and GGX)."""
        key = (self.distribution, float(self.alpha), tuple(float(t) for t in thresholds))
        got = _ANGLE_CACHE.get(key)
        if got is None:
            theta = np.linspace(0.0, np.pi / 2, 20001)
            q = self.peak_ratio(np.cos(theta))
            got = np.array([theta[q > t].max() if (q > t).any() else -1.0 for t in key[2]])
            _ANGLE_CACHE[key] = got
        return got


def glossy_levels(lobe: GlossyLobe, p: np.ndarray, b: np.ndarray, geometry: BlockGeometry,
                  thresholds=DEFAULT_LEVEL_THRESHOLDS) -> np.ndarray:
    """Appendix-A-style choice of the BRDF representation per (vertex, block) pair.

    Appendix A picks 1 / 4 / 16 coefficients or the pixel basis from the angle
    between the view and the block centre reflected about the normal and the
    specular exponent.  For microfacet lobes we use the same two ingredients in
    one number: the NDF at the half-vector of the block closest to the normal,
    relative to its peak, ``q = D(theta_h,min) / D(0)``, where
    ``theta_h,min = max(0, angle(n, h_centre) - r_b / |wo + w_centre|)`` (a
    direction ``r_b`` from the centre moves the half-vector by at most
    ``r_b / |wo + w|``).  ``q > t_pixel`` -> 256 pixels, ``> t_16`` -> 16,
    ``> t_4`` -> 4, else 1 (the lobe is at most ``t_4`` of its peak anywhere
    in the block, the block behaves "essentially as Lambertian")."""
    angles = lobe.threshold_angles(tuple(thresholds))          # theta_h where q = t
    nb = geometry.centre.shape[0]
    flat = p * nb + b
    cen = geometry.centre.astype(np.float32).T
    nc = (lobe.n32 @ cen).reshape(-1)[flat]
    vc = (lobe.v32 @ cen).reshape(-1)[flat]
    norm = np.sqrt(np.maximum(np.float32(2.0) + np.float32(2.0) * vc, np.float32(1e-12)))
    cos_hc = np.clip((nc + lobe.cos_o32[p]) / norm, -1.0, 1.0)
    th = np.arccos(cos_hc) - geometry.radius32[b] / norm     # closest half-vector angle
    levels = np.zeros(p.size, dtype=np.int64)
    levels[th < angles[3]] = 1
    levels[th < angles[2]] = 4
    levels[th < angles[1]] = 16
    levels[th < angles[0]] = PIXEL
    return levels


def near_horizon(lobe: GlossyLobe, p: np.ndarray, b: np.ndarray,
                 geometry: BlockGeometry) -> np.ndarray:
    """Per pair (vertex ``p``, block ``b``): whether some direction of the block may have
    ``cos_i <= lobe.horizon_cos()`` -- the angle between the normal and the block centre
    plus the block's radius reaches the cut (False: every direction is above it)."""
    top = np.arccos(np.float32(min(lobe.horizon_cos(), 1.0)))
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", lobe.n32[p],
                                      geometry.centre[b].astype(np.float32)), -1.0, 1.0))
    return (ang + geometry.radius32[b]) >= top


@dataclass
class BlocksStats:
    """Tables 1-2 style counts and stage times of one evaluation."""

    cases: np.ndarray = None          # (4,) pairs per Algorithm 1 case (case 0: zero blocks)
    levels: dict = None               # BRDF coefficients -> pairs sampled with them
    samples: int = 0                  # BRDF samples taken
    times: dict = None

    def __post_init__(self):
        self.cases = np.zeros(4, dtype=np.int64) if self.cases is None else self.cases
        self.levels = {lv: 0 for lv in (0,) + BRDF_LEVELS} if self.levels is None else self.levels
        self.times = {} if self.times is None else self.times

    def add(self, other: "BlocksStats"):
        self.cases += other.cases
        for k, v in other.levels.items():
            self.levels[k] += v
        self.samples += other.samples
        for k, v in other.times.items():
            self.times[k] = self.times.get(k, 0.0) + v


def _tick(stats, key, t0):
    t1 = _time.perf_counter()
    stats.times[key] = stats.times.get(key, 0.0) + (t1 - t0)
    return t1


def _group_bounds(keys: np.ndarray):
    """Start/stop of the runs of equal values in a sorted array."""
    if keys.size == 0:
        return []
    cut = np.nonzero(np.diff(keys))[0] + 1
    starts = np.concatenate([[0], cut])
    stops = np.concatenate([cut, [keys.size]])
    return list(zip(starts.tolist(), stops.tolist()))


#: pairs of one pixel-basis group evaluated together ((rows, 256) float32 arrays of 1 MB:
#: few numpy calls per sample, which is what bounds the speed here)
_PIXEL_ROWS = 1024
#: pairs of one 1 / 4 / 16 coefficient batch
_LEVEL_PAIRS = 32768
#: vertices of one glossy_blocks call in shade_points (its per-pair arrays: ~100 B per
#: active pair)
_GLOSSY_VERTICES = 65536
_QUIET = dict(over="ignore", under="ignore", divide="ignore", invalid="ignore")


def glossy_blocks(pairs: ActivePairs, sums: np.ndarray, tables: LightTables, lobe: GlossyLobe,
                  verts: np.ndarray, mode="adaptive", thresholds=DEFAULT_LEVEL_THRESHOLDS,
                  stats: BlocksStats | None = None, threads: int | None = 1) -> np.ndarray:
    with np.errstate(**_QUIET):
        return _glossy_blocks(pairs, sums, tables, lobe, verts, mode, thresholds, stats,
                              threads)


def _in_threads(tasks, fn, threads):
    """``fn(task_list)`` for ``threads`` interleaved shares of ``tasks`` (in this thread
    when there is one share); numpy releases the GIL inside the large array passes."""
    threads = max(1, min(int(threads or _os.cpu_count() or 1), len(tasks)))
    if threads <= 1:
        fn(tasks)
        return
    with _Pool(max_workers=threads) as pool:
        for f in [pool.submit(fn, tasks[i::threads]) for i in range(threads)]:
            f.result()


def _glossy_blocks(pairs, sums, tables, lobe, verts, mode, thresholds, stats, threads=1):
    # body of glossy_blocks (under np.errstate)
    """Glossy radiance (len(verts), 3) of vertices ``verts`` by Algorithm 1 over their
    active pairs.

    ``lobe`` is :meth:`GlossyLobe.prepare`-d for exactly these vertices (row i =
    ``verts[i]``); ``sums`` from :func:`light_vis_sums`.  ``mode``: "adaptive"
    (:func:`glossy_levels`), "pixel" (every block in the pixel basis) or a fixed
    1 / 4 / 16.

    Pairs with 1 / 4 / 16 coefficients are evaluated per level in large batches
    (their samples at the eq. 4 nodes of each pair's block): level 1 is ``rho_1 S_b``
    with the cached line-9 product, 4 and 16 are ``A . (V_d . H_b)`` with ``A`` the
    eq. 4 coefficients and ``V_d . H_b`` from the change indices
    (:func:`dct_light_vis`).  Pixel-basis pairs are grouped by block so that the BRDF
    samples of a group are matrix products against the block's directions, and
    line 6/11 is ``(rho * V) @ L~_b`` (occluded pixels contribute 0).  ``threads``
    share the batches and groups."""
    st = stats if stats is not None else BlocksStats()
    t0 = _time.perf_counter()
    verts = np.asarray(verts, dtype=np.int64)
    if verts.size and verts[-1] - verts[0] + 1 == verts.size and (np.diff(verts) == 1).all():
        # a run of vertices (one material on the object): its pairs are one slice
        a, b = int(pairs.first[verts[0]]), int(pairs.first[verts[-1] + 1])
        idx = np.arange(a, b)
        P = pairs.p[a:b] - verts[0]                          # local vertex of each pair
    else:
        starts = pairs.first[verts]
        counts = pairs.first[verts + 1] - starts
        P = np.repeat(np.arange(verts.size), counts)
        idx = np.repeat(starts - (np.cumsum(counts) - counts), counts) + \
            np.arange(int(counts.sum()))
    Bk = pairs.b[idx]
    geometry = block_geometry(tables.resolution)
    if mode == "adaptive":
        levels = glossy_levels(lobe, P, Bk, geometry, thresholds)
    elif mode in ("pixel", PIXEL):
        levels = np.full(idx.size, PIXEL, dtype=np.int64)
    elif mode in (1, 4, 16):
        levels = np.full(idx.size, int(mode), dtype=np.int64)
    else:
        raise ValueError("mode must be 'adaptive', 'pixel', 1, 4 or 16")
    t0 = _tick(st, "levels", t0)
    one = pairs.one[idx]
    wide = lobe.dtype == np.float64           # float64 lobe: float64 tables (tests, exactness)
    unit_dirs = tables.unit_dirs if wide else tables.unit_dirs32
    pixel = tables.pixel if wide else tables.pixel32
    per_pair = np.zeros((idx.size, 3), dtype=lobe.dtype)
    lock = _threading.Lock()

    def timed_add(key, seconds):
        with lock:
            st.times[key] = st.times.get(key, 0.0) + seconds

    # 1 / 4 / 16: all pairs of a level sampled at once at the eq. 4 nodes of their
    # blocks; coefficients A = inv @ samples; line 6 / 11 = A . W with W = V_d . H_b
    # from the change indices (eq. 6); one coefficient: rho * S_b (line 9's product).
    # Pairs are cut in pieces of _LEVEL_PAIRS for the threads.
    def run_levels(tasks):
        for lv, l, s in tasks:
            t1 = _time.perf_counter()
            pix, inv = projection_system(l)
            d = unit_dirs[Bk[s][:, None], pix[None, :]]              # (m, lv, 3)
            if lv == 1:
                W = sums.S[idx[s]][:, None, :].astype(lobe.dtype, copy=False)
            else:
                W = dct_light_vis(pairs, tables, idx[s], lv, lobe.dtype)
            inv_t = np.ascontiguousarray(inv.T, dtype=lobe.dtype)
            for f, w in lobe.dense(P[s], d):
                A = f if lv == 1 else f @ inv_t                      # (m, lv)
                per_pair[s] += np.einsum("mk,mkc->mc", A, W) * w
            timed_add(f"level {lv}", _time.perf_counter() - t1)

    tasks = []
    for lv, l in ((1, 1), (4, 2), (16, 4)):
        s = np.nonzero(levels == lv)[0]
        st.samples += s.size * lv
        tasks += [(lv, l, s[a:a + _LEVEL_PAIRS]) for a in range(0, s.size, _LEVEL_PAIRS)]
    _in_threads(tasks, run_levels, threads)
    # pixel basis (line 6/11 with 256 samples), grouped by block: the BRDF samples of a
    # group are matrix products against the block's directions, the product with the
    # lighting is ``(rho * V) @ L~_b`` (occluded pixels contribute 0); the groups
    # (cut at _PIXEL_ROWS pairs) are shared out to the threads
    rest = np.nonzero(levels == PIXEL)[0]
    # a pair whose block lies wholly above the lobe's horizon_cos skips the per-sample
    # horizon checks: grouped apart
    edge = near_horizon(lobe, P[rest], Bk[rest], geometry)
    order = np.lexsort((edge, Bk[rest]))
    rest, edge = rest[order], edge[order]
    st.samples += rest.size * BLOCK_PIXELS

    def run_pixels(tasks):
        decompress = 0.0
        t1 = _time.perf_counter()
        for blk, near, rows in tasks:
            vis = None
            if not one[rows].all():
                t2 = _time.perf_counter()
                vis = _decompress(pairs, idx[rows], lobe.dtype)     # §4.4
                decompress += _time.perf_counter() - t2
            for f, w in lobe.dense(P[rows], unit_dirs[blk], near):
                if vis is not None:
                    f *= vis
                per_pair[rows] += (f @ pixel[blk]) * w
        timed_add("pixel", _time.perf_counter() - t1 - decompress)
        timed_add("decompress", decompress)

    tasks = [(int(Bk[rest[lo]]), bool(edge[lo]), rest[a:min(hi, a + _PIXEL_ROWS)])
             for lo, hi in _group_bounds(Bk[rest] * 2 + edge)
             for a in range(lo, hi, _PIXEL_ROWS)]
    tasks.sort(key=lambda t: -t[2].size)               # largest first: balanced shares
    _in_threads(tasks, run_pixels, threads)
    t0 = _time.perf_counter()
    out = np.zeros((verts.size, 3))
    sampled = np.flatnonzero(levels)                   # level 0 pairs add nothing
    for c in range(3):
        out[:, c] = np.bincount(P[sampled], weights=per_pair[sampled, c], minlength=verts.size)
    _tick(st, "sum", t0)
    mixed = ~one
    st.cases[1] += int(one.sum())
    st.cases[2] += int((mixed & (levels <= 1)).sum())
    st.cases[3] += int((mixed & (levels > 1)).sum())
    for lv in (0,) + BRDF_LEVELS:
        st.levels[lv] += int((levels == lv).sum())
    return out


glossy_blocks.__doc__ = _glossy_blocks.__doc__


def for_chunks(count: int, chunk: int, fn, threads: int | None = None):
    """``fn(a, b)`` over chunks of ``range(count)`` on all cores; returns the results in order."""
    spans = list(enumerate((a, min(count, a + chunk)) for a in range(0, count, chunk)))
    out = [None] * len(spans)

    def run(share):
        for i, (a, b) in share:
            out[i] = fn(a, b)

    _in_threads(spans, run, threads)
    return out


def shade_points(pairs: ActivePairs, sums: np.ndarray, tables: LightTables, positions, normals,
                 materials, material_table, eye, view_dirs=None, irradiance=None,
                 mode="adaptive", thresholds=DEFAULT_LEVEL_THRESHOLDS, chunk: int | None = None,
                 threads: int | None = None, stats: BlocksStats | None = None) -> np.ndarray:
    """BLOCKS radiance (P, 3) of every vertex -- the counterpart of
    :func:`.reference.shade_points` (same arguments for the geometry, materials and
    view).  ``irradiance``: the cached Lambert sums (:func:`lambert_irradiance`).

    ``mode="pixel"`` samples the whole BRDF x cos (Lambert included, with the
    lighting's mean directions for the cosine as REFERENCE) at every visible
    pixel: it is then REFERENCE up to float rounding."""
    from .reference import lambert_layer, view_directions
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    P = len(normals)
    st = stats if stats is not None else BlocksStats()
    out = np.zeros((P, 3))
    materials = np.asarray(materials)
    t0 = _time.perf_counter()
    exact_lambert = mode in ("pixel", PIXEL)
    if irradiance is None and not exact_lambert:
        irradiance = lambert_irradiance(sums, normals)
        t0 = _tick(st, "lambert", t0)
    for slot in np.unique(materials):
        sel = np.nonzero(materials == slot)[0]
        mat = _brdf.slot_material(material_table, slot)
        needs_view = mat.fresnel == "DIELECTRIC" or not mat.is_diffuse_only or exact_lambert
        vd = None
        if needs_view:
            vd = view_directions(positions[sel], eye) if view_dirs is None else \
                np.asarray(view_dirs, dtype=np.float64)[sel]
        if exact_lambert:
            out[sel] = _pixel_vertices(pairs, tables, mat, normals[sel], vd, sel, threads)
            st.cases[1] += int(pairs.one[np.isin(pairs.p, sel)].sum())
            continue
        out[sel] = lambert_layer(mat, irradiance[sel], normals[sel], vd)
        if mat.is_diffuse_only:
            # the Lambert layer's blocks are Light-BRDF (line 6) / Light-Vis (line 9)
            # products of the light's first moment; nothing is sampled per frame
            in_sel = np.zeros(P, dtype=bool)
            in_sel[sel] = True
            ones = pairs.one[in_sel[pairs.p]]
            st.cases[1] += int(ones.sum())
            st.cases[2] += int((~ones).sum())
            continue

        # vertices in pieces of ``chunk`` (bounds the per-pair arrays); inside a piece the
        # threads share the BRDF batches and pixel-basis groups (large numpy passes
        # that release the GIL, not many small per-thread ones)
        t0 = _time.perf_counter()
        size = chunk or _GLOSSY_VERTICES
        for a in range(0, sel.size, size):
            b = min(sel.size, a + size)
            lobe = GlossyLobe(mat).prepare(normals[sel[a:b]], vd[a:b])
            out[sel[a:b]] += glossy_blocks(pairs, sums, tables, lobe, sel[a:b], mode,
                                           thresholds, st, threads=threads)
        st.times["glossy wall"] = st.times.get("glossy wall", 0.0) + _time.perf_counter() - t0
    st.cases[0] += pairs.dv.count * pairs.dv.blocks - pairs.count
    return out


def _pixel_vertices(pairs, tables, mat, normals, views, verts, threads):
    """Every visible pixel of every block: full BRDF x cos (Lambert + glossy)."""
    albedo = np.asarray(mat.diffuse_albedo, dtype=np.float64) / np.pi
    wd = _brdf.diffuse_view_weight(mat, normals, views).astype(np.float64) \
        if mat.fresnel == "DIELECTRIC" else np.ones((len(normals), 3))

    def run(a, b):
        v = verts[a:b]
        starts = pairs.first[v]
        counts = pairs.first[v + 1] - starts
        P = np.repeat(np.arange(v.size), counts)
        idx = np.repeat(starts - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))
        vis = _decompress(pairs, idx)
        rows, px = np.nonzero(vis > 0.0)
        bk = pairs.b[idx][rows]
        p = P[rows]
        f = np.zeros((rows.size, 3))
        if mat.has_diffuse:
            cos = np.maximum(np.einsum("ij,ij->i", normals[a:b][p], tables.mean_dirs[bk, px]), 0.0)
            f += cos[:, None] * albedo[None, :] * wd[a:b][p]
        if not mat.is_diffuse_only:
            lobe = GlossyLobe(mat, np.float64).prepare(normals[a:b], views[a:b])
            with np.errstate(**_QUIET):
                f += lobe.sample(p, tables.unit_dirs[bk, px])
        f *= vis[rows, px][:, None] * tables.pixel[bk, px]
        out = np.zeros((v.size, 3))
        for c in range(3):
            out[:, c] = np.bincount(p, weights=f[:, c], minlength=v.size)
        return out

    return np.concatenate(for_chunks(len(verts), 512, run, threads)) if len(verts) else np.zeros((0, 3))
