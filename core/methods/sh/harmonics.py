"""Spherical-harmonic PRT (Sloan et al. 2002, as the PRT survey presents it): diffuse
shadowed transfer.

Real, orthonormal spherical harmonics ``Y_i`` with ``i = l*(l+1) + m``; an
*order* ``n`` keeps the bands ``l < n`` (``n*n`` coefficients: order 2, 3, 4, 5
-> 4, 9, 16, 25).  Per shading point the transfer vector is

    T_i = integral Y_i(w) V(w) max(0, n . w) dw          (Sloan et al. 2002: the transfer vector)

(summed over the same cubemap texels and the same bit-packed visibility as
REFERENCE), the lighting is projected as ``l_i = integral L(w) Y_i(w) dw``, and
the outgoing radiance of a Lambert surface is ``rho/pi * sum_i l_i T_i`` -- a dot
product per point.  Rotating the world (a Mapping node) rotates the lighting's
coefficients band by band (:func:`rotation_matrix`) instead of re-projecting.
"""

from __future__ import annotations

import math

import numpy as np

from ...sphere.directions import Cubemap, cubemap, fibonacci_sphere
from ...sphere.envmap import CubeLighting, WorldLighting
from ...scene.visibility import unpack_visibility

ORDERS = (2, 3, 4, 5)


def coefficient_count(order: int) -> int:
    return int(order) * int(order)


def basis(dirs: np.ndarray, order: int) -> np.ndarray:
    """Real orthonormal SH ``Y_i(w)`` for unit directions (N, 3) -> (N, order^2).

    ``Y_l^0 = K_l^0 P_l^0(z)``, ``Y_l^m = sqrt(2) K_l^m P_l^m(z) cos(m phi)`` and
    ``Y_l^-m = sqrt(2) K_l^m P_l^m(z) sin(m phi)`` for ``m > 0``, with
    ``K_l^m = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!)`` and the associated Legendre
    polynomials with the Condon-Shortley phase, by the standard recurrences.
    """
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = int(order)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    phi = np.arctan2(y, x)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    out = np.empty((len(d), n * n))
    # P[l][m] for the current columns
    P = {}
    P[(0, 0)] = np.ones_like(z)
    for m in range(1, n):
        P[(m, m)] = -(2 * m - 1) * sin_t * P[(m - 1, m - 1)]
    for m in range(0, n - 1):
        P[(m + 1, m)] = (2 * m + 1) * z * P[(m, m)]
    for m in range(0, n):
        for l in range(m + 2, n):
            P[(l, m)] = ((2 * l - 1) * z * P[(l - 1, m)] - (l + m - 1) * P[(l - 2, m)]) / (l - m)
    for l in range(n):
        for m in range(0, l + 1):
            k = math.sqrt((2 * l + 1) / (4 * math.pi) * math.factorial(l - m) / math.factorial(l + m))
            if m == 0:
                out[:, l * (l + 1)] = k * P[(l, 0)]
            else:
                out[:, l * (l + 1) + m] = math.sqrt(2) * k * P[(l, m)] * np.cos(m * phi)
                out[:, l * (l + 1) - m] = math.sqrt(2) * k * P[(l, m)] * np.sin(m * phi)
    return out


def project(values: np.ndarray, dirs: np.ndarray, weights: np.ndarray, order: int) -> np.ndarray:
    """Coefficients ``sum_k values_k Y_i(w_k) weight_k``: (order^2,) or (order^2, C)."""
    Y = basis(dirs, order)
    v = np.asarray(values, dtype=np.float64)
    return Y.T @ (v * (np.asarray(weights, dtype=np.float64).reshape(-1, *([1] * (v.ndim - 1)))))


