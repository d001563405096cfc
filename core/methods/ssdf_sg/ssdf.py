"""Spherical signed distance functions of visibility and their PCA (Wang, Ren,
Gong, Snyder, Guo 2009, §5.1-5.2, eq. 23-24).

Per shading point the SSDF is an ``n x n`` image over the upper hemisphere of
the point's local frame, parameterised by the Shirley-Chiu concentric square
(``core.sphere.directions.shirley_chiu_to_hemisphere``; rows index ``b``, columns
``a``, both from -1 to 1, texel centres at ``-1 + (i + 1/2) 2/n``).  A texel
holds the signed *angular* distance (radians) from its direction to the
nearest visibility boundary, positive where the direction is visible (eq. 23).

Discretisation (what "exact" means here)
    1. Binary visibility is resampled from the stored cubemap bits into a
       supersampled ``H x H`` square (``H = n * VISIBILITY_SUPERSAMPLE``) by
       direction lookup (nearest cubemap texel of each square sample).
    2. The boundary is the set of midpoints ``normalize(d1 + d2)`` of every pair
       of 4-neighbour square samples whose visibility differs, plus the horizon:
       directions below the normal's horizon count as blocked (every method's
       visibility is zero there), so a visible direction is at most its
       elevation away from a boundary.
    3. The SSDF is evaluated at the centres of a ``(n s) x (n s)`` query square
       (``s = DISTANCE_SUPERSAMPLE``) as ``+-min angle(query, boundary)`` (sign
       from the visibility of the query direction's cubemap texel) and box
       filtered ``s x s`` down to ``n x n``: the §5.2 downsampling that
       prevents aliasing.

    The minimum over the boundary set is computed exactly (all boundary points
    of a point, by matrix products over chunks of points), so the result equals
    a brute-force loop over all boundary points (``tests/core/methods/ssdf_sg/test_ssdf.py``).

Special cases: a fully open hemisphere has no boundary except the horizon, its
SSDF is the elevation ``asin(z)`` (exact); a fully blocked hemisphere has no
visible direction at all and is set to ``-pi/2`` everywhere (every SG lobe is
then fully shadowed, eq. 30 clips ``theta_d`` to ``[-pi/2, pi/2]``).

Local frames: :func:`ssdf_frames`, not ``directions.orthonormal_frame``:
the SSDF is interpolated across triangles (PCA coefficients per pixel, §7),
which needs frames that vary continuously with the normal.  Duff et al.'s frame
flips its tangent where ``n_z`` changes sign; ours is
``t = normalize(REF x n)`` with a fixed oblique axis ``REF`` and is continuous
except within 2.6 degrees of ``+-REF`` (switches to a second axis there).
The GLSL twin is ``ssdf_frame`` in ``shaders/methods/ssdf_sg_lib.glsl``.

PCA (eq. 24): ``SSDF_x ~ mean + sum_j w_xj E_j``.  The covariance
``sum (x - m)(x - m)^T`` (``D = n^2`` squared, float64) is accumulated over
chunks of points, so memory is ``O(D^2 + chunk D)`` whatever the point count;
its eigenvectors are the exact principal components.  The number of terms is
the smallest multiple of 4 (RGBA packing) whose RMS reconstruction error over
all texels and points, ``sqrt(sum_{j > K} eigval_j / D)``, is within the error
budget (radians), capped at ``max_terms``.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from ...common.cache import memo
from ...sphere.directions import shirley_chiu_to_hemisphere, texel_of_components
from ...scene.visibility import unpack_visibility

#: square samples of binary visibility per SSDF texel edge (step 1)
VISIBILITY_SUPERSAMPLE = 4
#: query samples per SSDF texel edge, box-filtered down (step 3)
DISTANCE_SUPERSAMPLE = 2
#: fixed axis of the frame field (continuous except near +-REF)
FRAME_REF = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)
FRAME_REF_ALT = np.array([-3.0, 1.0, 2.0]) / math.sqrt(14.0)
#: |n . REF| above which FRAME_REF_ALT is used
FRAME_SWITCH = 0.999
BLOCKED_VALUE = -0.5 * math.pi


# --------------------------------------------------------------------------- frames

def ssdf_frames(normals):
    """(tangent, bitangent) completing unit ``normals`` (P, 3) to right-handed frames.

    ``t = normalize(REF x n)``, ``b = n x t``; REF switches to a second fixed
    axis when ``|n . REF| > FRAME_SWITCH``.  ``(t, b, n)`` maps local (x, y, z)
    to world.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    use_alt = np.abs(n @ FRAME_REF) > FRAME_SWITCH
    ref = np.where(use_alt[:, None], FRAME_REF_ALT, FRAME_REF)
    t = np.cross(ref, n)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
    b = np.cross(n, t)
    return t, b


