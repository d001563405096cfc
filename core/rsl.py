"""Rotatable square lights (Xu, Jia, Hu, Tai 2006): light decomposition, BRDF SATs,
visibility distance tables and the per-vertex evaluation of eq. 5.

Per vertex ``x`` and view ``wo`` the rendering integral over the environment is split
into ``K`` subregions ``S_i`` and each is approximated by the product of separate
integrals (eq. 5)::

    B(x, wo) ~= sum_i  E_i * avg_{R_i}(rho cos) * avg_{R_i}(V)

``E_i = integral of L over S_i`` (RGB, preserved exactly by the decomposition of
§4.1), ``R_i`` the square of the RSL in the vertex's disk parameterization (§5:
``p = sin(t)/sqrt(1+cos(t)) (sin f, cos f)``, equal-area with ``dw = 2 dp``, so the
square has area ``|S_i| / 2``); the BRDF average comes from a summed-area table (§4.2,
eq. 6/8, four look-ups per view node) and the visibility average from the visibility
distance table (§4.3, eq. 9) or, as the exact option, from a per-vertex SAT of the
visibility map.  ``V`` is the visibility of the hemisphere only: the horizon is cut
once, by the cosine in ``rho cos`` (see :func:`visibility_maps`).

Everything here is numpy only; :mod:`..addon.methods.rsl` and the GLSL pass use the
same tables.
"""

from __future__ import annotations

import heapq
import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import brdf
from .directions import (Cubemap, direction_to_texel, hemisphere_to_rsl_disk,
                         orthonormal_frame, texel_of_components)
from .directions import rsl_disk_to_hemisphere
from .envmap import LUMINANCE, CubeLighting

# --------------------------------------------------------------------------- #
# §4.1  Light decomposition
# --------------------------------------------------------------------------- #

@dataclass
class SquareLights:
    """``K`` rotatable square lights in the lighting's own (texture) frame.

    ``centres`` (K, 3) unit: the luminance-weighted mean direction of each subregion;
    ``solid_angles`` (K,): ``|S_i|`` (the square has this solid angle, i.e. area
    ``|S_i|/2`` in the disk map); ``energy`` (K, 3): ``integral of L over S_i``, so the
    intensity ``I_i = energy_i / |S_i|`` preserves each subregion's energy (§4.1.1).
    ``labels`` (6N²,): the subregion of every cubemap texel.  ``fit_error``: the
    intensity part of the RSL fitting error, ``sum_i integral_{S_i} (L - I_i)²`` in
    luminance (grows with every merge), relative to ``integral of Y² dw`` (see :func:`decompose`).
    """

    centres: np.ndarray
    solid_angles: np.ndarray
    energy: np.ndarray
    labels: np.ndarray
    fit_error: float = 0.0
    seconds: float = 0.0

    @property
    def count(self) -> int:
        return len(self.solid_angles)

    @property
    def half_sides(self) -> np.ndarray:
        """Half edge of each square in the disk plane: ``sqrt(|S|/2) / 2``."""
        return 0.5 * np.sqrt(0.5 * self.solid_angles)

    @property
    def intensity(self) -> np.ndarray:
        return self.energy / self.solid_angles[:, None]

    def rotated(self, world_to_texture: np.ndarray) -> np.ndarray:
        """Centres in world space for a world whose lighting reads ``E(R d)``:
        ``d = R^T c``, i.e. rows ``c @ R``."""
        return self.centres @ np.asarray(world_to_texture, dtype=np.float64)


def _texel_neighbours(cube: Cubemap) -> np.ndarray:
    """(E, 2) pairs of edge-adjacent texels, across cube faces too."""
    n = cube.resolution
    D = cube.size
    idx = np.arange(D)
    face, row, col = idx // (n * n), (idx // n) % n, idx % n
    from .directions import FACE_AXES
    ax = FACE_AXES[face]
    h = 2.0 / n
    s = -1.0 + (col + 0.5) * h
    t = -1.0 + (row + 0.5) * h
    pairs = []
    for ds, dt in ((h, 0.0), (0.0, h)):
        d = ax[:, 0] + (s + ds)[:, None] * ax[:, 1] + (t + dt)[:, None] * ax[:, 2]
        other = direction_to_texel(d, n)
        pairs.append(np.stack([idx, other], axis=1))
        d = ax[:, 0] + (s - ds)[:, None] * ax[:, 1] + (t - dt)[:, None] * ax[:, 2]
        other = direction_to_texel(d, n)
        pairs.append(np.stack([idx, other], axis=1))
    p = np.concatenate(pairs)
    p = p[p[:, 0] != p[:, 1]]
    p.sort(axis=1)
    return np.unique(p, axis=0)


