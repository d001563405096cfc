"""Per-point binary visibility over cubemap directions, traced with Embree.

For every shading point only the texels of the upper hemisphere of its
normal (``n . w > 0``) are traced; the others are stored as 0 (they carry no
light because of the cosine).  Results are bit-packed along the texel axis:
``(P, 6*N*N/8)`` uint8, bit order of ``numpy.packbits`` (big-endian in a byte).

Rays start at ``p + offset * n`` with ``offset`` relative to the scene's
bounding diagonal (default 1e-4 of it), and at least 16 float32 ulps of the
point's coordinates so scenes far from the origin do not shadow themselves.
The origin is not moved along the ray, so occluders in contact (a wall
meeting a floor) still block.

Work is split in chunks of points handed to a thread pool; Embree releases
the GIL during ``run``, so both cores trace.  Memory stays bounded by the
chunk size (``chunk_points * hemisphere_texels`` rays in flight per thread).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .directions import Cubemap

try:
    from embreex import rtcore_scene as _rtcs
    from embreex.mesh_construction import TriangleMesh as _TriangleMesh
except ImportError:  # pragma: no cover - reported to the user by the add-on
    _rtcs = None
    _TriangleMesh = None


class Cancelled(Exception):
    """Raised when a cancel callback asks the trace to stop."""


def have_embree() -> bool:
    return _rtcs is not None


def build_occluder_scene(triangle_positions: np.ndarray):
    """An Embree scene of (T, 3, 3) world triangles (degenerate ones dropped)."""
    if _rtcs is None:
        raise RuntimeError("embreex is not installed; it ships as a wheel with the extension")
    tri = np.ascontiguousarray(triangle_positions, dtype=np.float32).reshape(-1, 3, 3)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    keep = np.isfinite(area2) & (area2 > 0)
    tri = np.ascontiguousarray(tri[keep])
    scene = _rtcs.EmbreeScene()
    if len(tri):
        _TriangleMesh(scene, tri)
    return scene


def default_threads() -> int:
    return max(1, os.cpu_count() or 1)


def trace_visibility(scene, points: np.ndarray, normals: np.ndarray, cube: Cubemap,
                     offset: float, chunk_points: int = 64, threads: int | None = None,
                     progress=None, cancel=None) -> np.ndarray:
    """Bit-packed visibility (P, cube.size // 8) of ``cube`` directions at ``points``.

    ``progress(done, total)`` is called from worker threads after each chunk;
    ``cancel()`` returning True stops the trace with :class:`Cancelled`.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    total = len(pts)
    nbytes = (cube.size + 7) // 8
    out = np.zeros((total, nbytes), dtype=np.uint8)
    if total == 0:
        return out
    dirs64 = cube.directions
    dirs32 = dirs64.astype(np.float32)
    offset = float(offset)
    lock = threading.Lock()
    done = [0]

    def work(start):
        if cancel is not None and cancel():
            raise Cancelled()
        stop = min(total, start + chunk_points)
        n = nrm[start:stop]
        cosines = n @ dirs64.T                                  # (p, D)
        pi, di = np.nonzero(cosines > 0.0)
        # Step off the surface along the normal by the larger of the scene-relative
        # offset and a few float32 ulps of the coordinates (rays are traced in float32).
        p = pts[start:stop]
        step = np.maximum(offset, 16.0 * np.finfo(np.float32).eps * np.abs(p).max(axis=1))
        origins = (p + step[:, None] * n).astype(np.float32)[pi]
        rays = dirs32[di]
        if len(pi):
            hit = scene.run(origins, rays, query="OCCLUDED")
            visible = np.zeros(cosines.shape, dtype=bool)
            visible[pi, di] = hit == -1
            out[start:stop] = np.packbits(visible, axis=1)
        with lock:
            done[0] += stop - start
            if progress is not None:
                progress(done[0], total)

    starts = list(range(0, total, chunk_points))
    nthreads = threads or default_threads()
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
    return out


def unpack_visibility(bits: np.ndarray, count: int) -> np.ndarray:
    """(P, nbytes) uint8 -> (P, count) bool."""
    return np.unpackbits(np.asarray(bits, dtype=np.uint8), axis=1, count=count).astype(bool)


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