def to_local(dirs, normals, tangents=None, bitangents=None):
    """World directions (..., 3) -> local (x, y, z) in each point's SSDF frame."""
    if tangents is None:
        tangents, bitangents = ssdf_frames(normals)
    d = np.asarray(dirs, dtype=np.float64)
    return np.stack([np.sum(d * tangents, -1), np.sum(d * bitangents, -1),
                     np.sum(d * np.asarray(normals, np.float64), -1)], axis=-1)


# --------------------------------------------------------------------------- square grids

def square_centres(n: int) -> np.ndarray:
    """Local directions of the ``n x n`` Shirley-Chiu texel centres, (n, n, 3) [row b, col a]."""
    c = -1.0 + (np.arange(n) + 0.5) * (2.0 / n)
    b, a = np.meshgrid(c, c, indexing="ij")
    return shirley_chiu_to_hemisphere(a, b)


@memo(8)
def _boundary_candidates(h: int):
    """Midpoint directions of all 4-neighbour pairs of the ``h x h`` square, and pair indices."""
    d = square_centres(h).reshape(-1, 3)
    idx = np.arange(h * h).reshape(h, h)
    first = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    second = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    mid = d[first] + d[second]
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    for a in (d, first, second, mid):
        a.setflags(write=False)
    return d, first, second, mid


def square_visibility(bits, normals, cube, size: int, tangents=None, bitangents=None):
    """Binary visibility (P, size*size) bool in each point's ``size x size`` square,
    by nearest-texel lookup of the direction in the bit-packed cubemap visibility."""
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if tangents is None:
        tangents, bitangents = ssdf_frames(normals)
    local_t = np.ascontiguousarray(square_centres(size).reshape(-1, 3).T, dtype=np.float32)
    frame = np.stack([tangents, bitangents, normals], axis=1).astype(np.float32)   # (P, 3, 3)
    # world component c of every sample: frame[:, :, c] (P, 3) @ local^T (3, Q)
    xyz = [np.ascontiguousarray(frame[:, :, c]) @ local_t for c in range(3)]
    texel = texel_of_components(xyz[0], xyz[1], xyz[2], cube.resolution)
    vis = unpack_visibility(np.asarray(bits), cube.size)
    return np.take_along_axis(vis, texel, axis=1)


# --------------------------------------------------------------------------- SSDF

@dataclass(frozen=True)
class SSDFGrid:
    """Resolution choices of one SSDF computation."""

    resolution: int = 32
    visibility_supersample: int = VISIBILITY_SUPERSAMPLE
    distance_supersample: int = DISTANCE_SUPERSAMPLE

    @property
    def visibility_size(self):
        return self.resolution * self.visibility_supersample

    @property
    def query_size(self):
        return self.resolution * self.distance_supersample

    @property
    def texels(self):
        return self.resolution * self.resolution


def boundary_points(vis_square, size: int):
    """Boundary midpoints of one or more binary squares.

    ``vis_square`` (P, size*size) bool.  Returns ``(point_index (B,), directions (B, 3))``:
    the midpoint of every 4-neighbour pair whose visibility differs, grouped by point.
    """
    _, first, second, mid = _boundary_candidates(size)
    differ = vis_square[:, first] != vis_square[:, second]
    pidx, cidx = np.nonzero(differ)
    return pidx, mid[cidx]


