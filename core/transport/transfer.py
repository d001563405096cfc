"""Each receiver's transfer row over the gather clusters, from the rays the visibility
precompute traces (Hasan, Pellacini, Bala 2006: direct-to-indirect transfer; Sloan, Kautz,
Snyder 2002: interreflected transfer built from the same rays as the shadowed transfer).

A receiver ``p`` traces one ray per cubemap texel ``k`` of its hemisphere.  A ray that
hits the scene at a surface sees the radiance that surface sends back; a diffuse surface
sends ``L = rho E / pi``, the same in every direction.  With the hit surface's radiance
taken as its cluster's (:mod:`.clusters`), the bounced irradiance is

    E_ind(p) = sum_k  L_cluster(hit_k)  max(0, n_p . w_k) dw_k  =  sum_m  T[p, m] L_m,

so ``T[p, m]`` sums ``cos dw`` over the rays of ``p`` that hit cluster ``m`` (the hit
triangle's side names the cluster; a hit on a surface's back reads its back side, or
nothing when no back side was traced: a closed mesh's inside, an open surface's back
that nothing faces).  A row keeps its :data:`ROW_WIDTH` largest
entries, scaled so the row's sum -- the share of the hemisphere that sees the scene,
cosine-weighted -- is kept exactly (a uniformly bright scene bounces exactly as much
light as the full row would).  ``T`` between clusters -- the rows of the clusters' own
sample points -- carries further bounces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.visibility import hit_texels

#: entries kept per receiver row (cluster id int32 + weight float16 each: 192 bytes a
#: point before compression)
ROW_WIDTH = 32
#: entries kept per cluster row (the cluster-to-cluster transfer of further bounces)
CLUSTER_ROW_WIDTH = 64
#: at most this many (receiver, cluster) cells are accumulated densely per chunk of rays
#: (beyond it the chunk's entries are sorted instead)
DENSE_CELLS = 4_000_000
#: bytes a receiver takes while the precompute gathers its row: per entry a cluster id
#: (int32) and a weight (float32), and once a point inside its surface (float32 x 3) and
#: its row's rest (float32)
ENTRY_BYTES, INNER_BYTES = 8, 16
#: default budget of the receivers' rows (MiB): past it, rows keep fewer entries
#: (:func:`row_width`)
ROW_BUDGET_MIB = 256


def row_width(points: int, budget_mib: float) -> tuple[int, str]:
    """``(entries per receiver row, note)``: :data:`ROW_WIDTH`, or as many as ``points``
    rows fit in ``budget_mib`` (at least one).  A receiver's row keeps its largest entries
    and the sum of the rest (``TransferRows.rest``), which the frame reads through the
    clusters of the receiver's own triangles (the mean radiance they see:
    ``core.transport.bounce.rest_radiance``).  The note says when rows are cut."""
    per_point = budget_mib * 2 ** 20 / max(int(points), 1)
    width = int(min(ROW_WIDTH, max(1, (per_point - INNER_BYTES) // ENTRY_BYTES)))
    if width == ROW_WIDTH:
        return width, ""
    need = points * (ROW_WIDTH * ENTRY_BYTES + INNER_BYTES) / 2 ** 20
    return width, (f"Bounced light: rows of {width} entries per point (of {ROW_WIDTH}): "
                   f"{points} points' full rows would take {need:.0f} MiB, past the "
                   f"{budget_mib:.0f} MiB Bounce Rows Budget")


@dataclass
class Patches:
    """The sides of the static meshes' triangles, mesh after mesh: each mesh's triangles'
    front sides, then (a two-sided mesh) their back sides -- centroid, the side's normal
    (its corners' shading normals averaged; flipped for a back side) and area.
    ``offsets[i]`` is where mesh ``i``'s sides start.  Single precision: a
    thousand instances have tens of millions of sides (a cluster's grid cell and sample
    need no more)."""

    centroids: np.ndarray        # (N, 3) float32
    normals: np.ndarray          # (N, 3) float32
    areas: np.ndarray            # (N,) float32
    offsets: np.ndarray          # (meshes + 1,)

    @classmethod
    def of_meshes(cls, meshes):
        from ..scene.mesh import triangle_areas
        cen, nrm, area, offsets = [], [], [], [0]
        for arrays in meshes:
            tri = arrays.triangles[:arrays.front_triangles]
            tp = arrays.positions[arrays.corner_verts[tri]]
            n = arrays.corner_normals[tri].sum(axis=1)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
            n = n.astype(np.float32)
            sides = [n, -n] if arrays.two_sided else [n]
            c, a = tp.mean(axis=1).astype(np.float32), triangle_areas(tp).astype(np.float32)
            for side in sides:
                cen.append(c)
                nrm.append(side)
                area.append(a)
            offsets.append(offsets[-1] + len(tri) * len(sides))
        cat = (lambda xs, shape, dtype: np.concatenate(xs) if xs else np.zeros(shape, dtype))
        return cls(cat(cen, (0, 3), np.float32), cat(nrm, (0, 3), np.float32),
                   cat(area, (0,), np.float32), np.asarray(offsets, np.int64))

    def offsets_only(self) -> "Patches":
        """The same sides' places (:meth:`of_mesh`) without their arrays: what the hit map
        and the stored blobs need once the clusters and samples are made."""
        empty = np.zeros((0, 3), np.float32)
        return Patches(empty, empty, np.zeros(0, np.float32), self.offsets)

    def of_mesh(self, i: int, arrays):
        """``(front (T,), back (T,) or None)``: where mesh ``i``'s triangles' sides are."""
        t = arrays.front_triangles
        a = int(self.offsets[i])
        return np.arange(a, a + t), (np.arange(a + t, a + 2 * t) if arrays.two_sided else None)


@dataclass
class HitMap:
    """What a ray hitting occluder triangle ``t`` (in the occluder scene's order) reads:
    the gather cluster of its front side and of its back side (-1: no back side traced --
    a closed mesh's inside, an open surface's back that nothing faces), and the
    triangle's geometric normal turned to its front (the side its shading normals face),
    made from the occluders' own corners when read (a thousand instances' normals and
    corners held were 24 B a triangle more)."""

    front: np.ndarray            # (T,) int32
    back: np.ndarray             # (T,) int32
    #: (T,) bool: the triangle's winding normal points to its back
    turn: np.ndarray
    #: the occluders' corners (V, 3) float32 and triangles (T, 3) into them
    vertices: np.ndarray
    triangles: np.ndarray

    @classmethod
    def of_meshes(cls, meshes, patches: Patches, cluster_of_patch: np.ndarray,
                  occluders=None):
        """The map of several meshes' occluder triangles, concatenated in order
        (``core.scene.mesh.occluder_index`` of each), their sides' clusters given per
        patch of ``patches``; ``occluders`` the same triangles as the trace holds them
        (core.scene.mesh.Occluders or (T, 3, 3) corners; None: made here)."""
        from ..scene.mesh import Occluders, occluder_index, occluder_mesh
        front, back, turn = [], [], []
        cl = np.asarray(cluster_of_patch, np.int32)
        for i, arrays in enumerate(meshes):
            t = occluder_index(arrays)
            f, b = patches.of_mesh(i, arrays)
            front.append(cl[f[t]])
            back.append(cl[b[t]] if b is not None else np.full(len(t), -1, np.int32))
            tri = arrays.triangles[t]
            tp = arrays.positions[arrays.corner_verts[tri]]
            g = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
            turn.append(np.einsum("ij,ij->i", g, arrays.corner_normals[tri].sum(axis=1)) < 0.0)
        if occluders is None:
            occluders = Occluders.join([occluder_mesh(a)[0] for a in meshes])
        if isinstance(occluders, Occluders):
            vertices, triangles = occluders.vertices, occluders.triangles
        else:
            vertices = np.asarray(occluders, np.float32).reshape(-1, 3)
            triangles = np.arange(len(vertices), dtype=np.int32).reshape(-1, 3)
        cat = (lambda xs, dtype: np.concatenate(xs) if xs else np.zeros(0, dtype))
        out = cls(cat(front, np.int32), cat(back, np.int32), cat(turn, bool), vertices,
                  triangles)
        if len(out.front) != len(triangles):
            raise ValueError("the hit map's meshes are not the occluders' triangles")
        return out

    def normal(self, t: np.ndarray) -> np.ndarray:
        """(n, 3) the geometric normals of triangles ``t``, turned to their front."""
        p = self.vertices[self.triangles[t]].astype(np.float64)
        g = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        g[self.turn[t]] *= -1.0
        return g

    def corner(self, t: np.ndarray) -> np.ndarray:
        """(n, 3) a corner of each of triangles ``t`` (a point of its plane)."""
        return self.vertices[self.triangles[t, 0]].astype(np.float64)


def top_entries(acc: np.ndarray, width: int, keep_sum: bool = True):
    """``(columns (N, width) int32, weights (N, width) float32, rest (N,))``: each row's
    ``width`` largest entries of the dense ``acc`` (N, K), scaled to keep the row's sum
    (``rest`` 0), or as they are with the rest of the row's sum in ``rest``."""
    n, k = acc.shape
    width = min(width, k)
    if width == 0:
        return (np.zeros((n, 0), np.int32), np.zeros((n, 0), np.float32),
                acc.sum(axis=1) * (not keep_sum))
    cols = np.argpartition(-acc, width - 1, axis=1)[:, :width] if width < k else \
        np.broadcast_to(np.arange(k), (n, k)).copy()
    kept = np.take_along_axis(acc, cols, axis=1)
    return (cols.astype(np.int32),) + _kept(kept, kept.sum(axis=1), acc.sum(axis=1), keep_sum)


def _kept(kept, kept_sum, total, keep_sum):
    """``(weights, rest)`` of rows' kept entries (N, W) with their sums and the rows'."""
    if not keep_sum:
        return kept.astype(np.float32), np.maximum(total - kept_sum, 0.0)
    scale = np.where(kept_sum > 0.0, total / np.maximum(kept_sum, 1e-300), 0.0)
    return (kept * scale[:, None]).astype(np.float32), np.zeros(len(total))


def sparse_top(rows: np.ndarray, cols: np.ndarray, weights: np.ndarray, n: int, width: int,
               keep_sum: bool = True):
    """:func:`top_entries` of the sparse matrix with entries ``(rows, cols, weights)``
    (duplicates summed) and ``n`` rows."""
    out_c = np.zeros((n, width), np.int32)
    out_w = np.zeros((n, width), np.float64)
    if len(rows) == 0:
        return out_c, out_w.astype(np.float32), np.zeros(n)
    key = rows.astype(np.int64) * (int(cols.max()) + 1) + cols
    uniq, inverse = np.unique(key, return_inverse=True)
    sums = np.bincount(inverse, weights=weights)
    r, c = uniq // (int(cols.max()) + 1), uniq % (int(cols.max()) + 1)
    order = np.lexsort((-sums, r))
    r, c, s = r[order], c[order], sums[order]
    start = np.searchsorted(r, np.arange(n))
    rank = np.arange(len(r)) - start[r]
    total = np.bincount(r, weights=s, minlength=n)
    keep = rank < width
    kept = np.bincount(r[keep], weights=s[keep], minlength=n)
    out_c[r[keep], rank[keep]] = c[keep]
    out_w[r[keep], rank[keep]] = s[keep]
    return (out_c,) + _kept(out_w, kept, total, keep_sum)


def cluster_rows(owner: np.ndarray, weight: np.ndarray, columns: np.ndarray,
                 weights: np.ndarray, clusters: int, width: int = CLUSTER_ROW_WIDTH,
                 block: int = DENSE_CELLS):
    """``(columns (K, width) int32, weights (K, width) float32)``: each cluster's row, the
    ``weight``-weighted sum of its samples' rows (``columns``/``weights`` (S, W), samples
    in cluster order, ``owner`` (S,) their cluster), its ``width`` largest entries kept
    (:func:`sparse_top`).  About ``block`` entries at a time, cut where the cluster
    changes: a scatter's samples' entries at once were the precompute's peak."""
    owner = np.asarray(owner, np.int64)
    out_c = np.zeros((clusters, width), np.int32)
    out_w = np.zeros((clusters, width), np.float32)
    step = max(1, int(block) // max(columns.shape[1], 1))
    a = 0
    while a < len(owner):
        b = min(len(owner), a + step)
        if b < len(owner):              # back to the start of owner[b]'s cluster
            b = max(int(np.searchsorted(owner, owner[b], "left")), a + 1)
            b = int(np.searchsorted(owner, owner[b - 1], "right"))
        lo, hi = int(owner[a]), int(owner[b - 1]) + 1
        w = (weights[a:b] * np.asarray(weight[a:b])[:, None]).reshape(-1)
        keep = w > 0.0
        out_c[lo:hi], out_w[lo:hi], _ = sparse_top(
            np.repeat(owner[a:b] - lo, columns.shape[1])[keep],
            columns[a:b].reshape(-1)[keep].astype(np.int64), w[keep], hi - lo, width)
        a = b
    return out_c, out_w


class TransferRows:
    """Receiver rows accumulated as the trace hands on its chunks of rays (any thread:
    each chunk writes its own rows)."""

    def __init__(self, count: int, clusters: int, hits: HitMap, cube,
                 width: int = ROW_WIDTH, inner: np.ndarray | None = None,
                 keep_sum: bool = True):
        self.clusters = int(clusters)
        self.hits = hits
        self.dirs = np.asarray(cube.directions, np.float64)
        self.solid = np.asarray(cube.solid_angles, np.float64)
        self.subset = hit_texels(cube)
        #: (3, D) float32 texel directions times their solid angles: ``n . w dw``
        self.dirs_solid = np.ascontiguousarray((self.dirs * self.solid[:, None]).T, np.float32)
        self.width = int(width)
        #: (count, 3) a point inside each receiver's own surface (its triangles' centroids
        #: averaged): which side of a touching surface the receiver is on
        self.inner = inner
        self.columns = np.zeros((count, self.width), np.int32)
        self.weights = np.zeros((count, self.width), np.float32)
        #: a row's entries past its ``width`` largest: scaled into them (``keep_sum``), or
        #: their sum kept in ``rest`` (the receivers': :func:`row_width`)
        self.keep_sum = bool(keep_sum)
        self.rest = np.zeros(count if not keep_sum else 0, np.float32)

    def add(self, start: int, stop: int, normals: np.ndarray, blocked: np.ndarray,
            prim: np.ndarray):
        """Rows ``start:stop`` from their traced rays: ``blocked`` (n, D) the texels whose
        ray is blocked, ``prim`` (n, D) the occluder triangle the blocked rays of the hit
        texels (``core.scene.visibility.hit_texels``) hit first (-1: not traced; ``-3 -
        triangle``: a surface the receiver touches, read on the side its own surface lies
        on).  The hits stand for every blocked ray of their receiver: scaled by all its
        blocked rays' ``cos dw`` over the hits' (a ratio estimate: a row's sum stays the
        blocked share)."""
        n = stop - start
        nrm = np.asarray(normals, np.float32).reshape(-1, 3)
        cosw = nrm @ self.dirs_solid                                   # (n, D) cos dw
        np.maximum(cosw, 0.0, out=cosw)
        cosw[~blocked] = 0.0                                           # blocked rays only
        full = cosw.sum(axis=1, dtype=np.float64)
        found = (prim >= 0) | (prim <= -3)
        part = np.where(found, cosw, 0.0).sum(axis=1, dtype=np.float64)
        scale = np.where(part > 0.0, full / np.maximum(part, 1e-300), 0.0)
        i, k = np.nonzero(found)
        if len(i) == 0 or self.clusters == 0:
            self.columns[start:stop] = 0
            self.weights[start:stop] = 0.0
            if not self.keep_sum:
                self.rest[start:stop] = 0.0
            return
        t = prim[i, k].astype(np.int64)
        touching = t <= -3
        t = np.where(touching, -3 - t, t)
        g = self.hits.normal(t)
        front = np.einsum("ij,ij->i", self.dirs[k], g) < 0.0
        if touching.any() and self.inner is not None:
            # a touching surface's side is the one the receiver's own surface lies on
            j = np.nonzero(touching)[0]
            front[j] = np.einsum("ij,ij->i", self.inner[start + i[j]] - self.hits.corner(t[j]),
                                 g[j]) > 0.0
        m = np.where(front, self.hits.front[t], self.hits.back[t])
        ok = m >= 0
        i, m, w = i[ok], m[ok], (cosw[i, k].astype(np.float64) * scale[i])[ok]
        if n * self.clusters <= DENSE_CELLS:
            acc = np.bincount(i * self.clusters + m, weights=w,
                              minlength=n * self.clusters).reshape(n, self.clusters)
            cols, wts, rest = top_entries(acc, self.width, self.keep_sum)
            self.columns[start:stop, :cols.shape[1]] = cols
            self.weights[start:stop, :wts.shape[1]] = wts
        else:
            cols, wts, rest = sparse_top(i, m, w, n, self.width, self.keep_sum)
            self.columns[start:stop] = cols
            self.weights[start:stop] = wts
        if not self.keep_sum:
            self.rest[start:stop] = rest
