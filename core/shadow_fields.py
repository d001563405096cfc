"""Shadow fields for moving rigid objects (Zhou et al. 2005; Xu et al. 2006 §4.3.2, §5.1).

A *dynamic* object is traced once, in its own (object-space) frame, and its shadows then
follow it wherever it moves or turns, with no new precompute:

* :class:`OccluderField` -- the occluder visibility distance field (OVDF) of Xu et al.
  2006 §4.3.2: sample points on ``shells`` concentric spheres around the object (radii
  from ``inner`` to ``outer`` times its bounding radius, evenly spaced in log radius), each
  sphere sampled like a cubemap (``6 face^2`` points).  At every sample the visibility of
  the hemisphere facing the object's centre is traced (the disk map of §5, continued below
  the horizon to the square's corners), turned into a visibility distance table (VDT,
  §4.3) and compressed by PCA per segment (each cube face split in 2x2, §5.1).  A receiver
  reads the eight nearest samples (trilinear, §4.3.2), each with eq. 9 in the sample's own
  frame (Fig. 8: "project c to the local frame of sample point p of occluder J").  Beyond
  the outermost shell the object casts nothing.
* :class:`StaticField` -- the static scene's occlusion where dynamic objects go: a grid of
  sample points, each with its visibility over the cubemap's texels (world frame).  A point
  on a dynamic object reads the trilinear blend of the samples it can see (the segment from
  the point to the sample is free): a sample under the ground or inside a wall says nothing
  about a point above or in front of it (as irradiance probes with visibility, e.g.
  Majercik et al. 2019).

:func:`turn_texels` maps a dynamic object's own visibility (traced in world directions at
the precompute's pose) onto its current pose; the product of the three is what every
method shades (``core.reference`` and the others read it as visibility bits).  Everything
here is numpy + Embree; no bpy.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from . import directions
from .directions import Cubemap, face_coordinates, orthonormal_frame
from .rsl import disk_texel_samples, vdt_box, visibility_distance_table
from .visibility import Cancelled, build_occluder_scene, default_threads


@dataclass(frozen=True)
class FieldLayout:
    """Where an occluder field samples (Xu et al. 2006 §5.1: 16 shells, 0.4 r to 6 r,
    6x32x32 per shell, 32x32 VDTs, 8 eigenvectors per segment)."""
    shells: int = 16
    inner: float = 0.4
    outer: float = 6.0
    face: int = 16            # samples per cube-face edge on each shell (even: 2x2 segments)
    map: int = 32             # VDT resolution (disk map)
    eigen: int = 8            # PCA components per segment

    def __post_init__(self):
        if self.shells < 2 or self.face < 2 or self.face % 2:
            raise ValueError("a field needs >= 2 shells and an even face of >= 2 samples")
        if self.map < 4:
            raise ValueError("a field's maps need >= 4 texels a side")
        if self.eigen < 0:
            raise ValueError("a field keeps >= 0 eigenvectors per segment")
        if not 0.0 < self.inner < self.outer < math.inf:
            raise ValueError("field shells need 0 < inner < outer < inf")

    def radii(self, radius: float) -> np.ndarray:
        """The shells' radii, evenly spaced in log radius."""
        return radius * self.inner * (self.outer / self.inner) ** (
            np.arange(self.shells) / (self.shells - 1))


#: layouts by detail: (occluder field, static field samples); HIGH is Xu et al. 2006 §5.1's
DETAIL = {
    "LOW": (FieldLayout(shells=8, face=8, map=16, eigen=4), 1024),
    "MEDIUM": (FieldLayout(shells=12, face=12, map=24, eigen=8), 4096),
    "HIGH": (FieldLayout(shells=16, face=16, map=32, eigen=8), 16384),
}


def shell_directions(face: int) -> np.ndarray:
    """(6, face, face, 3) unit directions of a shell's samples: cubemap texel centres
    (face, row, col) as :func:`.directions.cubemap` orders them."""
    return directions.cubemap(face).directions.reshape(6, face, face, 3)