def _signed_distances(query_local, query_vis, bpoint, bdirs, count, any_visible):
    """SSDF at ``query_local`` (Q, 3) for ``count`` points: (count, Q) float64."""
    Q = len(query_local)
    q32 = np.ascontiguousarray(query_local.T, dtype=np.float32)      # (3, Q)
    best = np.full((count, Q), -2.0, dtype=np.float32)          # max cos to boundary
    if len(bdirs):
        counts = np.bincount(bpoint, minlength=count)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        has = counts > 0
        bd32 = bdirs.astype(np.float32)
        # points sorted by boundary count, in groups padded to the group's largest count
        # (repeating a point's first boundary point: duplicates do not change the maximum)
        order = np.argsort(counts, kind="stable")
        group = 16
        for g in range(0, count, group):
            idx = order[g:g + group]
            idx = idx[has[idx]]
            if len(idx) == 0:
                continue
            bmax = int(counts[idx].max())
            slot = np.minimum(np.arange(bmax)[None, :], counts[idx, None] - 1)
            padded = bd32[starts[idx, None] + slot]                       # (g, bmax, 3)
            dots = (padded.reshape(-1, 3) @ q32).reshape(len(idx), bmax, Q)   # one BLAS GEMM
            best[idx] = dots.max(axis=1)
    angle = np.arccos(np.clip(best.astype(np.float64), -1.0, 1.0))
    angle[best < -1.5] = np.inf                                 # no boundary point
    elevation = np.arcsin(np.clip(query_local[:, 2], 0.0, 1.0))[None, :]
    visible_dist = np.minimum(angle, elevation)
    # an occluded query with no boundary at all (a hole finer than the supersampled
    # square) lies on the boundary
    out = np.where(query_vis, visible_dist, -np.where(np.isinf(angle), 0.0, angle))
    out[~any_visible] = BLOCKED_VALUE
    return out


def compute_ssdf(bits, normals, cube, grid: SSDFGrid = SSDFGrid(), chunk: int = 64,
                 tangents=None, bitangents=None, threads: int | None = None,
                 cancel=None) -> np.ndarray:
    """SSDF images (P, n*n) float32 of bit-packed cubemap visibility (eq. 23, §5.2).

    ``bits`` (P, 6N^2/8) in ``cube`` texel order, ``normals`` (P, 3) unit.
    Work runs over chunks of ``chunk`` points on ``threads`` threads (numpy's
    matrix products and reductions release the GIL).  ``cancel()`` returning
    True stops between chunks (raises ``core.scene.visibility.Cancelled``).
    """
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    P = len(normals)
    n, s = grid.resolution, grid.distance_supersample
    hv, hq = grid.visibility_size, grid.query_size
    if tangents is None:
        tangents, bitangents = ssdf_frames(normals)
    query = square_centres(hq).reshape(-1, 3)
    out = np.empty((P, n * n), dtype=np.float32)
    bits = np.asarray(bits)

    def work(a, b):
        if cancel is not None and cancel():
            from ...common.parallel import Cancelled
            raise Cancelled()
        fr = (tangents[a:b], bitangents[a:b])
        vis_hi = square_visibility(bits[a:b], normals[a:b], cube, hv, *fr)
        vis_q = square_visibility(bits[a:b], normals[a:b], cube, hq, *fr) if hq != hv else vis_hi
        bpoint, bdirs = boundary_points(vis_hi, hv)
        d = _signed_distances(query, vis_q, bpoint, bdirs, b - a, vis_hi.any(axis=1))
        d = d.reshape(b - a, n, s, n, s).mean(axis=(2, 4))
        out[a:b] = d.reshape(b - a, n * n)

    spans = [(a, min(P, a + chunk)) for a in range(0, P, chunk)]
    threads = threads or min(2, os.cpu_count() or 1)
    if threads <= 1 or len(spans) <= 1:
        for a, b in spans:
            work(a, b)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            for f in [pool.submit(work, a, b) for a, b in spans]:
                f.result()
    return out


def brute_force_ssdf(vis_hi, vis_query, grid: SSDFGrid):
    """Eq. 23 by a plain loop over every boundary point (tests): (P, n*n) float64.

    ``vis_hi`` (P, H*H) and ``vis_query`` (P, (n s)^2) bool squares.
    """
    hv, hq, n, s = grid.visibility_size, grid.query_size, grid.resolution, grid.distance_supersample
    query = square_centres(hq).reshape(-1, 3)
    _, first, second, mid = _boundary_candidates(hv)
    out = np.empty((len(vis_hi), n * n))
    for p in range(len(vis_hi)):
        bnd = mid[vis_hi[p, first] != vis_hi[p, second]]
        vals = np.empty(len(query))
        for qi, q in enumerate(query):
            if not vis_hi[p].any():
                vals[qi] = BLOCKED_VALUE
                continue
            dist = np.arccos(np.clip(bnd @ q, -1, 1)).min() if len(bnd) else np.inf
            if vis_query[p, qi]:
                dist = min(dist, math.asin(min(max(q[2], 0.0), 1.0)))
                vals[qi] = dist
            else:
                vals[qi] = -dist if np.isfinite(dist) else 0.0
        out[p] = vals.reshape(n, s, n, s).mean(axis=(1, 3)).ravel()
    return out


