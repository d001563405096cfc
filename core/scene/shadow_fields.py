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
method shades (``core.methods.reference.shading`` and the others read it as visibility bits).  Everything
here is numpy + Embree; no bpy.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..sphere import directions
from ..sphere.directions import Cubemap
from .visibility import build_occluder_scene
from ..common.parallel import default_threads
from .occluder_fields import FieldLayout, OccluderField, trace_chunks, occluder_fractions, texel_half_sides


#: layouts by detail: (occluder field, static field samples); HIGH is Xu et al. 2006 §5.1's
DETAIL = {
    "LOW": (FieldLayout(shells=8, face=8, map=16, eigen=4), 1024),
    "MEDIUM": (FieldLayout(shells=12, face=12, map=24, eigen=8), 4096),
    "HIGH": (FieldLayout(shells=16, face=16, map=32, eigen=8), 16384),
}


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

    trace_chunks(scene, lambda a, b: pos[a:b], len(pos), cube.size,
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
# Storage form (core.common.codec blobs)
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
    """``(arrays, meta)`` for :func:`core.common.codec.pack`."""
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