def _fit_error(A, E, Q, M):
    """Mean over the four rotations of ``integral (T - F(theta))^2`` (§4.1.1), from moments.

    ``A`` solid angle, ``E = integral Y``, ``Q = integral Y^2``, ``M = integral w`` (3,).
    The square of area ``A`` (intensity ``I = E/A``) leaves the subregion's own
    variance ``Q - E²/A`` and, where region and square differ, ``I²`` times the area
    of the symmetric difference, averaged over the rotations 0, π/8, π/4, 3π/8.  That
    area is estimated from the region's second moment about its centre
    ``J = A - |M|²/A``: ``A (0.1 + 1.9 (1 - min(1, A²/2πJ)))``, from about ``0.1 A``
    for disk-like regions to ``2 A`` for long ones.  (The plane's own mean, 0.18 A for a disk,
    rendered worse on the tuning HDRIs: docs/measurements.md, RSL.)
    """
    var = max(Q - E * E / A, 0.0)
    J = max(A - (M[0] * M[0] + M[1] * M[1] + M[2] * M[2]) / A, 1e-300)
    compact = min(A * A / (2.0 * math.pi * J), 1.0)
    mismatch = A * (0.1 + 1.9 * (1.0 - compact))
    return var + (E / A) ** 2 * mismatch


def decompose(lighting: CubeLighting, cube: Cubemap, count: int | None = 30,
              error_budget: float | None = None, area_power: float = 1.0,
              _history: list | None = None) -> SquareLights:
    """Bottom-up merging of cubemap texels into ``count`` subregions (§4.1.2, Fig. 5).

    Each step merges the pair of adjacent subregions (across cube faces too) whose
    merged subregion has the least penalised fitting error ``|S|^p E(eta²)`` (eq. 7,
    ``p = area_power``; Fig. 5 picks the least merged error, not the least increase of
    the sum); costs come from moments (they add on a merge) and are kept in a priority
    queue with lazy invalidation, so 6x32² texels -> 30 lights takes well under a
    second instead of the paper's two minutes.  With ``error_budget``
    the count is the smallest one (not below ``count``; ``None``: 1) whose intensity
    fitting error ``sum_i integral_{S_i} (L - I_i)²`` is at most ``error_budget`` times
    ``(integral Y dw)² / 4 pi`` (the squared luminance integral of a uniform
    environment of the same power); the merge order does not depend on the budget.
    """
    if error_budget is not None:
        history = []
        decompose(lighting, cube, 1, None, area_power, _history=history)
        allowed = float(error_budget)
        floor_count = 1 if count is None else max(1, int(count))
        fits = [n for n, err in history if err <= allowed and n >= floor_count]
        best = min(fits) if fits else cube.size
        return decompose(lighting, cube, best, None, area_power)
    import time
    t0 = time.perf_counter()
    rad = np.asarray(lighting.radiance, dtype=np.float64)
    if not np.all(np.isfinite(rad)):
        raise ValueError("lighting has NaN/Inf radiance")
    D = cube.size
    if rad.shape != (D, 3):
        raise ValueError(f"lighting has {rad.shape[0]} texels, cubemap {D}")
    dw = np.asarray(cube.solid_angles, dtype=np.float64)
    Y = np.maximum(rad @ LUMINANCE, 0.0)
    target = 1 if count is None else max(1, min(int(count), D))
    A = dw.tolist()
    E = (Y * dw).tolist()
    Q = (Y * Y * dw).tolist()
    Mg = cube.mean_directions * dw[:, None]
    M = [tuple(m) for m in Mg.tolist()]
    p = float(area_power)
    alive = [True] * D
    parent = list(range(D))
    stamp = [0] * D
    neigh = [set() for _ in range(D)]
    for a, b in _texel_neighbours(cube).tolist():
        neigh[a].add(b)
        neigh[b].add(a)
    # scale: integral of Y² of a uniform environment with the same power
    q_total = max(float(np.sum(Y * dw)) ** 2 / (4.0 * np.pi), 1e-300)
    total_var = 0.0               # sum of Q - E²/A over subregions (0 for single texels)

    def merged_moments(a, b):
        Ma, Mb = M[a], M[b]
        return (Ma[0] + Mb[0], Ma[1] + Mb[1], Ma[2] + Mb[2])

    def merged(a, b):
        """Penalised fitting error ``|S|^p E(eta²)`` of the union of regions a and b."""
        Am = A[a] + A[b]
        return _fit_error(Am, E[a] + E[b], Q[a] + Q[b], merged_moments(a, b)) * Am ** p

    heap = []
    for a in range(D):
        for b in neigh[a]:
            if a < b:
                heap.append((merged(a, b), a, b, 0, 0))
    heapq.heapify(heap)
    regions = D
    while regions > target and heap:
        _, a, b, sa, sb = heapq.heappop(heap)
        if not (alive[a] and alive[b]) or stamp[a] != sa or stamp[b] != sb:
            continue
        Mm = merged_moments(a, b)
        if len(neigh[a]) < len(neigh[b]):
            a, b = b, a
        total_var += (Q[a] + Q[b] - (E[a] + E[b]) ** 2 / (A[a] + A[b])
                      - (Q[a] - E[a] ** 2 / A[a]) - (Q[b] - E[b] ** 2 / A[b]))
        A[a] += A[b]
        E[a] += E[b]
        Q[a] += Q[b]
        M[a] = Mm
        alive[b] = False
        stamp[a] += 1
        nb = neigh[b]
        nb.discard(a)
        na = neigh[a]
        na.discard(b)
        for x in nb:
            nx = neigh[x]
            nx.discard(b)
            nx.add(a)
        na |= nb
        neigh[b] = set()
        parent[b] = a
        regions -= 1
        if _history is not None:
            _history.append((regions, max(total_var, 0.0) / q_total))
        sa = stamp[a]
        for x in na:
            heapq.heappush(heap, (merged(a, x), a, x, sa, stamp[x]))
    labels = np.array(parent)
    while True:                       # follow merge parents to the surviving roots
        nxt = labels[labels]
        if np.array_equal(nxt, labels):
            break
        labels = nxt
    roots = np.nonzero(np.array(alive))[0]
    remap = np.full(D, -1, dtype=np.int64)
    remap[roots] = np.arange(len(roots))
    lab = remap[labels]
    K = len(roots)
    sa_k = np.bincount(lab, weights=dw, minlength=K)
    energy = np.stack([np.bincount(lab, weights=rad[:, c] * dw, minlength=K)
                       for c in range(3)], axis=1)
    # centre: luminance-weighted mean light direction (a sun keeps its direction);
    # geometric centre for dark subregions.
    ld = np.asarray(lighting.directions, dtype=np.float64)
    yw = Y * dw
    mom = np.stack([np.bincount(lab, weights=yw * ld[:, c], minlength=K) for c in range(3)], 1)
    geo = np.stack([np.bincount(lab, weights=Mg[:, c], minlength=K) for c in range(3)], 1)
    lum = np.bincount(lab, weights=yw, minlength=K)
    lit = lum > 1e-12 * max(lum.max(initial=0.0), 1e-300)
    centre = np.where(lit[:, None], mom, geo)
    nrm = np.linalg.norm(centre, axis=1, keepdims=True)
    bad = nrm[:, 0] < 1e-12
    centre = np.where(bad[:, None], geo, centre)
    centre /= np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-300)
    return SquareLights(centre, sa_k, energy, lab, max(total_var, 0.0) / q_total,
                        time.perf_counter() - t0)


