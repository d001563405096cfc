"""BLOCKS' per-lighting and per-visibility tables (Inger, Farbman, Lischinski 2013, §4.3): the
(vertex, block) pairs whose visibility is not constant 0, the lighting per block in DCT,
suffix-sum and pixel bases, the line-9 light-visibility sums and the exact Lambert layer."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ...sphere.directions import cubemap
from .encoding import BLOCK_PIXELS, ONE, ZERO, DiffVisibility, dct_basis, to_blocks

_DECODE_LOCK = threading.Lock()


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


def decompress(pairs: ActivePairs, sel: np.ndarray, dtype=np.float64,
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
