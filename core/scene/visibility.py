"""Per-point binary visibility over cubemap directions, traced with Embree.

For every shading point only the texels of the upper hemisphere of its
normal (``n . w > 0``) are traced; the others are stored as 0 (they carry no
light because of the cosine).  Results are bit-packed along the texel axis:
``(P, 6*N*N/8)`` uint8, bit order of ``numpy.packbits`` (big-endian in a byte).

Rays start at ``p + offset * n`` with ``offset`` relative to the scene's
bounding diagonal (default 1e-4 of it), and at least 16 float32 ulps of the
point's coordinates so scenes far from the origin do not shadow themselves.
The origin is not moved along the ray, so occluders in contact (a wall
meeting a floor) still block.  A point whose step along its normal crosses a surface it
touches (a smooth-shaded rim resting on a ground) starts from just inside its adjacent
face instead (:func:`contact_origins`).

Work is split in chunks of points handed to a thread pool; Embree releases
the GIL during ``run``, so all cores trace, and two threads per core let one
thread's numpy set-up overlap the others' tracing.  Memory stays bounded by
the chunk size (about half a million rays in flight per thread, and at most
:data:`RAYS_IN_FLIGHT` over all threads); with ``consume`` the rows are handed on
as they are traced (the precompute compresses them) instead of being kept.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..common.cache import Cache
from ..sphere.directions import Cubemap
from ..common.parallel import Cancelled, default_threads
from .mesh import Occluders, face_interiors

try:
    from embreex import rtcore_scene as _rtcs
    from embreex.mesh_construction import TriangleMesh as _TriangleMesh
except ImportError:  # pragma: no cover - reported to the user by the add-on
    _rtcs = None
    _TriangleMesh = None


def have_embree() -> bool:
    return _rtcs is not None


def build_occluder_scene(triangle_positions):
    """An Embree scene of (T, 3, 3) world triangles, or of core.scene.mesh.Occluders (held
    indexed): every one given, but those with a non-finite corner (Embree cannot hold
    them).  Which faces cast shadows is the caller's choice -- the precompute leaves out
    the zero-area faces it warns about (:func:`.mesh.occluder_triangles`); a face of zero
    area in float32 is never hit."""
    if _rtcs is None:
        raise RuntimeError("embreex is not installed; it ships as a wheel with the extension")
    scene = _rtcs.EmbreeScene()
    if isinstance(triangle_positions, Occluders):
        vertices = np.ascontiguousarray(triangle_positions.vertices, dtype=np.float32)
        tri = triangle_positions.triangles
        tri = np.ascontiguousarray(tri[np.isfinite(vertices).all(axis=1)[tri].all(axis=1)],
                                   dtype=np.int32)
        if len(tri):
            _TriangleMesh(scene, vertices, tri)
        return scene
    tri = np.ascontiguousarray(triangle_positions, dtype=np.float32).reshape(-1, 3, 3)
    tri = np.ascontiguousarray(tri[np.isfinite(tri).all(axis=(1, 2))])
    if len(tri):
        _TriangleMesh(scene, tri)
    return scene


def ray_step(points: np.ndarray, offset: float) -> np.ndarray:
    """Per-point distance to step off the surface: the scene-relative ``offset`` or
    16 float32 ulps of the coordinates, whichever is larger (rays are float32)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.maximum(float(offset), 16.0 * np.finfo(np.float32).eps * np.abs(p).max(axis=1))


def hemisphere_mask(normals: np.ndarray, cube: Cubemap) -> np.ndarray:
    """(P, D) bool: the texels traced for each normal, ``n . w > 0`` in float32."""
    n = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
    return (n @ _directions32(cube).T) > 0.0