# --------------------------------------------------------------------------- #
# Summed-area tables on the disk map (§4.2, §5)
# --------------------------------------------------------------------------- #

def disk_texel_samples(resolution: int, sub: int):
    """Sub-sample centres of the ``N x N`` disk grid over [-1, 1]²: ``(px, py)`` each
    (N*sub, N*sub) (rows py, columns px), their area ``(2/(N sub))²`` and an inside-disk mask."""
    m = int(resolution) * int(sub)
    c = -1.0 + (np.arange(m) + 0.5) * (2.0 / m)
    py, px = np.meshgrid(c, c, indexing="ij")
    return px, py, (2.0 / m) ** 2, px * px + py * py < 1.0


def summed_area(values: np.ndarray) -> np.ndarray:
    """SAT with a leading zero row/column: ``S[..., i, j] = sum values[..., :i, :j]``."""
    v = np.asarray(values, dtype=np.float64)
    S = np.zeros(v.shape[:-2] + (v.shape[-2] + 1, v.shape[-1] + 1))
    S[..., 1:, 1:] = v.cumsum(-2).cumsum(-1)
    return S


def _bilinear(S: np.ndarray, x: np.ndarray, y: np.ndarray, lead=None) -> np.ndarray:
    """Bilinear sample of corner tables ``S`` (..., N+1, N+1) at grid coordinates
    ``x`` (column), ``y`` (row) in [0, N] (clamped).  ``lead`` indexes the leading axis."""
    n = S.shape[-1] - 1
    x = np.clip(x, 0.0, n)
    y = np.clip(y, 0.0, n)
    x0 = np.minimum(x.astype(np.int64), n - 1)
    y0 = np.minimum(y.astype(np.int64), n - 1)
    fx, fy = x - x0, y - y0
    if lead is None:
        g = lambda r, c: S[r, c]                                    # noqa: E731
    else:
        g = lambda r, c: S[lead, r, c]                              # noqa: E731
    top = g(y0, x0) * (1 - fx) + g(y0, x0 + 1) * fx
    bot = g(y0 + 1, x0) * (1 - fx) + g(y0 + 1, x0 + 1) * fx
    return top * (1 - fy) + bot * fy


