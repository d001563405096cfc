"""The occluder visibility distance field of a moving rigid object (Zhou et al. 2005 in the
form of Xu et al. 2006 §4.3.2, §5.1): VDTs sampled on concentric shells around it,
compressed by PCA per segment, read trilinearly by a receiver in each sample's own frame."""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..common.parallel import Cancelled, default_threads
from ..sphere import directions
from ..sphere.directions import Cubemap, face_coordinates, orthonormal_frame
from .distance_tables import disk_texel_samples, vdt_box, visibility_distance_table
from .visibility import build_occluder_scene


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


def trace_chunks(scene, origins_of, count, rays_per, directions_of, consume, threads=None,
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

    trace_chunks(scene, lambda a, b: positions[a:b], count, M * M,
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


#: (point, texel) pairs read at once: each holds a few hundred bytes of temporaries, so a
#: block of points whose pairs pass this is split (~60 MB; 512 points near an object at 6x32²
#: directions were 3 M pairs and 1 GB at once, and 16x that at 6x128²)
MAX_PAIRS = 1 << 17


def occluder_fractions(field: OccluderField, points, texel_dirs, half, margin: float = 0.05,
                       normals=None, max_pairs: int = MAX_PAIRS):
    """Visible fraction of each (point, texel) the field's object may block, by eq. 9 at
    the eight nearest samples (each in its own frame), blended trilinearly (Xu et al. 2006
    §4.3.2).  ``points`` (P, 3) and ``texel_dirs`` (D, 3) in the field's (object) frame,
    ``half`` (D,) eq. 9's half side per texel (disk-map units).

    Returns ``(point_idx, texel_idx, fraction)``: only pairs inside the bounding sphere's
    cone of a point within the outermost shell (every other pair is 1), and with
    ``normals`` (P, 3) only texels above each point's horizon (the others are not
    shaded).  Points are read in blocks of at most ``max_pairs`` possible pairs."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    block = max(1, max_pairs // max(len(texel_dirs), 1))
    if len(points) > block:
        starts = range(0, len(points), block)
        parts = [occluder_fractions(field, points[a:a + block], texel_dirs, half, margin,
                                    None if normals is None else
                                    np.asarray(normals).reshape(-1, 3)[a:a + block], max_pairs)
                 for a in starts]
        return (np.concatenate([p[0] + a for p, a in zip(parts, starts)]),
                np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))
    L = field.layout
    q = points - field.centre
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