def ray_origins(points: np.ndarray, normals: np.ndarray, offset: float) -> np.ndarray:
    """(P, 3) float32 ray origins: each point stepped off its surface along the normal."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    return np.ascontiguousarray(p + ray_step(p, offset)[:, None] * n, dtype=np.float32)


#: how far into an adjacent face a moved origin sits: this share of the way from the point
#: to the face's centroid (then stepped off the face along its own normal)
CONTACT_SHARE = 0.02
#: faces within ~0.26 degrees of the point's normal are not probed
CONTACT_ALIGNED = 0.99999
#: triangles probed at a time by :func:`contact_origins` (bounds its temporaries)
CONTACT_CHUNK = 200_000


def contact_origins(scene, points: np.ndarray, normals: np.ndarray, tri_positions: np.ndarray,
                    tri_points: np.ndarray, offset: float):
    """``(origins (P, 3) float32, moved (P,) bool)``: :func:`ray_origins`, but for a point
    whose step along its normal crosses another surface the point touches.

    A smooth-shaded rim resting on a ground (a cylinder's bottom ring: normal 43 degrees
    down) steps under the ground and traces the world from below it: blind upward,
    seeing through the floor downward, and barycentric mixing carries that up the whole
    side.  Each adjacent face offers a sample just inside it (:data:`CONTACT_SHARE` of
    the way to its centroid, stepped off along its own normal); the step is cut off when
    the segment from the stepped origin to a face's sample is blocked.  Which side of the
    touched surface is the outside has no local answer, so the faces vote as they weigh
    the smooth normal, by corner angle: when the cut-off faces weigh more than those the
    origin still reaches, it moves to the sample of the cut-off face most aligned with
    the normal (a cylinder's side, 180 degrees, against its bottom cap's 165).
    ``tri_positions`` (T, 3, 3) and ``tri_points`` (T, 3): the points' triangles and
    the point index of each corner (indices into ``points``)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    tp_all = np.asarray(tri_positions, dtype=np.float64).reshape(-1, 3, 3)
    tri_pts = np.asarray(tri_points, dtype=np.int64).reshape(-1, 3)
    step = ray_step(p, offset)
    origins = ray_origins(p, n, offset)
    # a flat point on a concave crease (a room's corner) steps along its normal into the
    # plane of the face across the crease: its rays start on that face (hit at t = 0 or
    # slip through it).  Cycles shades the inside of a face, so the origin of a point
    # whose own faces all lie in its tangent plane also moves a little into them
    # (CONTACT_SHARE of the way to their centroids; smooth points keep the plain step)
    flat = _on_own_faces(tp_all, tri_pts, n)
    inward = face_interiors(tp_all, tri_pts, p)[flat] - p[flat]
    inward -= np.einsum("ij,ij->i", inward, n[flat])[:, None] * n[flat]
    origins[flat] += (CONTACT_SHARE * inward).astype(np.float32)

    def pairs(tris, probed_only=False):
        """(point, |n . face normal|, kept, sample) of the corners of triangles ``tris``
        (with ``probed_only`` only those of faces not aligned with the point's normal)."""
        tp = tp_all[tris]
        ng = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
        length = np.linalg.norm(ng, axis=1)
        ng = ng / np.maximum(length, 1e-300)[:, None]
        pt = tri_pts[tris].reshape(-1)
        tri = np.repeat(np.arange(len(tp)), 3)
        align = np.einsum("ij,ij->i", ng[tri], n[pt])
        keep = (length[tri] > 0.0) & (align != 0.0)
        if probed_only:
            keep &= np.abs(align) < CONTACT_ALIGNED
        pt, tri, align = pt[keep], tri[keep], align[keep]
        sample = (p[pt] + CONTACT_SHARE * (tp.mean(axis=1)[tri] - p[pt])
                  + (step[pt] * np.sign(align))[:, None] * ng[tri])
        return pt, np.abs(align), keep, sample

    # pass 1: which points' steps are cut off from some face's sample
    cut_points = []
    for lo in range(0, len(tp_all), CONTACT_CHUNK):
        # a face the normal already stands on (flat shading, flat regions) is reached:
        # the step along the normal is its own step, as Cycles takes it
        pt, align, _, sample = pairs(np.arange(lo, min(lo + CONTACT_CHUNK, len(tp_all))),
                                     probed_only=True)
        seg = sample - origins[pt]
        dist = np.linalg.norm(seg, axis=1)
        probe = dist > 0.0
        if probe.any():
            hit = _occluded(scene, origins[pt][probe], seg[probe] / dist[probe, None],
                            dist[probe])
            cut_points.append(pt[probe][hit])
    cut_points = np.unique(np.concatenate(cut_points)) if cut_points else np.zeros(0, int)
    moved = np.zeros(len(p), dtype=bool)
    if len(cut_points) == 0:
        return origins, moved
    # pass 2, those points' faces only: the vote by corner angle, the origin moved
    mine = np.zeros(len(p), dtype=bool)
    mine[cut_points] = True
    tris = np.flatnonzero(mine[tri_pts].any(axis=1))
    pt, align, keep, sample = pairs(tris)
    tp = tp_all[tris]
    a, b, c = tp, np.roll(tp, -1, axis=1), np.roll(tp, 1, axis=1)
    e1, e2 = b - a, c - a                           # the corner angle of each pair
    angle = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=-1),
                       np.einsum("tkj,tkj->tk", e1, e2)).reshape(-1)[keep]
    sel = mine[pt]
    pt, align, angle, sample = pt[sel], align[sel], angle[sel], sample[sel]
    seg = sample - origins[pt]
    dist = np.linalg.norm(seg, axis=1)
    probe = (dist > 0.0) & (align < CONTACT_ALIGNED)
    blocked = np.zeros(len(pt), dtype=bool)
    blocked[probe] = _occluded(scene, origins[pt][probe], seg[probe] / dist[probe, None],
                               dist[probe])
    cut = np.bincount(pt[blocked], angle[blocked], minlength=len(p))
    reached = np.bincount(pt[~blocked], angle[~blocked], minlength=len(p))
    moved = cut > reached
    # the best-aligned cut-off face of each moved point
    rows = np.flatnonzero(blocked & moved[pt])
    rows = rows[np.lexsort((-align[rows], pt[rows]))]
    rows = rows[np.unique(pt[rows], return_index=True)[1]]
    origins[pt[rows]] = sample[rows].astype(np.float32)
    return origins, moved


