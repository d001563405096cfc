"""BLOCKS: locally adaptive per-block products (Inger, Farbman, Lischinski 2013, §4) -- the batched
evaluator of the method.  The data layout and the visibility encoding are in
:mod:`.blocks_encoding`, the float32 microfacet lobe in :mod:`.blocks_lobe`;
``tests/core/methods/blocks/oracle.py`` states Algorithm 1 per vertex (the oracle the tests
hold this evaluator to).

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

import threading as _threading
import time as _time
from dataclasses import dataclass

import numpy as np

from ...shading import brdf as _brdf
from ...shading.materials import slot_material
from .encoding import BLOCK_PIXELS, BRDF_LEVELS, PIXEL, block_geometry, projection_system
from .lobe import DEFAULT_LEVEL_THRESHOLDS, GlossyLobe, glossy_levels, near_horizon
from ...common.parallel import in_threads, for_chunks
from .light_tables import ActivePairs, LightTables, decompress, dct_light_vis, lambert_irradiance

#: Algorithm 1 cases (per block)
CASE_ZERO, CASE_LIGHT_BRDF, CASE_LIGHT_VIS, CASE_TRIPLE = 0, 1, 2, 3
CASE_NAMES = ("zero (line 2)", "light-brdf (line 6)", "light-vis (line 9)", "triple (line 11)")


# --------------------------------------------------------------------------- batched evaluator
#
# The per-vertex ``integrate_vertex`` of tests/core/methods/blocks/oracle.py is the readable
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
    in_threads(tasks, run_levels, threads)
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
        decode_time = 0.0
        t1 = _time.perf_counter()
        for blk, near, rows in tasks:
            vis = None
            if not one[rows].all():
                t2 = _time.perf_counter()
                vis = decompress(pairs, idx[rows], lobe.dtype)     # §4.4
                decode_time += _time.perf_counter() - t2
            for f, w in lobe.dense(P[rows], unit_dirs[blk], near):
                if vis is not None:
                    f *= vis
                per_pair[rows] += (f @ pixel[blk]) * w
        timed_add("pixel", _time.perf_counter() - t1 - decode_time)
        timed_add("decompress", decode_time)

    tasks = [(int(Bk[rest[lo]]), bool(edge[lo]), rest[a:min(hi, a + _PIXEL_ROWS)])
             for lo, hi in _group_bounds(Bk[rest] * 2 + edge)
             for a in range(lo, hi, _PIXEL_ROWS)]
    tasks.sort(key=lambda t: -t[2].size)               # largest first: balanced shares
    in_threads(tasks, run_pixels, threads)
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
    from ..reference.shading import lambert_layer, view_directions
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
        mat = slot_material(material_table, slot)
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
        vis = decompress(pairs, idx)
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