def box_integral(S: np.ndarray, px, py, half, lead=None) -> np.ndarray:
    """Integral over the square ``[px-half, px+half] x [py-half, py+half]`` (disk-plane
    units, clipped to [-1, 1]²) of the piecewise-constant function whose corner SAT
    (:func:`summed_area` of per-texel integrals) is ``S``: four bilinear look-ups,
    exact for a piecewise-constant integrand."""
    n = S.shape[-1] - 1
    k = 0.5 * n
    x0, x1 = (px - half + 1.0) * k, (px + half + 1.0) * k
    y0, y1 = (py - half + 1.0) * k, (py + half + 1.0) * k
    return (_bilinear(S, x1, y1, lead) - _bilinear(S, x0, y1, lead)
            - _bilinear(S, x1, y0, lead) + _bilinear(S, x0, y0, lead))


@dataclass
class BrdfTables:
    """BRDF x cosine SATs of one material on the disk map (§4.2, isotropic: 3D).

    Glossy: for each separable term ``k`` of :func:`..brdf.specular_terms` a table
    ``glossy[k]`` (M, N+1, N+1) over ``M`` view elevations ``view_angles`` (view in
    the local x-z plane, azimuth 0) of the per-texel integral ``integral f_k cos dp``.
    ``cosine`` (N+1, N+1): the same for ``max(0, cos)`` (Lambert, view independent).
    ``offsets``: the per-table mean subtracted before summation -- the SAT precision
    fix for 32-bit GPUs (the sums of ``f - mean`` stay small); add
    ``offset * box area`` back after a box look-up (:func:`brdf_box`).
    """

    resolution: int
    view_angles: np.ndarray
    cosine: np.ndarray
    cosine_offset: float
    glossy: list = field(default_factory=list)
    glossy_offsets: list = field(default_factory=list)
    seconds: float = 0.0


def _offset_sat(texel_integrals: np.ndarray, cell_area: float):
    """SAT of ``texel_integrals - mean`` and the mean value per unit area."""
    mean = float(texel_integrals.mean()) / cell_area
    return summed_area(texel_integrals - mean * cell_area), mean


def _texel_sum(values: np.ndarray, resolution: int, sub: int) -> np.ndarray:
    n = int(resolution)
    return values.reshape(values.shape[:-2] + (n, sub, n, sub)).sum(axis=(-3, -1))


def brdf_tables(material: brdf.Material, resolution: int = 32, views: int = 32,
                sub: int = 4) -> BrdfTables:
    """Tabulate ``material``'s BRDF x cosine into SATs (§4.2; isotropic, so the view
    needs only its elevation: ``views`` nodes over [0, pi/2]).  Texel integrals use
    ``sub x sub`` midpoint samples inside the unit disk (zero outside: below the
    horizon)."""
    import time
    t0 = time.perf_counter()
    n = int(resolution)
    px, py, da, inside = disk_texel_samples(n, sub)
    dirs = rsl_disk_to_hemisphere(px, py).reshape(-1, 3)
    w = np.where(inside, da, 0.0).reshape(-1)
    cell = (2.0 / n) ** 2
    cos_int = _texel_sum((np.maximum(dirs[:, 2], 0.0) * w).reshape(px.shape), n, sub)
    cosine, cos_off = _offset_sat(cos_int, cell)
    angles = np.linspace(0.0, 0.5 * np.pi, int(views))
    out = BrdfTables(n, angles, cosine, cos_off)
    if not material.is_diffuse_only:
        M = len(angles)
        normals = np.tile([0.0, 0.0, 1.0], (M, 1))
        vdirs = np.stack([np.sin(angles), np.zeros(M), np.cos(angles)], axis=1)
        sel = w > 0
        for lobe, _weight in brdf.specular_terms(material, normals, vdirs, dirs[sel]):
            full = np.zeros((M, len(w)))
            full[:, sel] = lobe * w[sel]
            integ = _texel_sum(full.reshape((M,) + px.shape), n, sub)
            sats, offs = zip(*(_offset_sat(integ[j], cell) for j in range(M)))
            out.glossy.append(np.stack(sats))
            out.glossy_offsets.append(np.array(offs))
    out.seconds = time.perf_counter() - t0
    return out