def reconstruct(coeffs: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """``sum_i c_i Y_i(w)`` at ``dirs``."""
    c = np.asarray(coeffs, dtype=np.float64)
    order = int(round(math.sqrt(c.shape[0])))
    return basis(dirs, order) @ c


def project_lighting(lighting: CubeLighting, cube: Cubemap, order: int) -> np.ndarray:
    """(order^2, 3) coefficients of cubemap lighting (each texel at its light's direction)."""
    return project(lighting.radiance, lighting.unit_directions, cube.solid_angles, order)


def transfer(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap, order: int,
             block: int = 512, tick=None) -> np.ndarray:
    """Diffuse shadowed transfer vectors (P, order^2) float32 from stored visibility.

    The cosine of each texel is its exact mean cosine (``cube.mean_directions``),
    as in REFERENCE; the basis is evaluated at the texel centre.  ``tick(fraction)``
    is called after each block (it may raise to stop).
    """
    Y = (basis(cube.directions, order) * cube.solid_angles[:, None]).astype(np.float32)
    means = np.asarray(cube.mean_directions, dtype=np.float32)
    normals = np.asarray(normals, dtype=np.float32)
    out = np.empty((len(normals), coefficient_count(order)), dtype=np.float32)
    for a in range(0, len(normals), block):
        b = min(len(normals), a + block)
        w = normals[a:b] @ means.T
        np.maximum(w, 0.0, out=w)
        w *= unpack_visibility(vis_bits[a:b], cube.size)
        out[a:b] = w @ Y
        if tick is not None:
            tick(b / len(normals))
    return out


def rotation_matrix(R: np.ndarray, order: int) -> np.ndarray:
    """(order^2, order^2) block-diagonal matrix ``M`` with ``M @ c`` the coefficients of
    ``w -> f(R^T w)`` when ``c`` are those of ``f`` (rotating a function by ``R``).

    Each band's block solves ``Y_l(R u) = M_l Y_l(u)`` in the least-squares sense on
    64 well-spread directions: exact to rounding, since rotations map a band onto
    itself.
    """
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    u = fibonacci_sphere(64)
    Yu = basis(u, order)
    Yr = basis(u @ R.T, order)
    M = np.zeros((coefficient_count(order), coefficient_count(order)))
    for l in range(order):
        s = slice(l * l, (l + 1) * (l + 1))
        # Yr[:, s] = Yu[:, s] @ M_l.T   ->  solve for M_l.T
        sol, *_ = np.linalg.lstsq(Yu[:, s], Yr[:, s], rcond=None)
        M[s, s] = sol.T
    # coefficients of f(R^T w): g_i = sum_j M_ij f_j  with Y_i(R u) = sum_j M_ij Y_j(u)
    return M


class LightingProjector:
    """SH coefficients of a world's lighting, with rotations applied band-wise.

    The environment image is projected once in *texture* space; a Mapping
    rotation ``R`` (``L(d) = E(R d)``) then costs one small matrix product.
    """

    def __init__(self, order: int, resolution: int = 64):
        self.order = int(order)
        self.resolution = int(resolution)
        self._key = None
        self._texture_coeffs = None

    def coefficients(self, world: WorldLighting, content_key=None) -> np.ndarray:
        """(order^2, 3) coefficients of ``world`` (strength and rotation included)."""
        key = (content_key if content_key is not None else id(world.image), tuple(world.color))
        if key != self._key:
            unrotated = WorldLighting(image=world.image, color=world.color, strength=1.0)
            cube = cubemap(self.resolution)
            self._texture_coeffs = project_lighting(unrotated.to_cubemap(self.resolution), cube,
                                                    self.order)
            self._key = key
        # L(d) = E(R d) = E_rot(d) with E_rot(w) = E(R w): rotation by R^T.
        M = rotation_matrix(np.asarray(world.rotation).T, self.order)
        return world.strength * (M @ self._texture_coeffs)


def shade_diffuse(transfer_vectors: np.ndarray, light_coeffs: np.ndarray) -> np.ndarray:
    """Irradiance-like sums ``sum_i l_i T_i`` per point, (P, 3) float32 (times rho/pi
    gives Lambert radiance)."""
    return np.asarray(transfer_vectors, dtype=np.float32) @ np.asarray(light_coeffs,
                                                                       dtype=np.float32)
