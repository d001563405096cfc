"""Visibility over the hemisphere's disk map as distance tables (Xu, Jia, Hu, Tai 2006, §4.3,
eq. 9) or summed-area tables, and the summed-area look-ups RSL's BRDF tables share: what RSL
and the shadow fields of moving objects read a square's visible fraction from."""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..sphere.directions import (
    Cubemap,
    hemisphere_to_rsl_disk,
    orthonormal_frame,
    rsl_disk_to_hemisphere,
    texel_of_components,
)


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


def disk_coordinates(centres: np.ndarray, tangent, bitangent, normal):
    """Disk-map position ``(px, py)`` (P, K) of each light centre in each vertex frame
    (§3, Fig. 3).  Centres below the horizon continue the map outside the unit disk
    (``|p| = sqrt(1 - cos)`` up to sqrt 2), so their squares overlap it partially."""
    c = np.asarray(centres, dtype=np.float64)
    local = np.stack([tangent @ c.T, bitangent @ c.T, normal @ c.T], axis=-1)
    return hemisphere_to_rsl_disk(local)