def brdf_box(tables: BrdfTables, term: int | None, view_angle, px, py, half) -> np.ndarray:
    """Average of the term's ``f cos`` over the square (glossy ``term`` index, or None
    for the cosine), linear in the view elevation between table nodes (eq. 8)."""
    area = (2.0 * half) ** 2
    if term is None:
        box = box_integral(tables.cosine, px, py, half)
        return box / area + tables.cosine_offset * _clipped_area(px, py, half) / area
    angles = tables.view_angles
    M = len(angles)
    t = np.clip(np.asarray(view_angle, dtype=np.float64) / (angles[1] - angles[0]), 0, M - 1)
    j0 = np.minimum(t.astype(np.int64), M - 2)
    f = t - j0
    S, off = tables.glossy[term], tables.glossy_offsets[term]
    clip = _clipped_area(px, py, half)
    b0 = box_integral(S, px, py, half, lead=j0) + off[j0] * clip
    b1 = box_integral(S, px, py, half, lead=j0 + 1) + off[j0 + 1] * clip
    return ((1.0 - f) * b0 + f * b1) / area


def _clipped_area(px, py, half):
    wx = np.clip(px + half, -1, 1) - np.clip(px - half, -1, 1)
    wy = np.clip(py + half, -1, 1) - np.clip(py - half, -1, 1)
    return wx * wy


# --------------------------------------------------------------------------- #
# §4.3  Visibility in the disk map: maps, VDT (eq. 9), SAT
# --------------------------------------------------------------------------- #

def _disk_samples(cube: Cubemap, resolution: int, sub: int) -> np.ndarray:
    """(3, S) float32 local directions of the disk map's ``sub x sub`` samples per texel,
    those below the height ``z0`` moved up to it (see :func:`visibility_maps`)."""
    px, py, _, _ = disk_texel_samples(resolution, sub)
    # below the height z0 (|p|^2 = 1 - z): read at z0 along the same azimuth
    r_low = math.sqrt(1.0 - 2.0 / cube.resolution)
    scale = np.minimum(1.0, r_low / np.maximum(np.hypot(px, py), 1e-12))
    local = rsl_disk_to_hemisphere(px * scale, py * scale).reshape(-1, 3)
    return np.ascontiguousarray(local.T, dtype=np.float32)


def _frames(normals) -> np.ndarray:
    """(P, 3 world, 3 local) float32 frames ``(t, b, n)`` of :func:`orthonormal_frame`."""
    nrm = np.asarray(normals, dtype=np.float64)
    t, b = orthonormal_frame(nrm)
    return np.stack([t, b, nrm], axis=2).astype(np.float32)


def _visible_counts(packed: np.ndarray, frames: np.ndarray, local: np.ndarray, cube_res: int,
                    n: int, sub: int, chunk: int = 32) -> np.ndarray:
    """Visible samples per disk texel, (p, n, n) uint8 in [0, sub²], from packed bits.
    Small chunks: the sample arrays stay in the cache (2x faster than 512 points)."""
    out = np.empty((len(frames), n, n), np.uint8)
    for a in range(0, len(frames), chunk):
        e = min(len(frames), a + chunk)
        world = np.matmul(frames[a:e], local)                          # (p, 3, S)
        tex = texel_of_components(world[:, 0], world[:, 1], world[:, 2], cube_res)
        # read the packed bits directly (np.packbits order: most significant bit first)
        if packed.shape[1]:
            byte = np.take_along_axis(packed[a:e], tex >> 3, axis=1)
        else:
            byte = np.zeros(tex.shape, np.uint8)
        got = ((byte >> (7 - (tex & 7)).astype(np.uint8)) & np.uint8(1))
        got = got.reshape(e - a, n, sub, n, sub)
        acc = out[a:e]
        acc[...] = got[:, :, 0, :, 0]
        for i in range(sub):
            for j in range(sub):
                if i or j:
                    acc += got[:, :, i, :, j]
    return out


