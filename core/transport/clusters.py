"""Gather clusters: the scene's surface cut into patches of nearby, alike-facing triangles.

The bounced light a receiver gets is the light the surfaces its rays hit send back.  Those
surfaces are summarised by clusters (the gather points of Hasan, Pellacini, Bala 2006;
Enlighten's clusters): a receiver's transfer row is over clusters, not points, so it stays
short, and the frame's direct light is evaluated at one sample per cluster -- inside the
patch (a triangle's centroid), not at a vertex on a crease, where a contact shadow would
stand for the whole patch.  Clusters are the cells of a grid sized so there are about
``target`` of them, split by the dominant axis of the side's normal (a wall's two sides,
a box's faces never share a cluster).
"""

from __future__ import annotations

import numpy as np

#: shading points per cluster on average (the scene's cluster count is its points / this)
POINTS_PER_CLUSTER = 24


def normal_bucket(normals: np.ndarray) -> np.ndarray:
    """(N,) 0..5: the dominant axis of each normal and its sign (+x, -x, +y, -y, +z, -z)."""
    n = np.asarray(normals).reshape(-1, 3)
    axis = np.argmax(np.abs(n), axis=1)
    negative = n[np.arange(len(n)), axis] < 0.0
    return 2 * axis + negative


def cluster_patches(centroids: np.ndarray, normals: np.ndarray, areas: np.ndarray,
                    target: int) -> tuple[np.ndarray, int, float]:
    """``(cluster of each patch (N,) int32, cluster count K, cell side h)`` of surface
    patches (triangle sides: centroid, the side's normal, area): grid cells of side
    ``h = sqrt(total area / target)`` crossed with :func:`normal_bucket`, ids ordered by
    cell."""
    c = np.asarray(centroids).reshape(-1, 3)
    if len(c) == 0:
        return np.zeros(0, np.int32), 0, 1.0
    total = float(np.maximum(np.asarray(areas, np.float64), 0.0).sum())
    lo = c.min(axis=0)
    span = float(np.max(c.max(axis=0) - lo))
    h = np.sqrt(total / max(int(target), 1)) if total > 0.0 else span / max(int(target), 1)
    h = max(h, span * 1e-6, 1e-12)
    cell = np.floor((c - lo) / h).astype(np.int64)
    # one int64 key per patch, in the order of (cell x, y, z, bucket): at most 1e6 + 1
    # cells per axis (h >= span 1e-6), so the key stays below 2^63
    dims = cell.max(axis=0) + 1
    key = ((cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]) * 6
    del cell
    key += normal_bucket(normals)
    _, inverse = np.unique(key, return_inverse=True)
    inverse = inverse.reshape(-1)
    return inverse.astype(np.int32), int(inverse.max()) + 1, float(h)


def cluster_samples(cluster: np.ndarray, centroids: np.ndarray, areas: np.ndarray,
                    count: int) -> np.ndarray:
    """(K,) the patch of each cluster nearest its area-weighted centroid (where the frame
    evaluates the cluster's direct light); -1 for a cluster without patches."""
    c = np.asarray(cluster, np.int64)
    p = np.asarray(centroids, np.float64).reshape(-1, 3)
    w = np.maximum(np.asarray(areas, np.float64), 1e-300)
    centre = cluster_means(c, p, w, count)
    dist = np.linalg.norm(p - centre[c], axis=1)
    order = np.lexsort((dist, c))               # per cluster, nearest first
    first = np.ones(len(order), bool)
    first[1:] = c[order][1:] != c[order][:-1]
    out = np.full(count, -1, np.int64)
    out[c[order][first]] = order[first]
    return out


def sample_sets(cluster: np.ndarray, centroids: np.ndarray, areas: np.ndarray, count: int,
                cell: float):
    """``(patch (S,), cluster (S,), weight (S,))``, in cluster order: up to eight samples
    per cluster, one per occupied half-cell of its grid cell (the patch nearest the
    half-cell's centroid),
    each weighted by its half-cell's share of the cluster's area -- the cluster's mean
    direct light is their weighted sum (one sample at the centre underestimates a light
    that peaks inside the patch, as a lamp's does)."""
    c = np.asarray(cluster, np.int64)
    p = np.asarray(centroids).reshape(-1, 3)
    a = np.maximum(np.asarray(areas, np.float64), 0.0)
    if len(c) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    # a patch's half-cell within its cluster's cell: floor(2 y) - 2 floor(y), 0 or 1 per
    # axis (y = (p - lo) / cell as cluster_patches has it; halving h is exact)
    y = (p - p.min(axis=0)) / cell
    half = (np.floor(2.0 * y) - 2.0 * np.floor(y)).astype(np.int64)
    del y
    _, group = np.unique(c * 8 + half @ np.array([4, 2, 1]), return_inverse=True)
    group = group.reshape(-1)
    g = int(group.max()) + 1
    pick = cluster_samples(group, p, np.maximum(a, 1e-300), g)
    share = np.bincount(group, weights=a, minlength=g)
    owner = c[pick]
    total = np.bincount(owner, weights=share, minlength=count)
    weight = np.where(total[owner] > 0.0, share / np.maximum(total[owner], 1e-300),
                      1.0 / np.bincount(owner, minlength=count)[owner])
    return pick, owner, weight


def cluster_means(cluster: np.ndarray, values: np.ndarray, areas: np.ndarray,
                  count: int) -> np.ndarray:
    """(K, ...) area-weighted mean of per-patch ``values`` (N, ...) over each cluster."""
    c = np.asarray(cluster, np.int64)
    v = np.asarray(values).reshape(len(c), -1)
    w = np.maximum(np.asarray(areas, np.float64), 0.0)
    total = np.bincount(c, weights=w, minlength=count)
    out = np.stack([np.bincount(c, weights=w * v[:, k], minlength=count)
                    for k in range(v.shape[1])], axis=1)
    out /= np.maximum(total, 1e-300)[:, None]
    return out.reshape((count,) + np.asarray(values).shape[1:])
