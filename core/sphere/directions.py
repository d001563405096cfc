"""Direction sets on the sphere with exact solid-angle weights.

The cubemap is the discretisation every method shares (Inger et al. 2013, §4: "we use a
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

import numpy as np

from ..common.cache import memo

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


@memo(8)
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


def face_coordinates(dirs):
    """``(face, s, t)`` of directions (..., 3): the cube face and the coordinates in
    [-1, 1] on it (``s`` grows with the column, ``t`` with the row)."""
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
    return face, s, t


def texel_of_components(x, y, z, resolution: int) -> np.ndarray:
    """Flat cubemap texel index (int32) of directions given as component arrays ``x, y, z``
    (same shape), computed in their float type (float32 stays float32: the hot sample
    loops of SSDF and RSL).  The face coordinates of :data:`FACE_AXES` written out per
    major axis: +X (s, t) = (-z, -y)/|x|, -X (z, -y), +Y (x, z), -Y (x, -z), +Z (x, -y),
    -Z (-x, -y); ties go to x, then y."""
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    m = np.maximum(np.maximum(ax, ay), az)
    is_x = ax == m
    is_y = (ay == m) & ~is_x
    is_z = ~(is_x | is_y)
    s = np.where(is_x, z, x)
    np.negative(s, out=s, where=np.where(is_x, x >= 0, is_z & (z < 0)))
    t = np.where(is_y, z, y)
    np.negative(t, out=t, where=np.where(is_y, y < 0, True))
    m = np.where(m > 0, m, 1)
    h = 0.5 * int(resolution)
    s /= m
    s += 1
    s *= h
    t /= m
    t += 1
    t *= h
    n = int(resolution)
    col = np.clip(s.astype(np.int32), 0, n - 1)
    row = np.clip(t.astype(np.int32), 0, n - 1)
    face = np.where(is_x, x < 0, np.where(is_y, y < 0, z < 0)).astype(np.int32)
    face += 2 * is_y + 4 * is_z
    return (face * n + row) * n + col


def direction_to_texel(dirs: np.ndarray, resolution: int) -> np.ndarray:
    """Flat cubemap texel index for world directions ``dirs`` (..., 3)."""
    d = np.asarray(dirs)
    if not np.issubdtype(d.dtype, np.floating):
        d = d.astype(np.float64)
    return texel_of_components(d[..., 0], d[..., 1], d[..., 2], resolution)


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


# --------------------------------------------------------------------------- hemisphere maps
# Local frame: z is the normal.  Both maps below are equal-area, so solid
# angles follow from areas in the square exactly.

def shirley_chiu_to_hemisphere(a, b):
    """Shirley-Chiu concentric map of the square [-1, 1]^2 to the upper hemisphere.

    The square goes to the unit disk by the concentric map (area preserving up
    to pi/4), the disk to the hemisphere by the equal-area lift
    ``z = 1 - r^2``, ``xy *= sqrt(2 - r^2)``.  Every region of the square of area
    ``A`` covers the solid angle ``A * pi / 2``.  (Shirley & Chiu 1997; the SSDF
    images of Wang et al. 2009, §5.2, live in this square.)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    use_a = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4) * (b / safe_a), np.pi / 2 - (np.pi / 4) * (a / safe_b))
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    r2 = r * r
    s = np.abs(r) * np.sqrt(np.maximum(0.0, 2.0 - r2))
    sign = np.where(r < 0, -1.0, 1.0)
    return np.stack([sign * s * np.cos(phi), sign * s * np.sin(phi), 1.0 - r2], axis=-1)