def sample_frames(face: int) -> np.ndarray:
    """(6, face, face, 3, 3) rows (t, b, z) of each sample's frame: ``z`` toward the
    object's centre (the hemisphere the sample's map holds, §4.3.2)."""
    z = -shell_directions(face).reshape(-1, 3)
    t, b = orthonormal_frame(z)
    return np.stack([t, b, z], axis=1).reshape(6, face, face, 3, 3)


def map_directions(resolution: int) -> np.ndarray:
    """(M*M, 3) local directions of the disk map's texel centres (rows py, columns px),
    the square's corners continued below the horizon."""
    px, py, _, _ = disk_texel_samples(resolution, 1)
    return directions.rsl_disk_to_hemisphere(px, py, whole_sphere=True).reshape(-1, 3)


def bounding_sphere(positions) -> tuple[np.ndarray, float]:
    """Centre of the bounding box and the largest distance of a vertex from it."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        return np.zeros(3), 0.0
    c = 0.5 * (p.min(axis=0) + p.max(axis=0))
    return c, float(np.linalg.norm(p - c, axis=1).max())


@dataclass
class OccluderField:
    """An object's OVDF in its own frame (object space), PCA-compressed per segment."""
    centre: np.ndarray        # (3,) object space
    radius: float             # bounding radius, object space
    layout: FieldLayout
    means: np.ndarray         # (S, 6, 2, 2, M*M) float16
    bases: np.ndarray         # (S, 6, 2, 2, k, M*M) float16
    coeffs: np.ndarray        # (S, 6, face, face, k) float16
    #: relative RMS of the compressed VDTs against the traced ones
    error: float = 0.0
    seconds: float = 0.0

    @property
    def nbytes(self) -> int:
        return int(self.means.nbytes + self.bases.nbytes + self.coeffs.nbytes)

    def tables(self, ids: np.ndarray) -> np.ndarray:
        """(len(ids), M, M) float32 VDTs of flat sample ids (shell, face, row, col)."""
        L = self.layout
        n, h = L.face, L.face // 2
        ids = np.asarray(ids, dtype=np.int64)
        shell, rest = np.divmod(ids, 6 * n * n)
        f, rest = np.divmod(rest, n * n)
        row, col = np.divmod(rest, n)
        seg = (shell, f, row // h, col // h)
        c = self.coeffs.reshape(L.shells, 6, n, n, -1)[shell, f, row, col].astype(np.float32)
        out = self.means[seg].astype(np.float32)
        out += np.einsum("pk,pkm->pm", c, self.bases[seg].astype(np.float32))
        return out.reshape(len(ids), L.map, L.map)


def _trace_chunks(scene, origins_of, count, rays_per, directions_of, consume, threads=None,
                  cancel=None, progress=None):
    """Trace ``count`` samples of ``rays_per`` rays each on a thread pool (Embree releases
    the GIL): ``origins_of(a, b)`` (b-a, 3), ``directions_of(a, b)`` (b-a, rays_per, 3);
    ``consume(a, b, blocked)`` gets each chunk's (b-a, rays_per) bool, True where blocked."""
    chunk = max(1, 400_000 // max(rays_per, 1))
    done = [0]

    def work(a):
        if cancel is not None and cancel():
            raise Cancelled()
        b = min(count, a + chunk)
        org = np.repeat(np.asarray(origins_of(a, b), np.float32), rays_per, axis=0)
        dirs = np.ascontiguousarray(np.asarray(directions_of(a, b), np.float32).reshape(-1, 3))
        hit = scene.run(np.ascontiguousarray(org), dirs, query="OCCLUDED")
        consume(a, b, (np.asarray(hit) != -1).reshape(b - a, rays_per))
        done[0] += b - a
        if progress is not None:
            progress(done[0], count)

    starts = range(0, count, chunk)
    nthreads = threads or default_threads()
    if nthreads <= 1:
        for a in starts:
            work(a)
        return
    with ThreadPoolExecutor(max_workers=nthreads) as pool:
        futures = [pool.submit(work, a) for a in starts]
        try:
            for fut in futures:
                fut.result()
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise


def _pca(X: np.ndarray, k: int):
    """Mean and the top ``k`` principal directions (rows) of the rows of ``X``, from the
    eigenvectors of the small Gram matrix (rows << columns); missing rank pads with zero
    directions."""
    mean = X.mean(axis=0)
    Y = X - mean
    vals, vecs = np.linalg.eigh(Y @ Y.T)
    order = np.argsort(vals)[::-1][:k]
    basis = np.zeros((k, X.shape[1]), dtype=np.float64)
    for i, j in enumerate(order):
        if vals[j] > 1e-12 * max(vals.max(), 1e-300):
            basis[i] = (vecs[:, j] @ Y) / math.sqrt(vals[j])
    return mean, basis


def build_occluder_field(triangles, layout: FieldLayout = FieldLayout(), threads=None,
                         cancel=None, progress=None) -> OccluderField:
    """Trace an object's OVDF: ``triangles`` (T, 3, 3) in the object's own frame."""
    t0 = time.perf_counter()
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    centre, radius = bounding_sphere(tri.reshape(-1, 3))
    radius = max(radius, 1e-9)
    L = layout
    n, M = L.face, L.map
    radii = L.radii(radius)
    dirs = shell_directions(n).reshape(-1, 3)                       # (6n², 3)
    frames = sample_frames(n).reshape(-1, 3, 3)                     # (6n², 3, 3)
    local = map_directions(M)                                      # (M², 3)
    world_of_frame = np.einsum("mk,skj->smj", local, frames).astype(np.float32)  # (6n², M², 3)
    per_shell = 6 * n * n
    count = L.shells * per_shell
    positions = (centre[None, None, :] + radii[:, None, None] * dirs[None]).reshape(-1, 3)
    scene = build_occluder_scene(tri)
    blocked = np.zeros((count, M * M), dtype=bool)

    def keep(a, b, rows):
        blocked[a:b] = rows

    _trace_chunks(scene, lambda a, b: positions[a:b], count, M * M,
                  lambda a, b: world_of_frame[np.arange(a, b) % per_shell], keep,
                  threads, cancel, progress)
    del scene
    k, h = L.eigen, n // 2
    means = np.zeros((L.shells, 6, 2, 2, M * M), np.float16)
    bases = np.zeros((L.shells, 6, 2, 2, k, M * M), np.float16)
    coeffs = np.zeros((L.shells, 6, 2, h, 2, h, k), np.float16)
    sums = np.zeros((L.shells, 2))

    def compress(s):
        """One shell's tables (VDT, §4.3) and their PCA per segment (§5.1)."""
        maps = ~blocked[s * per_shell:(s + 1) * per_shell]
        vdt = visibility_distance_table(maps.reshape(-1, M, M).astype(np.float32))
        vdt = vdt.reshape(6, 2, h, 2, h, M * M).astype(np.float64)
        for f in range(6):
            for a in range(2):
                for b in range(2):
                    X = vdt[f, a, :, b, :].reshape(-1, M * M)
                    mean, basis = _pca(X, k)
                    mean16, basis16 = mean.astype(np.float16), basis.astype(np.float16)
                    # coefficients against the stored (half-precision) mean and basis
                    c = (X - mean16) @ basis16.astype(np.float64).T
                    means[s, f, a, b], bases[s, f, a, b] = mean16, basis16
                    coeffs[s, f, a, :, b, :] = c.reshape(h, h, k)
                    rec = mean16 + c.astype(np.float16).astype(np.float64) @ basis16
                    sums[s] += (((X - rec) ** 2).sum(), (X ** 2).sum())

    with ThreadPoolExecutor(max_workers=max(1, threads or os.cpu_count() or 1)) as pool:
        list(pool.map(compress, range(L.shells)))
    err, total = sums.sum(axis=0)
    return OccluderField(centre=centre, radius=radius, layout=L, means=means, bases=bases,
                         coeffs=coeffs.reshape(L.shells, 6, n, n, k),
                         error=math.sqrt(err / max(total, 1e-30)),
                         seconds=time.perf_counter() - t0)


def _cone_pairs(rel_dist, rel_dir, texel_dirs, radius, margin):
    """(point index, texel index) pairs whose texel can meet the bounding sphere seen from
    the point (the cone of half angle asin(r/d), widened by ``margin`` radians); every
    texel of a point inside the sphere."""
    s = np.clip(radius / np.maximum(rel_dist, 1e-30), 0.0, 1.0)
    half = np.arcsin(s) + margin
    cos_min = np.where(s >= 1.0, -2.0, np.cos(np.minimum(half, math.pi)))
    cos = rel_dir @ texel_dirs.T                                    # (P, D) toward the centre
    return np.nonzero(cos >= cos_min[:, None])


def occluder_fractions(field: OccluderField, points, texel_dirs, half, margin: float = 0.05,
                       normals=None):
    """Visible fraction of each (point, texel) the field's object may block, by eq. 9 at
    the eight nearest samples (each in its own frame), blended trilinearly (Xu et al. 2006
    §4.3.2).  ``points`` (P, 3) and ``texel_dirs`` (D, 3) in the field's (object) frame,
    ``half`` (D,) eq. 9's half side per texel (disk-map units).

    Returns ``(point_idx, texel_idx, fraction)``: only pairs inside the bounding sphere's
    cone of a point within the outermost shell (every other pair is 1), and with
    ``normals`` (P, 3) only texels above each point's horizon (the others are not
    shaded)."""
    L = field.layout
    q = np.asarray(points, dtype=np.float64).reshape(-1, 3) - field.centre
    d = np.linalg.norm(q, axis=1)
    near = np.nonzero(d < L.outer * field.radius)[0]
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32))
    if len(near) == 0:
        return empty
    q, d = q[near], d[near]
    u = q / np.maximum(d, 1e-30)[:, None]
    pi, ki = _cone_pairs(d, -u, np.asarray(texel_dirs, np.float64), field.radius, margin)
    if normals is not None:
        nrm = np.asarray(normals, np.float64).reshape(-1, 3)[near]
        up = np.einsum("qj,qj->q", nrm[pi], np.asarray(texel_dirs, np.float64)[ki]) > 0.0
        pi, ki = pi[up], ki[up]
    if len(pi) == 0:
        return empty
    # shell coordinate (log radius) and face-grid coordinates of each point
    n = L.face
    x = np.log(np.maximum(d, 1e-30) / (L.inner * field.radius)) / math.log(L.outer / L.inner)
    x = np.clip(x * (L.shells - 1), 0.0, L.shells - 1.0)
    s0 = np.minimum(x.astype(np.int64), L.shells - 2)
    fs = x - s0
    face, s, t = face_coordinates(u)
    col = np.clip((s + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    row = np.clip((t + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    c0 = np.minimum(col.astype(np.int64), n - 2)
    r0 = np.minimum(row.astype(np.int64), n - 2)
    fc, fr = col - c0, row - r0
    frames = sample_frames(n).reshape(-1, 3, 3).astype(np.float32)
    w_dirs = np.asarray(texel_dirs, np.float32)[ki]                # (Q, 3)
    hk = np.asarray(half, np.float32).reshape(-1)
    hk = hk[ki] if hk.size > 1 else np.full(len(ki), float(hk[0]), np.float32)
    out = np.zeros(len(pi), dtype=np.float32)
    fs, fr, fc = (v.astype(np.float32) for v in (fs, fr, fc))
    for dr, wr in ((0, 1.0 - fr), (1, fr)):
        for dc, wc in ((0, 1.0 - fc), (1, fc)):
            # the sample's frame is the same on every shell: the map position is shared
            in_shell = ((face * n + r0 + dr) * n + c0 + dc)           # (P,) within a shell
            loc = np.einsum("qij,qj->qi", frames[in_shell[pi]], w_dirs)
            rho = np.sqrt(loc[:, 0] ** 2 + loc[:, 1] ** 2)
            r = np.sqrt(np.maximum(0.0, 1.0 - np.clip(loc[:, 2], -1.0, 1.0)))
            scale = np.where(rho > 1e-12, r / np.maximum(rho, 1e-12), 0.0)
            px, py = loc[:, 1] * scale, loc[:, 0] * scale              # (r sin f, r cos f)
            sel = np.nonzero((np.abs(px) <= 1.0) & (np.abs(py) <= 1.0))[0]
            for ds, ws in ((0, 1.0 - fs), (1, fs)):
                w = (ws * wr * wc)[pi]                                    # (Q,)
                out += w                                                  # open unless seen
                if len(sel) == 0:
                    continue
                sid = (s0 + ds) * 6 * n * n + in_shell
                uniq, inv = np.unique(sid, return_inverse=True)
                vdt = field.tables(uniq)
                frac = vdt_box(vdt, px[sel], py[sel], hk[sel], lead=inv.reshape(-1)[pi[sel]])
                out[sel] -= w[sel] * (1.0 - frac.astype(np.float32))
    return near[pi], ki, np.clip(out, 0.0, 1.0).astype(np.float32)


def texel_half_sides(cube: Cubemap) -> np.ndarray:
    """Eq. 9's half side (disk-map units) of a square with each texel's solid angle
    (the map is equal-area with ``dw = 2 dp``)."""
    return 0.5 * np.sqrt(np.asarray(cube.solid_angles, np.float64) / 2.0)


# --------------------------------------------------------------------------- #
# The static scene's field (the occluders that do not move, seen from dynamic objects)
# --------------------------------------------------------------------------- #

@dataclass
class StaticField:
    """The static scene's visibility over the cubemap at the corners of a grid
    (world frame): ``bits`` (X*Y*Z, D/8) packed, sample ``(i, j, k)`` at
    ``origin + spacing * (i, j, k)``, flat index ``(i * Y + j) * Z + k``."""
    origin: np.ndarray
    spacing: float
    dims: tuple
    resolution: int
    bits: np.ndarray
    seconds: float = 0.0

    @property
    def nbytes(self) -> int:
        return int(self.bits.nbytes)

    def positions(self) -> np.ndarray:
        X, Y, Z = self.dims
        i, j, k = np.meshgrid(np.arange(X), np.arange(Y), np.arange(Z), indexing="ij")
        return self.origin + self.spacing * np.stack([i, j, k], -1).reshape(-1, 3)


def static_grid(lo, hi, samples: int = 4096):
    """Origin, spacing and dims of a grid of cubic cells over the box ``[lo, hi]`` with
    about ``samples`` corners; half a cell beyond the box on every side, so no sample
    lies in a plane bounding the box (a ground plane)."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    ext = np.maximum(hi - lo, 1e-6)
    spacing = float(np.cbrt(np.prod(ext) / max(samples, 8)))
    spacing = max(spacing, float(ext.max()) / max(samples - 1, 1))
    for _ in range(64):
        dims = tuple(int(v) for v in np.ceil(ext / spacing).astype(np.int64) + 2)
        if np.prod(dims) <= samples * 1.25:
            break
        spacing *= 1.05
    origin = lo - 0.5 * spacing
    return origin, spacing, dims


def build_static_field(triangles, lo, hi, cube: Cubemap, samples: int = 4096, threads=None,
                       cancel=None, progress=None) -> StaticField:
    """Trace the static scene (``triangles`` (T, 3, 3), world) from a grid over
    ``[lo, hi]``: every cubemap direction at every sample."""
    t0 = time.perf_counter()
    origin, spacing, dims = static_grid(lo, hi, samples)
    field = StaticField(origin=origin, spacing=spacing, dims=dims, resolution=cube.resolution,
                        bits=np.zeros((0, cube.size // 8), np.uint8))
    pos = field.positions()
    scene = build_occluder_scene(np.asarray(triangles, np.float64).reshape(-1, 3, 3))
    dirs = np.asarray(cube.directions, np.float32)
    bits = np.zeros((len(pos), cube.size // 8), np.uint8)

    def keep(a, b, rows):
        bits[a:b] = np.packbits(~rows, axis=1)

    _trace_chunks(scene, lambda a, b: pos[a:b], len(pos), cube.size,
                  lambda a, b: np.broadcast_to(dirs, (b - a,) + dirs.shape), keep,
                  threads, cancel, progress)
    field.bits = bits
    field.seconds = time.perf_counter() - t0
    return field


def static_corners(field: StaticField, points):
    """The eight grid corners around each point (clamped to the grid) and their
    trilinear weights: ``(ids (P, 8), weights (P, 8))``."""
    X, Y, Z = field.dims
    g = (np.asarray(points, np.float64).reshape(-1, 3) - field.origin) / field.spacing
    dims = np.array([X, Y, Z])
    g = np.clip(g, 0.0, dims - 1.0)
    i0 = np.minimum(g.astype(np.int64), np.maximum(dims - 2, 0))
    f = g - i0
    ids, ws = [], []
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                idx = np.minimum(i0 + (di, dj, dk), dims - 1)
                ids.append((idx[:, 0] * Y + idx[:, 1]) * Z + idx[:, 2])
                ws.append(np.where(di, f[:, 0], 1 - f[:, 0]) * np.where(dj, f[:, 1], 1 - f[:, 1])
                          * np.where(dk, f[:, 2], 1 - f[:, 2]))
    return np.stack(ids, 1), np.stack(ws, 1)


def seen_corners(scene, field: StaticField, origins, ids, weights):
    """``weights`` with the corners a point cannot see (the segment from its ray origin to
    the sample is blocked by the static scene) set to zero, renormalised; a point that
    sees none keeps the plain weights."""
    pos = field.positions()
    o = np.repeat(np.asarray(origins, np.float32), ids.shape[1], axis=0)
    to = pos[ids.reshape(-1)].astype(np.float32) - o
    length = np.linalg.norm(to, axis=1)
    ok = length > 1e-12
    d = np.where(ok[:, None], to / np.maximum(length, 1e-30)[:, None], np.float32([0, 0, 1]))
    got = scene.run(np.ascontiguousarray(o), np.ascontiguousarray(d, np.float32), output=1)
    far = np.asarray(got["tfar"], np.float64)
    hit = (np.asarray(got["geomID"]) >= 0) & (far < length * (1.0 - 1e-4)) & ok
    w = np.where(hit.reshape(ids.shape), 0.0, weights)
    total = w.sum(axis=1, keepdims=True)
    return np.where(total > 1e-9, w / np.maximum(total, 1e-30), weights)


def static_visibility(field: StaticField, ids, weights) -> np.ndarray:
    """(P, D) float32: the weighted blend of the corners' visibility."""
    D = field.bits.shape[1] * 8
    out = np.zeros((len(ids), D), dtype=np.float32)
    for c in range(ids.shape[1]):
        w = weights[:, c].astype(np.float32)
        live = np.nonzero(w > 0)[0]
        if len(live):
            out[live] += np.unpackbits(field.bits[ids[live, c]], axis=1,
                                       count=D).astype(np.float32) * w[live, None]
    return out


# --------------------------------------------------------------------------- #
# A dynamic object's own visibility after it turned
# --------------------------------------------------------------------------- #

def turn_texels(cube: Cubemap, turn) -> np.ndarray:
    """(D,) the texel each world texel read before the object turned by ``turn`` (3x3,
    now = turn @ then): a direction ``w`` now was ``turn^T w`` at the precompute."""
    back = np.asarray(cube.directions, np.float64) @ np.asarray(turn, np.float64)
    return directions.direction_to_texel(back, cube.resolution)


def turned_bits(bits: np.ndarray, cube: Cubemap, turn) -> np.ndarray:
    """Packed rows of visibility traced at the precompute's pose, read along the turned
    directions (nearest texel)."""
    idx = turn_texels(cube, turn)
    bits = np.asarray(bits, np.uint8)
    out = np.empty_like(bits)
    for a in range(0, len(bits), 4096):            # rows in chunks: bounded temporaries
        vis = np.unpackbits(bits[a:a + 4096], axis=1, count=cube.size)
        out[a:a + 4096] = np.packbits(vis[:, idx], axis=1)
    return out



# --------------------------------------------------------------------------- #
# Poses, and the product of the fields at the current one
# --------------------------------------------------------------------------- #

#: largest spread of a motion's singular values (relative) that is still a uniform scale
SCALE_TOLERANCE = 1e-4
#: a texel is blocked when less than this fraction of it is visible (fields are blended,
#: visibility bits are binary)
BLOCKED_BELOW = 0.5


def relative_motion(then, now, tolerance: float = SCALE_TOLERANCE):
    """How an object moved from its 4x4 world matrix ``then`` (the precompute's) to
    ``now``: ``(T, R, s)`` with ``x_now = T x_then`` for its points, ``T``'s linear part
    ``s R`` (R a rotation).  None when it is no rigid motion with uniform scale
    (non-uniform scale, shear, a mirror)."""
    M0 = np.asarray(then, np.float64).reshape(4, 4)
    M1 = np.asarray(now, np.float64).reshape(4, 4)
    try:
        T = M1 @ np.linalg.inv(M0)
    except np.linalg.LinAlgError:
        return None
    A = T[:3, :3]
    sv = np.linalg.svd(A, compute_uv=False)
    if not np.all(np.isfinite(sv)) or sv.min() <= 0.0 or \
            sv.max() - sv.min() > tolerance * sv.max():
        return None
    s = float(sv.mean())
    R = A / s
    if np.linalg.det(R) <= 0.0:
        return None
    U, _, Vt = np.linalg.svd(R)
    return T, U @ Vt, s


def to_field_frame(T, points) -> np.ndarray:
    """Current world points taken back to the field's frame (the world at the precompute
    pose): ``T^-1 x``."""
    Ti = np.linalg.inv(np.asarray(T, np.float64))
    p = np.asarray(points, np.float64).reshape(-1, 3)
    return p @ Ti[:3, :3].T + Ti[:3, 3]


def clear_bits(bits: np.ndarray, rows, texels) -> np.ndarray:
    """A copy of packed visibility rows with the (row, texel) pairs set to blocked."""
    out = np.array(bits, dtype=np.uint8, copy=True)
    rows = np.asarray(rows, np.int64)
    texels = np.asarray(texels, np.int64)
    if len(rows):
        mask = (~(np.uint8(0x80) >> (texels & 7).astype(np.uint8))).astype(np.uint8)
        np.bitwise_and.at(out, (rows, texels >> 3), mask)
    return out


def block_by_field(bits: np.ndarray, field: OccluderField, points, cube: Cubemap, T, R,
                   half=None, chunk: int = 512, normals=None, threads=None) -> np.ndarray:
    """``bits`` (P, D/8) of current world ``points`` with what the moved occluder blocks
    cleared: the occluder's field (traced in the frame of its precompute pose) read at
    the points taken back to that frame, along the texels' directions turned back
    (``R^T w``); a texel less than :data:`BLOCKED_BELOW` visible is blocked.  Rows of
    points beyond its outermost shell are unchanged (the same array when none is near);
    with ``normals`` only texels above a point's horizon are looked up."""
    pts = to_field_frame(T, points)
    nrm = None if normals is None else np.asarray(normals, np.float64) @ np.asarray(R,
                                                                                 np.float64)
    dirs = np.asarray(cube.directions, np.float64) @ np.asarray(R, np.float64)
    half = texel_half_sides(cube) if half is None else half
    def blocked(a):
        p, k, frac = occluder_fractions(field, pts[a:a + chunk], dirs, half,
                                        normals=None if nrm is None else nrm[a:a + chunk])
        hit = frac < BLOCKED_BELOW
        return p[hit] + a, k[hit]

    starts = range(0, len(pts), chunk)
    if len(starts) > 1 and (threads or default_threads()) > 1:     # numpy frees the GIL
        with ThreadPoolExecutor(max_workers=threads or default_threads()) as pool:
            got = list(pool.map(blocked, starts))
    else:
        got = [blocked(a) for a in starts]
    rows = np.concatenate([g[0] for g in got]) if got else np.zeros(0, np.int64)
    texels = [g[1] for g in got]
    if len(rows) == 0:
        return bits
    return clear_bits(bits, rows, np.concatenate(texels))


def static_bits(field: StaticField, scene, origins, points, chunk: int = 1024) -> np.ndarray:
    """Packed visibility (P, D/8) the static scene leaves at ``points`` (their ray
    ``origins`` for the corner test): the blend of the grid corners each point sees,
    blocked below :data:`BLOCKED_BELOW`."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    org = np.asarray(origins, np.float64).reshape(-1, 3)
    out = np.zeros((len(pts), field.bits.shape[1]), np.uint8)
    for a in range(0, len(pts), chunk):
        ids, w = static_corners(field, pts[a:a + chunk])
        if scene is not None:
            w = seen_corners(scene, field, org[a:a + chunk], ids, w)
        vis = static_visibility(field, ids, w)
        out[a:a + chunk] = np.packbits(vis >= BLOCKED_BELOW, axis=1)
    return out


def in_field_box(field: StaticField, points) -> bool:
    """Whether every point lies within the static field's grid (else its samples are
    extrapolated from the nearest ones)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    hi = field.origin + field.spacing * (np.asarray(field.dims) - 1)
    return bool(np.all(p >= field.origin - 1e-9) and np.all(p <= hi + 1e-9))


# --------------------------------------------------------------------------- #
# Storage form (core.codec blobs)
# --------------------------------------------------------------------------- #

@dataclass
class DynamicData:
    """What a dynamic object stores besides its own visibility: its occluder field, the
    static scene's field where it goes (None without static occluders), its pose at the
    precompute (4x4 ``matrix``; ``rotation`` and ``probe`` as :mod:`.rigid` stores them)
    and the ray offset the trace used."""
    field: OccluderField
    static: StaticField | None
    matrix: np.ndarray
    rotation: np.ndarray
    probe: np.ndarray
    offset: float

    @property
    def nbytes(self) -> int:
        return self.field.nbytes + (self.static.nbytes if self.static is not None else 0)


def dynamic_arrays(data: DynamicData) -> tuple[dict, dict]:
    """``(arrays, meta)`` for :func:`core.codec.pack`."""
    f, L = data.field, data.field.layout
    arrays = {"means": f.means, "bases": f.bases, "coeffs": f.coeffs,
              "centre": np.asarray(f.centre, np.float64),
              "matrix": np.asarray(data.matrix, np.float64).reshape(4, 4),
              "rotation": np.asarray(data.rotation, np.float64).reshape(3, 3),
              "probe": np.asarray(data.probe, np.float64).reshape(-1, 3)}
    meta = {"radius": float(f.radius), "error": float(f.error), "offset": float(data.offset),
            "layout": [L.shells, L.inner, L.outer, L.face, L.map, L.eigen]}
    if data.static is not None:
        s = data.static
        arrays["static_bits"] = s.bits
        arrays["static_origin"] = np.asarray(s.origin, np.float64)
        meta["static"] = {"spacing": float(s.spacing), "dims": [int(v) for v in s.dims],
                          "resolution": int(s.resolution)}
    return arrays, meta


def dynamic_of_arrays(arrays: dict, meta: dict) -> DynamicData:
    """The inverse of :func:`dynamic_arrays`; ValueError when it does not fit together."""
    try:
        shells, inner, outer, face, m, eigen = meta["layout"]
        layout = FieldLayout(int(shells), float(inner), float(outer), int(face), int(m),
                             int(eigen))
        field = OccluderField(centre=arrays["centre"], radius=float(meta["radius"]),
                              layout=layout, means=arrays["means"], bases=arrays["bases"],
                              coeffs=arrays["coeffs"], error=float(meta.get("error", 0.0)))
        n, M, k = layout.face, layout.map, layout.eigen
        if (field.means.shape != (layout.shells, 6, 2, 2, M * M)
                or field.bases.shape != (layout.shells, 6, 2, 2, k, M * M)
                or field.coeffs.shape != (layout.shells, 6, n, n, k)):
            raise ValueError("occluder field arrays do not match their layout")
        static = None
        if "static" in meta:
            sm = meta["static"]
            dims = tuple(int(v) for v in sm["dims"])
            static = StaticField(origin=arrays["static_origin"], spacing=float(sm["spacing"]),
                                 dims=dims, resolution=int(sm["resolution"]),
                                 bits=arrays["static_bits"])
            if static.bits.shape != (int(np.prod(dims)), 6 * static.resolution ** 2 // 8):
                raise ValueError("static field arrays do not match their grid")
        return DynamicData(field=field, static=static, matrix=arrays["matrix"],
                           rotation=arrays["rotation"], probe=arrays["probe"],
                           offset=float(meta["offset"]))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"shadow field incomplete ({exc})") from None
