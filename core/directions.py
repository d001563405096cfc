"""Direction sets on the sphere with exact solid-angle weights.

The cubemap is the discretisation every method shares (seed 004 §4: "we use a
cubemap to discretize the space of all directions").  Its texels are
addressed as ``(face, row, col)`` and flattened in that order; ``face`` runs
over +X, -X, +Y, -Y, +Z, -Z in *world* coordinates (Blender: Z up).

For face ``f`` with major axis ``a`` and tangent axes ``U``, ``V`` a texel
centre at face coordinates ``(s, t)`` in ``(-1, 1)`` points along
``a + s*U + t*V`` (normalised).  ``s`` grows with the column, ``t`` with the
row.  The solid angle of a texel is exact: the area on the unit sphere of the
projection of the square ``[s0, s1] x [t0, t1]`` on the plane at distance one
is ``F(s1,t1) - F(s0,t1) - F(s1,t0) + F(s0,t0)`` with
``F(s, t) = atan2(s*t, sqrt(s*s + t*t + 1))``, so the weights of a cubemap
add up to 4*pi to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: (major axis, U, V) per face, in world coordinates.
FACE_AXES = np.array(
    [
        [[1, 0, 0], [0, 0, -1], [0, -1, 0]],   # +X
        [[-1, 0, 0], [0, 0, 1], [0, -1, 0]],   # -X
        [[0, 1, 0], [1, 0, 0], [0, 0, 1]],     # +Y
        [[0, -1, 0], [1, 0, 0], [0, 0, -1]],   # -Y
        [[0, 0, 1], [1, 0, 0], [0, -1, 0]],    # +Z
        [[0, 0, -1], [-1, 0, 0], [0, -1, 0]],  # -Z
    ],
    dtype=np.float64,
)
FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
CUBEMAP_RESOLUTIONS = (32, 64, 128)


def _corner_area(s, t):
    return np.arctan2(s * t, np.sqrt(s * s + t * t + 1.0))


@dataclass(frozen=True)
class Cubemap:
    """A cubemap direction set: ``directions`` (6*N*N, 3), ``solid_angles`` (6*N*N,)."""

    resolution: int
    directions: np.ndarray
    solid_angles: np.ndarray
    #: (6*N*N, 3) integral of w over each texel divided by its solid angle: the
    #: texel's mean direction vector (length slightly below one).  ``n . mean``
    #: is the texel's exact mean cosine for normals that see all of it.
    mean_directions: np.ndarray

    @property
    def size(self) -> int:
        return 6 * self.resolution * self.resolution

    def texel_index(self, dirs: np.ndarray) -> np.ndarray:
        """Flat texel index of each direction in ``dirs`` (..., 3)."""
        return direction_to_texel(np.asarray(dirs, dtype=np.float64), self.resolution)


@lru_cache(maxsize=8)
def cubemap(resolution: int = 32) -> Cubemap:
    """The cubemap direction set of ``resolution`` texels per face edge."""
    n = int(resolution)
    if n < 1:
        raise ValueError("cubemap resolution must be positive")
    edges = np.linspace(-1.0, 1.0, n + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    t, s = np.meshgrid(centres, centres, indexing="ij")          # row -> t, col -> s
    t0, s0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    t1, s1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    area = _corner_area(s1, t1) - _corner_area(s0, t1) - _corner_area(s1, t0) + _corner_area(s0, t0)
    dirs = (FACE_AXES[:, None, None, 0, :]
            + s[None, :, :, None] * FACE_AXES[:, None, None, 1, :]
            + t[None, :, :, None] * FACE_AXES[:, None, None, 2, :])
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    weights = np.broadcast_to(area, (6, n, n)).reshape(-1).copy()
    dirs = dirs.reshape(-1, 3)
    means = _texel_mean_directions(n, weights)
    for a in (dirs, weights, means):
        a.setflags(write=False)
    return Cubemap(n, dirs, weights, means)


def _texel_mean_directions(n, weights, sub=8):
    """(1/|T|) * integral over texel T of w dw, by a sub x sub midpoint rule.

    On the face plane (s, t, 1) the solid-angle density is (1+s^2+t^2)^(-3/2)
    and w = (s, t, 1)/sqrt(1+s^2+t^2).
    """
    h = 2.0 / (n * sub)
    c = -1.0 + (np.arange(n * sub) + 0.5) * h
    t, s = np.meshgrid(c, c, indexing="ij")
    r2 = 1.0 + s * s + t * t
    dens = h * h * r2 ** -1.5
    inv = 1.0 / np.sqrt(r2)
    comp = [(s * inv * dens), (t * inv * dens), (inv * dens)]
    comp = [x.reshape(n, sub, n, sub).sum(axis=(1, 3)) for x in comp]       # (n, n) each
    means = (FACE_AXES[:, None, None, 1, :] * comp[0][None, :, :, None]
             + FACE_AXES[:, None, None, 2, :] * comp[1][None, :, :, None]
             + FACE_AXES[:, None, None, 0, :] * comp[2][None, :, :, None])
    means = means.reshape(-1, 3)
    # Rescale so the length matches the exact solid angle of each texel.
    quad_area = np.broadcast_to(
        (h * h * r2 ** -1.5).reshape(n, sub, n, sub).sum(axis=(1, 3)), (6, n, n)).reshape(-1)
    return means / quad_area[:, None]


def direction_to_texel(dirs: np.ndarray, resolution: int) -> np.ndarray:
    """Flat cubemap texel index for world directions ``dirs`` (..., 3)."""
    d = np.asarray(dirs, dtype=np.float64)
    ax = np.abs(d)
    major = np.argmax(ax, axis=-1)
    comp = np.take_along_axis(d, major[..., None], axis=-1)[..., 0]
    face = 2 * major + (comp < 0)
    m = np.take_along_axis(ax, major[..., None], axis=-1)[..., 0]
    m = np.where(m > 0, m, 1.0)
    axes = FACE_AXES[face]                                    # (..., 3, 3)
    s = np.einsum("...k,...k->...", d, axes[..., 1, :]) / m
    t = np.einsum("...k,...k->...", d, axes[..., 2, :]) / m
    n = int(resolution)
    col = np.clip(((s + 1.0) * 0.5 * n).astype(np.int64), 0, n - 1)
    row = np.clip(((t + 1.0) * 0.5 * n).astype(np.int64), 0, n - 1)
    return (face * n + row) * n + col


def orthonormal_frame(normals: np.ndarray):
    """Tangent and bitangent completing unit ``normals`` (P, 3) to right-handed frames.

    Branchless construction of Duff et al. 2017 ("Building an orthonormal basis,
    revisited"); stable for every unit normal including +-Z.
    """
    n = np.asarray(normals, dtype=np.float64)
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    tangent = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bitangent = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return tangent, bitangent


def hemisphere_uniform(resolution: int):
    """Equal-area cells on the upper hemisphere (local frame, z up).

    ``resolution`` x ``resolution`` cells of the map (u, v) -> (cos(theta) = 1 - u,
    phi = 2*pi*v), each of solid angle ``2*pi / resolution**2`` exactly.
    Returns ``(directions (R*R, 3), solid_angles (R*R,))``.
    """
    r = int(resolution)
    c = (np.arange(r) + 0.5) / r
    u, v = np.meshgrid(c, c, indexing="ij")
    cos_t = 1.0 - u
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * v
    dirs = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1).reshape(-1, 3)
    return dirs, np.full(r * r, 2.0 * np.pi / (r * r))


def fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` nearly uniform unit directions (spherical Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