def visibility_maps(bits: np.ndarray, normals: np.ndarray, cube: Cubemap, resolution: int = 32,
                    sub: int = 2, chunk: int = 32) -> np.ndarray:
    """Per-vertex visibility in its local disk map, (P, N, N) float32 in [0, 1].

    The stored cubemap visibility bits (world texel order) are read along ``sub x
    sub`` sample directions per disk texel in the frame ``(t, b, n)`` of
    :func:`..directions.orthonormal_frame`; a texel's value is the visible fraction
    of its samples (``sub = 1``: a binary map, one ray per texel as in §4.3.1).

    The map is the visibility of the *hemisphere* (§4.3: the VDT holds distances to the
    map's occlusion boundaries); the horizon is not one of them -- the cosine in the
    BRDF tables already cuts the integrand there (zero outside the unit disk), and a
    square average of a visibility that also drops to 0 at the horizon would count
    the cut twice in eq. 5 (``avg rho * avg V`` for a light across the horizon).  So
    samples lower than ``z0 = 2/M`` (M the cubemap resolution: the cube texel holding
    the direction then lies above the horizon, so its bit was traced), the disk rim
    and the square's corners outside the disk, read the visibility at height ``z0``
    along their azimuth: a boundary meeting the horizon continues straight below it.
    """
    n, sub = int(resolution), int(sub)
    counts = _visible_counts(np.asarray(bits, dtype=np.uint8), _frames(normals),
                             _disk_samples(cube, n, sub), cube.resolution, n, sub, chunk)
    return counts.astype(np.float32) * np.float32(1.0 / (sub * sub))


def _signed_distances(vis: np.ndarray) -> np.ndarray:
    """:func:`visibility_distance_table` of boolean maps (P, n, n), float32."""
    P, n, _ = vis.shape
    h = 2.0 / n
    big = np.float32(4.0 * n * n)
    out = np.empty((P, n, n), dtype=np.float32)
    cols = np.ascontiguousarray(vis.transpose(2, 0, 1))                # (cols, P, rows)
    for target in (False, True):
        # distance from every texel to the nearest texel equal to `target`
        feat = cols == target
        # pass 1: along rows (1D distance to the nearest feature in the same row)
        g = np.empty((n, P, n), np.float32)
        last = np.full((P, n), -big, np.float32)
        for j in range(n):
            last[feat[j]] = j
            g[j] = j - last
        last.fill(big)
        for j in range(n - 1, -1, -1):
            last[feat[j]] = j
            np.minimum(g[j], last - j, out=g[j])
        np.minimum(g, big, out=g)
        g *= g
        g = np.ascontiguousarray(g.transpose(1, 2, 0))                # (P, rows, cols)
        # pass 2: along columns, d²(i, j) = min_k g(k, j) + (i - k)², by offset |i - k|;
        # no offset whose square passes every distance so far can lower one
        d2 = g.copy()
        top = float(d2.max(initial=0.0))
        for o in range(1, n):
            c = np.float32(o * o)
            if c >= top:
                break
            np.minimum(d2[:, o:], g[:, :n - o] + c, out=d2[:, o:])
            np.minimum(d2[:, :n - o], g[:, o:] + c, out=d2[:, :n - o])
        d = np.sqrt(d2)
        d *= np.float32(h)
        d -= np.float32(0.5 * h)
        sel = vis != target          # texels of the other value measure to `target`
        out[sel] = (-d if target else d)[sel]
    flat = vis.reshape(P, -1)
    none = ~flat.any(1) | flat.all(1)
    out[none] = np.where(vis[none], 2.0, -2.0)
    return out