# --------------------------------------------------------------------------- sampling

def square_coordinates(local):
    """Local directions (..., 3) -> continuous texture coordinates (u, v) in [0, 1]
    of the Shirley-Chiu square (u along a / columns, v along b / rows).  Directions
    below the horizon are projected onto it."""
    d = np.asarray(local, dtype=np.float64)
    # closed-form inverse of the concentric map (same formulas as the GLSL twin)
    z = np.clip(d[..., 2], 0.0, 1.0)
    r = np.sqrt(1.0 - z)
    x, y = d[..., 0], d[..., 1]
    ax, ay = np.abs(x), np.abs(y)
    phi = np.arctan2(y, x)
    # sector |x| >= |y|: a = r sign(x), b = a * (4/pi) * phi'  with phi' relative angle
    use_x = ax >= ay
    phix = np.where(x >= 0, phi, np.where(phi >= 0, phi - math.pi, phi + math.pi))
    a1 = np.where(x >= 0, r, -r)
    b1 = a1 * (4.0 / math.pi) * phix
    phiy = np.where(y >= 0, math.pi / 2 - phi, -math.pi / 2 - phi)
    b2 = np.where(y >= 0, r, -r)
    a2 = b2 * (4.0 / math.pi) * phiy
    a = np.where(use_x, a1, a2)
    b = np.where(use_x, b1, b2)
    return 0.5 * (a + 1.0), 0.5 * (b + 1.0)


def bilinear(images, u, v, n: int, gradient: bool = False):
    """GL-style bilinear lookup (texel centres at (i+1/2)/n, clamp to edge).

    ``images`` (P, C, n*n) or (C, n*n); ``u``, ``v`` (P, L) -> (P, L, C) (or (L, C)).
    ``gradient``: also the derivatives of the bilinear patch with respect to ``u`` and
    ``v`` (the slope of the cell the lookup falls in, as ``shaders/methods/ssdf_sg_lib.glsl``)."""
    xr = np.asarray(u) * n - 0.5
    yr = np.asarray(v) * n - 0.5
    x = np.clip(xr, 0.0, n - 1.0)
    y = np.clip(yr, 0.0, n - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), n - 2) if n > 1 else np.zeros_like(x, np.int64)
    y0 = np.minimum(np.floor(y).astype(np.int64), n - 2) if n > 1 else np.zeros_like(y, np.int64)
    fx, fy = x - x0, y - y0
    x1 = np.minimum(x0 + 1, n - 1)
    y1 = np.minimum(y0 + 1, n - 1)
    img = np.asarray(images)
    shared = img.ndim == 2

    def take(yy, xx):
        flat = yy * n + xx                                     # (P, L)
        if shared:
            return np.moveaxis(img[:, flat], 0, -1)            # (P, L, C)
        return np.take_along_axis(img, flat[:, None, :], axis=2).transpose(0, 2, 1)

    w00 = ((1 - fx) * (1 - fy))[..., None]
    w10 = (fx * (1 - fy))[..., None]
    w01 = ((1 - fx) * fy)[..., None]
    w11 = (fx * fy)[..., None]
    t00, t10, t01, t11 = take(y0, x0), take(y0, x1), take(y1, x0), take(y1, x1)
    value = t00 * w00 + t10 * w10 + t01 * w01 + t11 * w11
    if not gradient:
        return value
    fx, fy = fx[..., None], fy[..., None]
    # clamped to the edge (the outer half texel): flat in that coordinate
    du = n * ((t10 - t00) * (1 - fy) + (t11 - t01) * fy) * (x == xr)[..., None]
    dv = n * ((t01 - t00) * (1 - fx) + (t11 - t10) * fx) * (y == yr)[..., None]
    return value, du, dv


def lookup_ssdf(images, local, n: int):
    """theta_d = SSDF(p) for local lobe axes ``local`` (P, L, 3) from per-point images
    (P, n*n) (bilinear in the square).  Below the horizon the value continues as
    ``SSDF(horizon point) - depth angle`` (the direction is blocked and at least
    that far from any visible direction)."""
    u, v = square_coordinates(local)
    val = bilinear(np.asarray(images)[:, None, :], u, v, n)[..., 0]
    below = np.arcsin(np.clip(-np.asarray(local)[..., 2], 0.0, 1.0))
    return val - below


# --------------------------------------------------------------------------- PCA (eq. 24)

