"""Rotatable square lights (Xu, Jia, Hu, Tai 2006): light decomposition, BRDF SATs,
visibility distance tables and the per-vertex evaluation of eq. 5.

Per vertex ``x`` and view ``wo`` the rendering integral over the environment is split
into ``K`` subregions ``S_i`` and each is approximated by the product of separate
integrals (eq. 5)::

    B(x, wo) ~= sum_i  E_i * avg_{R_i}(rho cos) * avg_{R_i}(V)

``E_i = integral of L over S_i`` (RGB, preserved exactly by the decomposition of
§4.1), ``R_i`` the square of the RSL in the vertex's disk parameterization (§5:
``p = sin(t)/sqrt(1+cos(t)) (sin f, cos f)``, equal-area with ``dw = 2 dp``, so the
square has area ``|S_i| / 2``); the BRDF average comes from a summed-area table (§4.2,
eq. 6/8, four look-ups per view node) and the visibility average from the visibility
distance table (§4.3, eq. 9) or, as the exact option, from a per-vertex SAT of the
visibility map.  ``V`` is the visibility of the hemisphere only: the horizon is cut
once, by the cosine in ``rho cos`` (see :func:`visibility_maps`).

Everything here is numpy only; :mod:`..addon.methods.rsl.shading` and the GLSL pass use the
same tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...shading import brdf
from ...shading import materials
from ...sphere.directions import orthonormal_frame
from ...sphere.directions import rsl_disk_to_hemisphere
from .square_lights import SquareLights
from ...scene.distance_tables import box_integral, disk_coordinates, disk_texel_samples, summed_area, vdt_box

# --------------------------------------------------------------------------- #
# §4.1  Light decomposition
# --------------------------------------------------------------------------- #


# --------------------------------------------------------------------------- #
# Summed-area tables on the disk map (§4.2, §5)
# --------------------------------------------------------------------------- #


@dataclass
class BrdfTables:
    """BRDF x cosine SATs of one material on the disk map (§4.2, isotropic: 3D).

    Glossy: for each separable term ``k`` of :func:`..brdf.specular_terms` a table
    ``glossy[k]`` (M, N+1, N+1) over ``M`` view elevations ``view_angles`` (view in
    the local x-z plane, azimuth 0) of the per-texel integral ``integral f_k cos dp``.
    ``cosine`` (N+1, N+1): the same for ``max(0, cos)`` (Lambert, view independent).
    ``offsets``: the per-table mean subtracted before summation -- the SAT precision
    fix for 32-bit GPUs (the sums of ``f - mean`` stay small); add
    ``offset * box area`` back after a box look-up (:func:`brdf_box`).
    """

    resolution: int
    view_angles: np.ndarray
    cosine: np.ndarray
    cosine_offset: float
    glossy: list = field(default_factory=list)
    glossy_offsets: list = field(default_factory=list)
    seconds: float = 0.0


def offset_sat(texel_integrals: np.ndarray, cell_area: float):
    """SAT of ``texel_integrals - mean`` and the mean value per unit area."""
    mean = float(texel_integrals.mean()) / cell_area
    return summed_area(texel_integrals - mean * cell_area), mean


def _texel_sum(values: np.ndarray, resolution: int, sub: int) -> np.ndarray:
    n = int(resolution)
    return values.reshape(values.shape[:-2] + (n, sub, n, sub)).sum(axis=(-3, -1))


def table_material(material: materials.Material) -> materials.Material:
    """The material :func:`brdf_tables` needs: the base colour reaches the glossy tables only
    through a Principled metal lobe (its F0), so without one it is set to the default (a
    textured slot's variants shaded with white and black share their tables)."""
    if material.fresnel == "DIELECTRIC" and material.metallic > 0.0:
        return material
    return replace(material, diffuse_albedo=materials.Material().diffuse_albedo)


def brdf_tables(material: materials.Material, resolution: int = 32, views: int = 32,
                sub: int = 4) -> BrdfTables:
    """Tabulate ``material``'s BRDF x cosine into SATs (§4.2; isotropic, so the view
    needs only its elevation: ``views`` nodes over [0, pi/2]).  Texel integrals use
    ``sub x sub`` midpoint samples inside the unit disk (zero outside: below the
    horizon)."""
    import time
    t0 = time.perf_counter()
    n = int(resolution)
    px, py, da, inside = disk_texel_samples(n, sub)
    dirs = rsl_disk_to_hemisphere(px, py).reshape(-1, 3)
    w = np.where(inside, da, 0.0).reshape(-1)
    cell = (2.0 / n) ** 2
    cos_int = _texel_sum((np.maximum(dirs[:, 2], 0.0) * w).reshape(px.shape), n, sub)
    cosine, cos_off = offset_sat(cos_int, cell)
    angles = np.linspace(0.0, 0.5 * np.pi, int(views))
    out = BrdfTables(n, angles, cosine, cos_off)
    if not material.is_diffuse_only:
        M = len(angles)
        normals = np.tile([0.0, 0.0, 1.0], (M, 1))
        vdirs = np.stack([np.sin(angles), np.zeros(M), np.cos(angles)], axis=1)
        sel = w > 0
        for lobe, _weight in brdf.specular_terms(material, normals, vdirs, dirs[sel]):
            full = np.zeros((M, len(w)))
            full[:, sel] = lobe * w[sel]
            integ = _texel_sum(full.reshape((M,) + px.shape), n, sub)
            sats, offs = zip(*(offset_sat(integ[j], cell) for j in range(M)))
            out.glossy.append(np.stack(sats))
            out.glossy_offsets.append(np.array(offs))
    out.seconds = time.perf_counter() - t0
    return out


def brdf_box(tables: BrdfTables, term: int | None, view_angle, px, py, half) -> np.ndarray:
    """Average of the term's ``f cos`` over the square (glossy ``term`` index, or None
    for the cosine), linear in the view elevation between table nodes (eq. 8)."""
    area = (2.0 * half) ** 2
    if term is None:
        box = box_integral(tables.cosine, px, py, half)
        return box / area + tables.cosine_offset * clipped_area(px, py, half) / area
    angles = tables.view_angles
    M = len(angles)
    t = np.clip(np.asarray(view_angle, dtype=np.float64) / (angles[1] - angles[0]), 0, M - 1)
    j0 = np.minimum(t.astype(np.int64), M - 2)
    f = t - j0
    S, off = tables.glossy[term], tables.glossy_offsets[term]
    clip = clipped_area(px, py, half)
    b0 = box_integral(S, px, py, half, lead=j0) + off[j0] * clip
    b1 = box_integral(S, px, py, half, lead=j0 + 1) + off[j0 + 1] * clip
    return ((1.0 - f) * b0 + f * b1) / area


def clipped_area(px, py, half):
    wx = np.clip(px + half, -1, 1) - np.clip(px - half, -1, 1)
    wy = np.clip(py + half, -1, 1) - np.clip(py - half, -1, 1)
    return wx * wy


# --------------------------------------------------------------------------- #
# §4.3  Visibility in the disk map: maps, VDT (eq. 9), SAT
# --------------------------------------------------------------------------- #


# --------------------------------------------------------------------------- #
# Per-vertex evaluation (eq. 5, Fig. 8)
# --------------------------------------------------------------------------- #


def view_frames(normals: np.ndarray, views: np.ndarray):
    """Frames ``(t', b', n)`` whose x axis is the view projected on the tangent plane
    (the isotropic tables are tabulated at view azimuth 0) and the view elevation."""
    n = np.asarray(normals, dtype=np.float64)
    v = np.asarray(views, dtype=np.float64)
    cos_o = np.einsum("ij,ij->i", n, v)
    tp = v - cos_o[:, None] * n
    ln = np.linalg.norm(tp, axis=1)
    t0, _ = orthonormal_frame(n)
    tp = np.where(ln[:, None] > 1e-9, tp / np.maximum(ln, 1e-300)[:, None], t0)
    bp = np.cross(n, tp)
    return tp, bp, np.arccos(np.clip(cos_o, 0.0, 1.0))


def visible_fraction(kind: str, table: np.ndarray, px, py, half) -> np.ndarray:
    """``avg_R V`` (P, K) for per-vertex tables: ``"VDT"`` (eq. 9, one look-up) or
    ``"SAT"`` (exact box integral of the visibility map, four look-ups, averaged over
    the part of the square inside the table: the map has no values beyond it, where a
    square near the horizon reaches; 1 for a square wholly outside)."""
    lead = np.arange(len(table))[:, None]
    if kind == "VDT":
        return vdt_box(table, px, py, half, lead=lead)
    area = clipped_area(px, py, half)
    inside = area > 1e-12
    return np.where(inside, box_integral(table, px, py, half, lead=lead)
                    / np.where(inside, area, 1.0), 1.0)


class Evaluator:
    """Numpy per-vertex RSL shading (eq. 5 summed over lights, Fig. 8).

    ``lights``: :class:`SquareLights`; ``world_to_texture``: the world's rotation
    (centres are rotated, nothing recomputed).  ``tables(material)`` returns the
    material's :class:`BrdfTables` (cached by the caller)."""

    def __init__(self, lights: SquareLights, world_to_texture=None):
        R = np.eye(3) if world_to_texture is None else world_to_texture
        self.centres = lights.rotated(R)
        self.half = lights.half_sides[None, :]
        self.energy = lights.energy.astype(np.float64)

    def diffuse_factors(self, normals, vis_kind, vis_table, cos_table: BrdfTables):
        """View-independent ``avg_R V`` and ``avg_R cos`` (P, K) in the fixed frames."""
        t, b = orthonormal_frame(normals)
        px, py = disk_coordinates(self.centres, t, b, np.asarray(normals, np.float64))
        V = visible_fraction(vis_kind, vis_table, px, py, self.half)
        C = brdf_box(cos_table, None, None, px, py, self.half)
        return V, C

    def shade(self, material: materials.Material, tables: BrdfTables, normals, views, V, C):
        """Outgoing radiance (P, 3) of points sharing ``material``; ``V``, ``C`` from
        :meth:`diffuse_factors`; ``views`` (P, 3) unit toward the eye (None is
        allowed for diffuse-only, non-layered materials)."""
        normals = np.asarray(normals, dtype=np.float64)
        weights = point_weights(material, normals, views)
        out = ((C * V) @ self.energy) * weights[0]
        if len(weights) == 1:
            return out
        tp, bp, theta_o = view_frames(normals, views)
        px, py = disk_coordinates(self.centres, tp, bp, normals)
        th = np.broadcast_to(theta_o[:, None], px.shape)
        for k, w in enumerate(weights[1:]):
            G = brdf_box(tables, k, th, px, py, self.half)
            out += ((G * V) @ self.energy) * w
        return out


def point_weights(material: materials.Material, normals, views) -> list:
    """Per-point RGB weights (P, 3) of the tabulated sums: ``albedo/pi * W(n, wo)`` for
    the cosine table (Principled layering weight ``W``, 1 otherwise), then one per
    glossy term of :func:`..brdf.specular_terms` (Fresnel, colour, multiscatter; they
    depend on the view elevation only, so they stay outside the SATs)."""
    normals = np.asarray(normals, dtype=np.float64)
    P = len(normals)
    diffuse = np.zeros((P, 3))
    if material.has_diffuse:
        diffuse += np.asarray(material.diffuse_albedo) / np.pi
        if material.fresnel == "DIELECTRIC":
            diffuse *= brdf.diffuse_view_weight(material, normals, views)
    if material.is_diffuse_only or P == 0:
        return [diffuse]
    return [diffuse] + [w.astype(np.float64) for _, w in brdf.specular_terms(
        material, normals, views, np.array([[0.0, 0.0, 1.0]]))]