def visibility_distance_table(maps: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Signed distance (disk-plane units) from each texel centre to the visibility
    boundary, positive where visible (§4.3, Fig. 7): ``D = sign (d - h/2)`` with ``d``
    the exact Euclidean distance to the nearest centre of the other value (two-pass
    squared EDT) and ``h`` the texel size, so a boundary along texel edges is met
    exactly.  Maps are thresholded at 1/2.  A map with no boundary gets ``±2``."""
    maps = np.asarray(maps)
    out = np.empty(maps.shape, np.float32)
    for a in range(0, len(maps), chunk):
        out[a:a + chunk] = _signed_distances(maps[a:a + chunk] >= 0.5)
    return out


def visibility_tables(bits: np.ndarray, normals: np.ndarray, cube: Cubemap, kind: str = "VDT",
                      resolution: int = 32, sub: int = 2, dtype=np.float32, threads=None,
                      progress=None, block: int = 256) -> np.ndarray:
    """The VDT (P, N, N) or visibility SAT (P, N+1, N+1) of every point straight from
    its visibility bits, ``block`` points at a time on ``threads`` threads (numpy
    releases the GIL in its loops): the float maps of all points are never held.
    Equal to :func:`visibility_distance_table` / :func:`visibility_sat` of
    :func:`visibility_maps`.  ``progress(fraction)`` runs on the calling thread after
    each block (it may raise to stop)."""
    n, sub = int(resolution), int(sub)
    packed = np.asarray(bits, dtype=np.uint8)
    frames = _frames(normals)
    local = _disk_samples(cube, n, sub)
    P = len(frames)
    m = n if kind == "VDT" else n + 1
    out = np.empty((P, m, m), dtype)

    def one(a):
        e = min(P, a + block)
        counts = _visible_counts(packed[a:e], frames[a:e], local, cube.resolution, n, sub)
        if kind == "VDT":
            out[a:e] = _signed_distances(counts.astype(np.int32) * 2 >= sub * sub)
        else:
            out[a:e] = visibility_sat(counts.astype(np.float32) * np.float32(1.0 / (sub * sub)))
        return e

    starts = range(0, P, block)
    workers = max(1, min(int(threads or os.cpu_count() or 1), len(starts)))
    if workers == 1:
        for a in starts:
            e = one(a)
            if progress is not None:
                progress(e / P)
        return out
    with ThreadPoolExecutor(workers) as pool:
        jobs = [pool.submit(one, a) for a in starts]
        try:
            for job in jobs:
                e = job.result()
                if progress is not None:
                    progress(e / P)
        except BaseException:
            for job in jobs:
                job.cancel()
            raise
    return out


def vdt_box(vdt: np.ndarray, px, py, half, lead=None) -> np.ndarray:
    """Eq. 9: visible fraction of the square ``(p, half side a)`` from one bilinear VDT
    look-up, ``clamp((a + D(p)) / 2a, 0, 1)`` (exact for a straight boundary parallel
    to a square edge)."""
    n = vdt.shape[-1]
    k = 0.5 * n
    x = (px + 1.0) * k - 0.5
    y = (py + 1.0) * k - 0.5
    D = _bilinear_centres(vdt, x, y, lead)
    return np.clip((half + D) / (2.0 * half), 0.0, 1.0)


def _bilinear_centres(T, x, y, lead):
    """Bilinear sample of texel-centre values ``T`` (..., N, N) at centre coordinates."""
    n = T.shape[-1]
    x = np.clip(x, 0.0, n - 1.0)
    y = np.clip(y, 0.0, n - 1.0)
    x0 = np.minimum(x.astype(np.int64), n - 2)
    y0 = np.minimum(y.astype(np.int64), n - 2)
    fx, fy = x - x0, y - y0
    if lead is None:
        g = (lambda r, c: T[r, c])
    else:                       # one flat take per corner (faster than three index arrays)
        flat = T.reshape(-1)
        base = np.asarray(lead, np.int64) * (n * n) + y0 * n + x0
        g = (lambda r, c: flat.take(base + (r - y0) * n + (c - x0)))
    top = g(y0, x0) * (1 - fx) + g(y0, x0 + 1) * fx
    bot = g(y0 + 1, x0) * (1 - fx) + g(y0 + 1, x0 + 1) * fx
    return top * (1 - fy) + bot * fy


def visibility_sat(maps: np.ndarray) -> np.ndarray:
    """Per-vertex SAT of the visibility maps' texel integrals, (P, N+1, N+1): the exact
    box-integral option of §4.3.

    Anchored at the disk centre (§2's GPU precision problem, the centred table of
    Hensley et al.): ``S(i, j)`` is the signed integral from the centre corner
    ``(N/2, N/2)`` to ``(i, j)``, i.e. the corner SAT minus its centre row and column
    (a function of ``i`` alone plus one of ``j`` alone, which cancels in the four
    look-ups of a box), so the values stay within a quadrant's area (1 instead of 4)
    and a float32 box near the normal, where most lights are, keeps its digits."""
    n = maps.shape[-1]
    S = summed_area(np.asarray(maps, dtype=np.float64) * (2.0 / n) ** 2)
    m = n // 2
    S = S - S[..., :, m:m + 1] - S[..., m:m + 1, :] + S[..., m:m + 1, m:m + 1]
    return S.astype(np.float32)


# --------------------------------------------------------------------------- #
# Per-vertex evaluation (eq. 5, Fig. 8)
# --------------------------------------------------------------------------- #

def disk_coordinates(centres: np.ndarray, tangent, bitangent, normal):
    """Disk-map position ``(px, py)`` (P, K) of each light centre in each vertex frame
    (§3, Fig. 3).  Centres below the horizon continue the map outside the unit disk
    (``|p| = sqrt(1 - cos)`` up to sqrt 2), so their squares overlap it partially."""
    c = np.asarray(centres, dtype=np.float64)
    local = np.stack([tangent @ c.T, bitangent @ c.T, normal @ c.T], axis=-1)
    return hemisphere_to_rsl_disk(local)


def view_frames(normals: np.ndarray, views: np.ndarray):
    """Frames ``(t', b', n)`` whose x axis is the view projected on the tangent plane
    (the isotropic tables are tabulated at view azimuth 0) and the view elevation."""
    n = np.asarray(normals, dtype=np.float64)
    v = np.asarray(views, dtype=np.float64)
    cos_o = np.einsum("ij,ij->i", n, v)
    tp = v - cos_o[:, None] * n
    ln = np.linalg.norm(tp, axis=1)
    t0, _ = orthonormal_frame(n)
    tp = np.where(ln[:, None] > 1e-9, tp / np.maximum(ln, 1e-300)[:, None], t0)
    bp = np.cross(n, tp)
    return tp, bp, np.arccos(np.clip(cos_o, 0.0, 1.0))


def visible_fraction(kind: str, table: np.ndarray, px, py, half) -> np.ndarray:
    """``avg_R V`` (P, K) for per-vertex tables: ``"VDT"`` (eq. 9, one look-up) or
    ``"SAT"`` (exact box integral of the visibility map, four look-ups, averaged over
    the part of the square inside the table: the map has no values beyond it, where a
    square near the horizon reaches; 1 for a square wholly outside)."""
    lead = np.arange(len(table))[:, None]
    if kind == "VDT":
        return vdt_box(table, px, py, half, lead=lead)
    area = _clipped_area(px, py, half)
    inside = area > 1e-12
    return np.where(inside, box_integral(table, px, py, half, lead=lead)
                    / np.where(inside, area, 1.0), 1.0)


class Evaluator:
    """Numpy per-vertex RSL shading (eq. 5 summed over lights, Fig. 8).

    ``lights``: :class:`SquareLights`; ``world_to_texture``: the world's rotation
    (centres are rotated, nothing recomputed).  ``tables(material)`` returns the
    material's :class:`BrdfTables` (cached by the caller)."""

    def __init__(self, lights: SquareLights, world_to_texture=None):
        R = np.eye(3) if world_to_texture is None else world_to_texture
        self.centres = lights.rotated(R)
        self.half = lights.half_sides[None, :]
        self.energy = lights.energy.astype(np.float64)

    def diffuse_factors(self, normals, vis_kind, vis_table, cos_table: BrdfTables):
        """View-independent ``avg_R V`` and ``avg_R cos`` (P, K) in the fixed frames."""
        t, b = orthonormal_frame(normals)
        px, py = disk_coordinates(self.centres, t, b, np.asarray(normals, np.float64))
        V = visible_fraction(vis_kind, vis_table, px, py, self.half)
        C = brdf_box(cos_table, None, None, px, py, self.half)
        return V, C

    def shade(self, material: brdf.Material, tables: BrdfTables, normals, views, V, C):
        """Outgoing radiance (P, 3) of points sharing ``material``; ``V``, ``C`` from
        :meth:`diffuse_factors`; ``views`` (P, 3) unit toward the eye (None is
        allowed for diffuse-only, non-layered materials)."""
        normals = np.asarray(normals, dtype=np.float64)
        weights = point_weights(material, normals, views)
        out = ((C * V) @ self.energy) * weights[0]
        if len(weights) == 1:
            return out
        tp, bp, theta_o = view_frames(normals, views)
        px, py = disk_coordinates(self.centres, tp, bp, normals)
        th = np.broadcast_to(theta_o[:, None], px.shape)
        for k, w in enumerate(weights[1:]):
            G = brdf_box(tables, k, th, px, py, self.half)
            out += ((G * V) @ self.energy) * w
        return out


def point_weights(material: brdf.Material, normals, views) -> list:
    """Per-point RGB weights (P, 3) of the tabulated sums: ``albedo/pi * W(n, wo)`` for
    the cosine table (Principled layering weight ``W``, 1 otherwise), then one per
    glossy term of :func:`..brdf.specular_terms` (Fresnel, colour, multiscatter; they
    depend on the view elevation only, so they stay outside the SATs)."""
    normals = np.asarray(normals, dtype=np.float64)
    P = len(normals)
    diffuse = np.zeros((P, 3))
    if material.has_diffuse:
        diffuse += np.asarray(material.diffuse_albedo) / np.pi
        if material.fresnel == "DIELECTRIC":
            diffuse *= brdf.diffuse_view_weight(material, normals, views)
    if material.is_diffuse_only or P == 0:
        return [diffuse]
    return [diffuse] + [w.astype(np.float64) for _, w in brdf.specular_terms(
        material, normals, views, np.array([[0.0, 0.0, 1.0]]))]