def hemisphere_to_shirley_chiu(dirs):
    """Inverse of :func:`shirley_chiu_to_hemisphere` for local directions with z >= 0."""
    d = np.asarray(dirs, dtype=np.float64)
    z = np.clip(d[..., 2], 0.0, 1.0)
    r = np.sqrt(1.0 - z)                                  # disk radius
    phi = np.mod(np.arctan2(d[..., 1], d[..., 0]) + np.pi / 4, 2 * np.pi)   # [0, 2pi)
    sector = np.minimum((phi // (np.pi / 2)).astype(np.int64), 3)
    t = (phi - sector * (np.pi / 2)) * (4 / np.pi) - 1.0        # in [-1, 1]
    a = np.empty_like(r)
    b = np.empty_like(r)
    for k in range(4):
        m = sector == k
        tk = t[m]
        rk = r[m]
        if k == 0:
            a[m], b[m] = rk, rk * tk
        elif k == 1:
            a[m], b[m] = -rk * tk, rk
        elif k == 2:
            a[m], b[m] = -rk, -rk * tk
        else:
            a[m], b[m] = rk * tk, -rk
    return a, b


def shirley_chiu_hemisphere(resolution: int):
    """Texel centres of an N x N Shirley-Chiu square and their exact solid angles.

    Returns ``(directions (N*N, 3) local, solid_angles (N*N,))``; rows index b,
    columns index a, both from -1 to 1.  Every texel covers ``2*pi / N^2``.
    """
    n = int(resolution)
    c = -1.0 + (np.arange(n) + 0.5) * (2.0 / n)
    b, a = np.meshgrid(c, c, indexing="ij")
    dirs = shirley_chiu_to_hemisphere(a, b).reshape(-1, 3)
    return dirs, np.full(n * n, 2.0 * np.pi / (n * n))


def rsl_disk_to_hemisphere(px, py, whole_sphere: bool = False):
    """The hemisphere map of Xu et al. 2006, §5: ``p = sin(t)/sqrt(1+cos(t)) * (sin(f), cos(f))``.

    ``|p|^2 = 1 - cos(t)``: an equal-area (Lambert azimuthal) map of the
    hemisphere onto the unit disk, a region of area ``A`` covering ``2 A``
    steradians.  Points outside the disk are clamped to the horizon, or with
    ``whole_sphere`` continue below it (``|p|^2`` up to 2, the opposite pole).
    """
    px = np.asarray(px, dtype=np.float64)
    py = np.asarray(py, dtype=np.float64)
    r2 = np.minimum(px * px + py * py, 2.0 if whole_sphere else 1.0)
    cos_t = 1.0 - r2
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = np.arctan2(px, py)                              # p = r (sin f, cos f)
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


def hemisphere_to_rsl_disk(dirs):
    """Inverse of :func:`rsl_disk_to_hemisphere`: (px, py) for local directions."""
    d = np.asarray(dirs, dtype=np.float64)
    cos_t = np.clip(d[..., 2], -1.0, 1.0)
    r = np.sqrt(np.maximum(0.0, 1.0 - cos_t))
    phi = np.arctan2(d[..., 1], d[..., 0])
    return r * np.sin(phi), r * np.cos(phi)


def disk_strip_area(x0, x1, y0, y1):
    """Exact area of the unit disk inside [x0, x1] x [y0, y1] (vectorised)."""
    def H(x):                                            # integral of sqrt(1 - x^2)
        x = np.clip(x, -1.0, 1.0)
        return 0.5 * (x * np.sqrt(1.0 - x * x) + np.arcsin(x))

    def upto(y, x_lo, x_hi):
        # integral over [x_lo, x_hi] of the length of {y' <= y} inside the disk
        # column at x, i.e. clip(y + h(x), 0, 2h(x)) with h = sqrt(1 - x^2).
        # Split where h(x) = |y| (the only kink inside |x| < 1).
        xs = np.sqrt(np.clip(1.0 - y * y, 0.0, 1.0))
        total = np.zeros_like(y)
        # pieces: |x| > xs (h < |y|) and |x| < xs (h > |y|)
        for lo, hi, inner in ((-1.0, -xs, False), (-xs, xs, True), (xs, 1.0, False)):
            a = np.clip(np.maximum(x_lo, lo), -1.0, 1.0)
            b = np.clip(np.minimum(x_hi, hi), -1.0, 1.0)
            b = np.maximum(a, b)
            if inner:           # |y| < h: column cut at y: length y + h
                total += y * (b - a) + (H(b) - H(a))
            else:               # h <= |y|: whole column (2h) if y > 0, nothing if y < 0
                total += np.where(y > 0, 2.0 * (H(b) - H(a)), 0.0)
        return total

    return upto(np.asarray(y1, float), x0, x1) - upto(np.asarray(y0, float), x0, x1)


def rsl_hemisphere(resolution: int):
    """N x N texels of Xu et al. 2006's disk map over [-1, 1]^2 (rows py, columns px).

    Returns ``(directions (N*N, 3) local, solid_angles (N*N,))``: texel centres
    mapped to the hemisphere (clamped to the horizon outside the disk) and the
    exact solid angle ``2 * area(texel ∩ disk)`` (0 for texels outside it).
    """
    n = int(resolution)
    edges = np.linspace(-1.0, 1.0, n + 1)
    c = 0.5 * (edges[:-1] + edges[1:])
    py, px = np.meshgrid(c, c, indexing="ij")
    y0, x0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    y1, x1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    area = disk_strip_area(x0, x1, y0, y1)
    dirs = rsl_disk_to_hemisphere(px, py).reshape(-1, 3)
    return dirs, (2.0 * area).reshape(-1)
