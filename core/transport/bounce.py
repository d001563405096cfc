"""The bounce of one frame: the direct light at each gather cluster, carried to every
receiver through the stored transfer rows, as many times as the scene's light paths allow.

With ``L_m`` the diffuse radiance a cluster sends (``rho_m E_m / pi``; ``E_m`` the direct
irradiance at its sample point from the World -- its compact sources included -- and the
lamps), one bounce gives each receiver ``E_ind = T_pm L_m`` (:mod:`.transfer`).  Further
bounces go through the clusters first: ``E'_m = T_mj L_j``, ``L'_m = rho_m E'_m / pi``,
and the receivers gather the sum ``L + L' + ...`` (Sloan, Kautz, Snyder 2002, §5: bounce
passes, each gathering the previous one; Hasan, Pellacini, Bala 2006: the gather-to-gather
matrix for multiple bounces).  Reflectors are diffuse with their albedo (their glossy
part sends nothing here); receivers take the bounce through their diffuse part.
"""

from __future__ import annotations

import math

import numpy as np

#: shadow rays traced per area lamp and gather point (points spread over its surface)
AREA_SAMPLES = 4
#: view cosines (Gauss-Legendre on [0, 1], cosine-weighted) averaging a Principled base's
#: layering weight into its diffuse reflectance
_MU, _MU_W = np.polynomial.legendre.leggauss(6)
_MU = 0.5 * (_MU + 1.0)
_MU_W = _MU_W * _MU          # cosine-weighted, normalised below
_MU_W = _MU_W / _MU_W.sum()


def diffuse_reflectance(material, weight_of_views=None) -> np.ndarray:
    """(3,) the share of light a material's diffuse base sends back, averaged over the
    directions it leaves in (cosine-weighted): its base colour times the weight a
    Principled layer leaves it (``weight_of_views(material, normals, views)`` (N, 3):
    ``core.shading.brdf.diffuse_view_weight``, metallic included; None: 1)."""
    albedo = np.asarray(material.diffuse_albedo, np.float64)
    if weight_of_views is None:
        return albedo
    n = np.tile([0.0, 0.0, 1.0], (len(_MU), 1))
    views = np.column_stack([np.sqrt(np.maximum(1.0 - _MU ** 2, 0.0)), 0 * _MU, _MU])
    w = np.asarray(weight_of_views(material, n, views), np.float64)[:, 0]
    return albedo * float(w @ _MU_W)


def lamp_irradiance(lamps, positions, normals, occluded=None) -> np.ndarray:
    """(S, 3) direct irradiance of Blender's lamps at points, as Cycles lights them, each
    lamp taken as a point (a sphere's or a disc's light from its centre: the bounce it
    drives is smooth) and an area lamp as :data:`AREA_SAMPLES` points on its surface;
    ``occluded(origins, directions, distances)`` -> (N,) bool tests the shadow rays
    (None: unshadowed)."""
    x = np.asarray(positions, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(x), 3))
    for lamp in lamps:
        col = np.asarray(lamp.color, np.float64).reshape(3)
        if lamp.kind == "SUN":
            to = np.broadcast_to(-np.asarray(lamp.direction, np.float64), x.shape)
            cos = np.maximum(np.einsum("ij,ij->i", n, to), 0.0)
            dist = np.full(len(x), np.inf)
            vis = _visible(occluded, x, n, to, dist, cos)
            out += (cos * vis)[:, None] * col
            continue
        if lamp.kind == "AREA":
            hx, hy = np.asarray(lamp.half_x, np.float64), np.asarray(lamp.half_y, np.float64)
            # the centres of its four quadrants (a disc's are 0.42 out: close enough for
            # the smooth light it bounces)
            spots = [(0.5 * sx, 0.5 * sy) for sx in (-1, 1) for sy in (-1, 1)][:AREA_SAMPLES]
            face = np.asarray(lamp.direction, np.float64)
            radiance = col / (math.pi * max(lamp.area, 1e-300))
            for sx, sy in spots:
                p = np.asarray(lamp.position, np.float64) + sx * hx + sy * hy
                v = p[None, :] - x
                dist = np.linalg.norm(v, axis=1)
                to = v / np.maximum(dist, 1e-300)[:, None]
                cos = np.maximum(np.einsum("ij,ij->i", n, to), 0.0)
                cos_l = np.maximum(-to @ face, 0.0)
                vis = _visible(occluded, x, n, to, dist, cos * cos_l)
                e = radiance[None, :] * (lamp.area / len(spots)) * \
                    (cos * cos_l * vis / np.maximum(dist * dist, 1e-300))[:, None]
                out += e
            continue
        v = np.asarray(lamp.position, np.float64)[None, :] - x
        dist = np.linalg.norm(v, axis=1)
        to = v / np.maximum(dist, 1e-300)[:, None]
        cos = np.maximum(np.einsum("ij,ij->i", n, to), 0.0)
        e = 1.0 / (4.0 * math.pi * np.maximum(dist * dist, 1e-300))
        if lamp.kind == "SPOT":
            axis = np.asarray(lamp.direction, np.float64)
            cos_a = -to @ axis
            half = math.cos(0.5 * lamp.spot_size)
            blend = (1.0 - half) * lamp.spot_blend
            t = np.clip((cos_a - half) / max(blend, 1e-9), 0.0, 1.0)
            e = e * np.where(cos_a > half, t * t * (3.0 - 2.0 * t) if blend > 0 else 1.0, 0.0)
        vis = _visible(occluded, x, n, to, dist, cos * e)
        out += (cos * e * vis)[:, None] * col
    return out


def _visible(occluded, x, n, to, dist, weight) -> np.ndarray:
    """1 where the shadow ray toward the lamp is free (only rays that carry light are
    traced), else 0."""
    vis = (weight > 0.0).astype(np.float64)
    if occluded is None or not vis.any():
        return vis
    sel = np.nonzero(vis)[0]
    blocked = occluded(x[sel], to[sel], dist[sel])
    vis[sel[blocked]] = 0.0
    return vis


def bounce(direct: np.ndarray, albedo: np.ndarray, columns: np.ndarray, weights: np.ndarray,
           bounces: int) -> np.ndarray:
    """(K, 3) the radiance the clusters send in all, summed over ``bounces`` bounces:
    ``L_0 = albedo E / pi`` from the direct irradiance ``direct`` (K, 3), then each further
    bounce gathered through the clusters' rows ``columns``/``weights`` (K, W)."""
    rho = np.asarray(albedo, np.float64) / math.pi
    L = rho * np.asarray(direct, np.float64)
    total = L.copy()
    w = np.asarray(weights, np.float64)
    for _ in range(max(int(bounces), 1) - 1):
        L = rho * np.einsum("kw,kwc->kc", w, L[columns])
        total += L
    return total


def receive(columns: np.ndarray, weights: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(P, 3) bounced irradiance of each receiver: its row over the clusters' radiance."""
    return np.einsum("pw,pwc->pc", np.asarray(weights, np.float32),
                     np.asarray(radiance, np.float32)[columns])
