"""BLOCKS' data layout (Inger, Farbman, Lischinski 2013, §4): cubemap blocks, the DCT basis and the
differential visibility encoding (eq. 5).  No BRDF and no lighting here: the evaluator is
:mod:`.blocks`, its float32 lobe :mod:`.blocks_lobe`.

The cubemap (6 x N x N, N = 32/64/128, texels flattened ``(face, row, col)``
as in :mod:`.directions`) is split into 16 x 16 *blocks*, ordered
``(face, block_row, block_col)``; inside a block the pixels are concatenated
row by row (row-major, index ``i*16 + j`` in 0..255).  :func:`block_permutation`
maps between the two orders; :func:`block_geometry` gives each block's texel
directions, centre and angular radius.

Visibility (§4.2, eq. 5).  ``V_d = D V`` with ``V_d[0] = V[0]`` and
``V_d[i] = V[i] - V[i-1]``: only the indices where ``V_d != 0`` are stored
(uint8, "CCITT group 3" style).  For binary maps the values are implied (they
alternate +1, -1, ... because the map starts from an implicit 0); for the
quantized grey-level variant (Fig. 3, ``bits`` = 6 -> levels 0..63) the integer
derivative values are stored alongside.  Blocks that are constant 0 / constant
"fully visible" are flagged and carry no indices.  :func:`serialize_visibility`
writes everything as base-128 varints (LEB128, protocol-buffer style); the
change indices are written as run lengths (gaps to the previous change).

DCT (§4.1 eq. 4, §4.3).  The 16 lowest orthonormal 2-D DCT-II functions (u, v < 4),
ordered as nested squares so that the first 1 / 4 / 16 are the sets ``u, v < l`` for
l = 1, 2, 4 (:data:`DCT_ORDER`), for the lighting's and the BRDF's coefficients alike
(eq. 4 as printed writes ``cos(x 2 pi u / N)``, which is not the basis whose
coefficients the lighting is stored in; line 6's dot product needs both in the same
orthonormal basis, so DCT-II serves both).  :func:`projection_system` is eq. 4's
interpolation system: l^2 samples of a block -> its l^2 lowest coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...common.cache import memo
from ...sphere.directions import cubemap
from ...scene.visibility import unpack_visibility

BLOCK = 16
BLOCK_PIXELS = BLOCK * BLOCK

#: block kinds
ZERO, ONE, MIXED = 0, 1, 2
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


# --------------------------------------------------------------------------- block geometry

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
