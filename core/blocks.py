"""BLOCKS: locally adaptive per-block products (Inger, Farbman, Lischinski 2013, §4) -- the batched
evaluator of the method.  The data layout and the visibility encoding are in
:mod:`.blocks_encoding`, the float32 microfacet lobe in :mod:`.blocks_lobe`;
``tests/blocks_oracle.py`` states Algorithm 1 per vertex (the oracle the tests hold this
evaluator to).

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

Lighting (§4.3), per block, after the per-pixel solid-angle correction
``L~_k = L_k dw_k`` (so that plain sums are integrals):

(i)   ``dct``: the 16 lowest orthonormal 2-D DCT-II coefficients
      (:data:`.blocks_encoding.DCT_ORDER`);
(ii)  ``integral``: ``L_int = D^{-T} L~`` (eq. 6), i.e. ``L_int[i] = sum_{j>=i}
      L~_j`` -- *suffix* sums along the concatenated rows (eq. 6's upper
      triangular matrix of ones).  Then ``L~ . V = L_int . V_d`` exactly, a sum
      over the stored change indices only;
(iii) ``pixel``: ``L~`` itself, (block, 256, 3).

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

import os as _os
import threading as _threading
import time as _time
from concurrent.futures import ThreadPoolExecutor as _Pool
from dataclasses import dataclass

import numpy as np

from . import brdf as _brdf
from .blocks_encoding import (BLOCK_PIXELS, BRDF_LEVELS, ONE, PIXEL, ZERO,
                              DiffVisibility, block_geometry, dct_basis, projection_system,
                              to_blocks)
from .blocks_lobe import DEFAULT_LEVEL_THRESHOLDS, GlossyLobe, glossy_levels, near_horizon
from .directions import cubemap

#: Algorithm 1 cases (per block)
CASE_ZERO, CASE_LIGHT_BRDF, CASE_LIGHT_VIS, CASE_TRIPLE = 0, 1, 2, 3
CASE_NAMES = ("zero (line 2)", "light-brdf (line 6)", "light-vis (line 9)", "triple (line 11)")


# --------------------------------------------------------------------------- batched evaluator
#
# The per-vertex ``integrate_vertex`` of tests/blocks_oracle.py is the readable
# statement of Algorithm 1; what follows evaluates the same cases for many vertices at once
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

_DECODE_LOCK = _threading.Lock()


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