def _on_own_faces(tri_positions: np.ndarray, tri_points: np.ndarray,
                  normals: np.ndarray) -> np.ndarray:
    """(P,) bool: every triangle a point is a corner of lies in its tangent plane (its
    normal within :data:`CONTACT_ALIGNED` of the point's; a point of no triangle: False)."""
    tp = tri_positions
    ng = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
    ng /= np.maximum(np.linalg.norm(ng, axis=1), 1e-300)[:, None]
    worst = np.full(len(normals), 2.0)
    for k in range(3):
        pt = tri_points[:, k]
        np.minimum.at(worst, pt, np.abs(np.einsum("ij,ij->i", ng, normals[pt])))
    return (worst >= CONTACT_ALIGNED) & (worst <= 1.0 + 1e-9)


def _occluded(scene, origins, dirs, dists, parts: int | None = None) -> np.ndarray:
    """(R,) bool: is each segment blocked; the rays split over threads (Embree releases
    the GIL)."""
    parts = max(1, min(parts or default_threads(), len(origins) // 10_000))
    cuts = np.linspace(0, len(origins), parts + 1).astype(int)

    def run(k):
        a, b = cuts[k], cuts[k + 1]
        return scene.run(np.ascontiguousarray(origins[a:b], dtype=np.float32),
                         np.ascontiguousarray(dirs[a:b], dtype=np.float32),
                         dists=np.ascontiguousarray(dists[a:b], dtype=np.float32),
                         query="OCCLUDED") != -1
    if parts == 1:
        return run(0)
    with ThreadPoolExecutor(max_workers=parts) as pool:
        return np.concatenate(list(pool.map(run, range(parts))))


def _repeat_rows(rows: np.ndarray, repeats) -> np.ndarray:
    """``np.repeat(rows, repeats, axis=0)`` for (N, 3) float32, several times faster
    (rows are copied as 12-byte records)."""
    records = np.ascontiguousarray(rows, dtype=np.float32).view(np.dtype((np.void, 12)))
    return np.repeat(records.reshape(-1), repeats).view(np.float32).reshape(-1, 3)


def hemisphere_rays(points: np.ndarray, normals: np.ndarray, cube: Cubemap, offset: float,
                    origins: np.ndarray | None = None):
    """The occlusion rays traced for ``points``: one per texel of :func:`hemisphere_mask`,
    from :func:`ray_origins` or the given ``origins`` (P, 3) (:func:`contact_origins`).

    Returns ``(origins (R, 3) float32, directions (R, 3) float32, mask (P, D) bool)``;
    rays are ordered point by point, texels ascending (the order of ``mask``'s
    True entries), so ``mask[mask] = hits`` scatters results back.
    """
    mask = hemisphere_mask(normals, cube)
    if origins is None:
        origins = ray_origins(points, normals, offset)
    origins = _repeat_rows(origins, mask.sum(axis=1))
    # Select 12-byte records from a broadcast (never materialised) direction table.
    records = _directions32(cube).view(np.dtype((np.void, 12))).reshape(-1)
    table = np.broadcast_to(records, mask.shape)
    directions = table[mask].view(np.float32).reshape(-1, 3)
    return origins, directions, mask


# float32 texel directions per cubemap resolution
_DIRS32 = Cache(8)


def _directions32(cube: Cubemap) -> np.ndarray:
    d = _DIRS32.get(cube.resolution)
    if d is None:
        d = _DIRS32[cube.resolution] = np.ascontiguousarray(cube.directions, dtype=np.float32)
    return d


#: Rays in flight over all threads at most (with the default chunks): what the trace's
#: temporaries (origins, directions, masks, Embree's ray buffers) take does not grow with
#: the number of cores.
RAYS_IN_FLIGHT = 4_000_000


def trace_visibility(scene, points: np.ndarray, normals: np.ndarray, cube: Cubemap,
                     offset: float, chunk_points: int | None = None, threads: int | None = None,
                     progress=None, cancel=None, stats: dict | None = None,
                     consume=None, origins: np.ndarray | None = None,
                     hits=None) -> np.ndarray | None:
    """Bit-packed visibility (P, cube.size // 8) of ``cube`` directions at ``points``.

    ``progress(done, total)`` is called from worker threads after each chunk;
    ``cancel()`` returning True stops the trace with :class:`Cancelled`.
    ``stats``, when given, receives ``rays`` (the number traced).
    ``consume(start, stop, bits)``, when given, receives each chunk of rows as it is
    traced (from worker threads, in any order) and nothing is kept: returns None.
    ``origins`` (P, 3): where each point's rays start (default :func:`ray_origins`).
    ``hits(start, stop, blocked, prim)``, when given, receives what each chunk's rays
    hit: ``blocked`` (n, D) the texels whose ray is blocked, ``prim`` (n, D) the triangle
    the blocked rays of :func:`hit_texels` hit first (``-3 - triangle`` when the hit is
    within four steps: a surface the point touches), else -1 (:mod:`..transport.transfer`
    builds the bounce from them).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    total = len(pts)
    nbytes = (cube.size + 7) // 8
    out = None if consume is not None else np.zeros((total, nbytes), dtype=np.uint8)
    if stats is not None:
        stats["rays"] = 0
    if total == 0:
        return out
    nthreads = threads or default_threads()
    if chunk_points is None:      # about 0.5 M rays per chunk, fewer with many threads
        chunk_points = max(8, min(1_000_000 // cube.size,
                                  2 * RAYS_IN_FLIGHT // (nthreads * cube.size)))
    lock = threading.Lock()
    done = [0, 0]
    subset = hit_texels(cube)

    def work(start):
        if cancel is not None and cancel():
            raise Cancelled()
        stop = min(total, start + chunk_points)
        origins_, rays, mask = hemisphere_rays(
            pts[start:stop], nrm[start:stop], cube, offset,
            None if origins is None else origins[start:stop])
        if len(rays) and hits is not None:
            # occlusion for every ray; the nearest hit only for the blocked rays of the
            # texels of hit_texels(cube) (the bounce is smooth: about 6 x 16^2 of them)
            blocked = scene.run(origins_, rays, query="OCCLUDED") != -1
            traced = mask.copy()                      # (n, D): which texels were traced
            mask[mask] = blocked                      # now: which texels are blocked
            nearest = mask & subset
            prim = np.full(mask.shape, -1, np.int32)
            if nearest.any():
                pick = nearest[traced]                # per ray: traced for its nearest hit
                found = scene.run(np.ascontiguousarray(origins_[pick]),
                                  np.ascontiguousarray(rays[pick]), query="INTERSECT",
                                  output=1)
                got = np.asarray(found["primID"], np.int32)
                # a hit within a few steps of the origin is on a surface the point touches
                # (a crease): its side is the one the point's own surface lies on, which
                # the ray's direction does not tell -- marked -3 - triangle
                near = np.asarray(found["tfar"]) < 4.0 * np.repeat(
                    ray_step(pts[start:stop], offset), nearest.sum(axis=1))
                near &= got >= 0
                got[near] = -3 - got[near]
                prim[nearest] = got
            hits(start, stop, mask, prim)
            np.logical_xor(traced, mask, out=mask)    # visible: traced and not blocked
        elif len(rays):
            hit = scene.run(origins_, rays, query="OCCLUDED")
            mask[mask] = hit == -1                    # -1: no hit, the texel is visible
        packed = np.packbits(mask, axis=1)
        count = len(rays)
        del mask, origins_, rays
        if consume is not None:
            consume(start, stop, packed)
        else:
            out[start:stop] = packed
        with lock:
            done[0] += stop - start
            done[1] += count
            if progress is not None:
                progress(done[0], total)

    starts = list(range(0, total, chunk_points))
    if nthreads == 1:
        for s in starts:
            work(s)
    else:
        with ThreadPoolExecutor(max_workers=nthreads) as pool:
            futures = [pool.submit(work, s) for s in starts]
            try:
                for f in futures:
                    f.result()
            except BaseException:
                for f in futures:
                    f.cancel()
                raise
    if stats is not None:
        stats["rays"] = done[1]
    return out


#: texels per face edge whose rays are traced for their nearest hit (the bounce's rows)
HIT_TEXELS = 8


def hit_texels(cube: Cubemap) -> np.ndarray:
    """(D,) bool: the texels whose blocked rays are traced for their nearest hit -- every
    s-th row and column of each face, s = N / :data:`HIT_TEXELS` (all of them up to 16^2)."""
    n = cube.resolution
    s = max(1, n // HIT_TEXELS)
    k = np.arange(cube.size)
    return ((k % n) % s == 0) & (((k // n) % n) % s == 0)


def unpack_visibility(bits: np.ndarray, count: int) -> np.ndarray:
    """(P, nbytes) uint8 -> (P, count) bool (a view of the unpacked 0/1 bytes: no copy)."""
    return np.unpackbits(np.asarray(bits, dtype=np.uint8), axis=1, count=count).view(bool)


def bytes_to_float24(bits: np.ndarray) -> np.ndarray:
    """Pack bytes three at a time into float32 integers below 2**24 (exact in float32).

    Used to store bit-packed visibility in float image textures that round-trip
    exactly.  ``bits.shape[1]`` must be a multiple of 3 (true for every cubemap
    resolution that is a multiple of 4: 6*N*N/8 = 3*N*N/4).
    """
    b = np.asarray(bits, dtype=np.uint8)
    if b.shape[1] % 3:
        raise ValueError("byte count per point must be a multiple of 3")
    b = b.reshape(len(b), -1, 3).astype(np.uint32)
    return ((b[..., 0] << 16) | (b[..., 1] << 8) | b[..., 2]).astype(np.float32)


def float24_to_bytes(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=np.float32)
    if not np.isfinite(v).all() or (v < 0).any() or (v >= 2 ** 24).any() or (v != np.round(v)).any():
        raise ValueError("stored visibility is corrupt (not 24-bit integers)")
    i = v.astype(np.uint32)
    out = np.stack([(i >> 16) & 255, (i >> 8) & 255, i & 255], axis=-1).astype(np.uint8)
    return out.reshape(len(v), -1)