@dataclass
class SSDFBasis:
    """Eq. 24: ``SSDF ~ mean + coefficients @ eigen``."""

    resolution: int
    mean: np.ndarray          # (D,) float32
    eigen: np.ndarray         # (K, D) float32, orthonormal rows
    eigenvalues: np.ndarray   # (D,) float64, descending (all of them)
    point_count: int
    budget: float
    #: predicted RMS reconstruction error (radians) of K terms over all texels and points
    rms_error: float
    #: share of the blocked texels (SSDF < 0) whose reconstruction is still blocked, over
    #: all points (1 when nothing is blocked); set by :func:`ssdf_pca`.  The RMS budget is
    #: dominated by open sky: a ground's small occluders (a sun shadow) can be lost at a
    #: budget that looks tight, and this says how much of the occlusion the terms keep.
    occlusion_kept: float = 1.0
    #: the share of blocked texels the terms were chosen to keep (0: the RMS budget alone)
    occlusion_target: float = 0.0

    @property
    def terms(self) -> int:
        return len(self.eigen)

    def project(self, ssdf) -> np.ndarray:
        return ((np.asarray(ssdf, np.float32) - self.mean) @ self.eigen.T).astype(np.float32)

    def reconstruct(self, coefficients) -> np.ndarray:
        return self.mean + np.asarray(coefficients, np.float32) @ self.eigen


def choose_terms(eigenvalues, dim: int, budget: float, max_terms: int) -> int:
    """Smallest multiple of 4 (at least 4) with ``sqrt(sum_{j>K} ev_j / dim) <= budget``."""
    ev = np.clip(np.asarray(eigenvalues, np.float64), 0.0, None)
    tail = np.concatenate([np.cumsum(ev[::-1])[::-1], [0.0]])       # tail[k] = sum_{j>=k}
    rms = np.sqrt(tail / dim)
    cap = term_cap(dim, max_terms)
    for k in range(4, cap + 1, 4):
        if k >= len(rms) or rms[min(k, len(rms) - 1)] <= budget:
            return min(k, cap)
    return cap


class CovarianceAccumulator:
    """Streaming mean and covariance of row vectors (float64 sums over chunks)."""

    def __init__(self, dim: int):
        self.count = 0
        self.total = np.zeros(dim)
        self.gram = np.zeros((dim, dim))
        self.shift = None        # first chunk's mean, subtracted for conditioning

    def add(self, rows):
        x = np.asarray(rows, np.float64)
        if len(x) == 0:
            return
        if self.shift is None:
            self.shift = x.mean(axis=0)
        y = x - self.shift
        self.count += len(y)
        self.total += y.sum(axis=0)
        self.gram += y.T @ y

    def finish(self):
        m = self.total / max(self.count, 1)
        cov = self.gram / max(self.count, 1) - np.outer(m, m)
        return m + self.shift, 0.5 * (cov + cov.T)


def term_cap(dim: int, max_terms: int) -> int:
    """Most PCA terms :func:`choose_terms` may pick (a multiple of 4, at least 4)."""
    return max(4, min(int(max_terms) // 4 * 4, dim // 4 * 4 if dim >= 4 else 4))


def _covariance_eigen(chunks, dim: int):
    """``(mean (D,), eigenvalues (D,) descending, clipped >= 0, eigenvectors (D, D) as
    columns, row count)`` of SSDF rows streamed over ``chunks``."""
    acc = CovarianceAccumulator(dim)
    for rows in chunks:
        acc.add(rows)
    if acc.count == 0:
        raise ValueError("no SSDF rows to fit")
    mean, cov = acc.finish()
    ev, vec = np.linalg.eigh(cov)
    order = np.argsort(ev)[::-1]
    return mean, np.clip(ev[order], 0.0, None), vec[:, order], acc.count


def _leading_rows(vec, k: int, dim: int) -> np.ndarray:
    """The first ``k`` eigenvectors as float32 rows (zero rows past the dimension)."""
    rows = np.zeros((k, dim), np.float32)
    kk = min(k, vec.shape[1])
    rows[:kk] = vec[:, :kk].T
    return rows


def _tail_rms(ev, k: int, dim: int) -> float:
    """RMS reconstruction error (radians) of ``k`` terms: the dropped eigenvalues' share."""
    return float(math.sqrt(max(float(ev[k:].sum()), 0.0) / dim))


def fit_basis(chunks, resolution: int, budget: float, max_terms: int = 64) -> SSDFBasis:
    """PCA basis from an iterable of SSDF chunks (rows (p, n*n)), eq. 24."""
    dim = resolution * resolution
    mean, ev, vec, count = _covariance_eigen(chunks, dim)
    k = choose_terms(ev, dim, budget, max_terms)
    return SSDFBasis(resolution, mean.astype(np.float32), _leading_rows(vec, k, dim), ev,
                     count, float(budget), _tail_rms(ev, k, dim))


#: SSDF rows kept in memory between the two PCA passes (else recomputed)
CACHE_BYTES = 512 * 1024 * 1024


def ssdf_pca(bits, normals, cube, grid: SSDFGrid, budget: float, max_terms: int = 64,
             chunk_points: int = 8192, cancel=None, threads=None, progress=None,
             occlusion_target: float = 0.0):
    """SSDFs of all points compressed by PCA (eq. 24), streamed over chunks of points.

    Pass 1 accumulates the covariance chunk by chunk; pass 2 projects every
    SSDF on the chosen eigen-images (SSDFs are kept between the passes when they
    fit in :data:`CACHE_BYTES`, else recomputed) and counts the blocked texels the
    compression keeps blocked (``basis.occlusion_kept``).  The RMS ``budget`` picks the
    number of terms; with ``occlusion_target`` > 0 more terms (in steps of 4, up to
    ``max_terms``) are taken until that share of the blocked texels stays blocked (the
    RMS is dominated by open sky: small occluders -- a low sun's shadow on a ground -- can
    be lost at a budget that looks tight).  Returns ``(basis, coefficients (P, K) float32)``.
    """
    normals = np.asarray(normals, np.float64).reshape(-1, 3)
    P = len(normals)
    spans = [(a, min(P, a + chunk_points)) for a in range(0, P, chunk_points)]
    keep = P * grid.texels * 4 <= CACHE_BYTES
    cache = []
    done = [0]

    def rows(a, b):
        r = compute_ssdf(bits[a:b], normals[a:b], cube, grid, cancel=cancel, threads=threads)
        done[0] += b - a
        if progress is not None:
            progress(done[0], P * (1 if keep else 2))
        return r

    def first_pass():
        for a, b in spans:
            r = rows(a, b)
            if keep:
                cache.append(r)
            yield r

    dim = grid.texels
    mean, ev, vec, count = _covariance_eigen(first_pass(), dim)
    k0 = choose_terms(ev, dim, budget, max_terms)
    cap = max(k0, term_cap(dim, max_terms)) if occlusion_target > 0.0 else k0
    # every candidate term; the basis returned keeps the first K of them
    widest = SSDFBasis(grid.resolution, mean.astype(np.float32), _leading_rows(vec, cap, dim),
                       ev, count, float(budget), _tail_rms(ev, cap, dim),
                       occlusion_target=float(occlusion_target))
    mean, eigen = widest.mean, widest.eigen
    steps = [k0] + list(range(k0 + 4, cap + 1, 4))
    coeffs = np.empty((P, cap), np.float32)
    blocked, kept = 0, np.zeros(len(steps), np.int64)
    for i, (a, b) in enumerate(spans):
        r = np.asarray(cache[i] if keep else rows(a, b), np.float32)
        c = widest.project(r)
        coeffs[a:b] = c
        rec = mean + c[:, :steps[0]] @ eigen[:steps[0]]
        b_now, k_now = occlusion_counts(r, rec)
        blocked += b_now
        kept[0] += k_now
        for j in range(1, len(steps)):
            rec += c[:, steps[j - 1]:steps[j]] @ eigen[steps[j - 1]:steps[j]]
            kept[j] += occlusion_counts(r, rec)[1]
    share = kept / blocked if blocked else np.ones(len(steps))
    pick = 0
    if occlusion_target > 0.0:
        meets = np.flatnonzero(share >= occlusion_target)
        pick = int(meets[0]) if len(meets) else len(steps) - 1
    K = steps[pick]
    basis = replace(widest, eigen=np.ascontiguousarray(eigen[:K]), rms_error=_tail_rms(ev, K, dim),
                    occlusion_kept=float(share[pick]))
    return basis, np.ascontiguousarray(coeffs[:, :K])


def occlusion_counts(exact, reconstructed):
    """``(blocked texels, of them still blocked after compression)`` of SSDF rows: a texel
    is blocked where its signed distance is negative (eq. 23)."""
    blocked = np.asarray(exact) < 0.0
    return int(blocked.sum()), int((blocked & (np.asarray(reconstructed) < 0.0)).sum())
