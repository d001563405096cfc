"""The bounce of one frame: the direct light at each gather cluster, carried to every
receiver through the stored transfer rows, as many times as the scene's light paths allow.

With ``L_m`` the diffuse radiance a cluster sends (``rho_m E_m / pi``; ``E_m`` the direct
irradiance at its sample point from the World -- its compact sources included -- and the
lamps), one bounce gives each receiver ``E_ind = T_pm L_m`` (:mod:`.transfer`).  Further
bounces go through the clusters first: ``E'_m = T_mj L_j``, ``L'_m = rho_m E'_m / pi``,
and the receivers gather the sum ``L + L' + ...`` (Sloan, Kautz, Snyder 2002, §5: bounce
passes, each gathering the previous one; Hasan, Pellacini, Bala 2006: the gather-to-gather
matrix for multiple bounces).  Reflectors send their whole albedo, diffuse and glossy,
as diffuse light (:func:`reflectance`: the glossy part's energy kept, its direction not);
receivers take the bounce through their diffuse part and, as if it came evenly from
their hemisphere, through their glossy part (:func:`glossy_albedo`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..common.cache import Cache
from ..sg.lamp_lobes import Lamp
from ..shading import brdf

#: shadow rays traced per area lamp and gather point (points spread over its surface)
AREA_SAMPLES = 4
#: view cosines (Gauss-Legendre on [0, 1], cosine-weighted) averaging a Principled base's
#: layering weight into its diffuse reflectance
_MU, _MU_W = np.polynomial.legendre.leggauss(6)
_MU = 0.5 * (_MU + 1.0)
_MU_W = _MU_W * _MU          # cosine-weighted, normalised below
_MU_W = _MU_W / _MU_W.sum()
#: the glossy albedo's quadrature: Gauss-Legendre in cos(theta), uniform in phi, and view
#: cosines a table interpolates between
_GL_MU, _GL_W = np.polynomial.legendre.leggauss(48)
_GL_MU, _GL_W = 0.5 * (_GL_MU + 1.0), 0.5 * _GL_W
_GL_PHI = 192
_GL_VIEWS = np.linspace(0.02, 1.0, 12)
#: lobes narrower than the quadrature resolves are integrated at this roughness: a
#: microfacet lobe's albedo changes by under 2 % between it and a mirror's
GLOSSY_QUADRATURE_ROUGHNESS = 0.3
#: rows gathered at once by :func:`bounce` and :func:`receive`
GATHER_BLOCK = 32768
#: the glossy albedo per material (its repr): a small table, computed in ~10 ms
_GLOSSY_TABLES = Cache(256)


def _hemisphere():
    """(D, 3) directions and (D,) solid angles of the glossy albedo's quadrature."""
    phi = (np.arange(_GL_PHI) + 0.5) * (2.0 * math.pi / _GL_PHI)
    mu = np.repeat(_GL_MU, _GL_PHI)
    s = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    ph = np.tile(phi, len(_GL_MU))
    dirs = np.column_stack([s * np.cos(ph), s * np.sin(ph), mu])
    return dirs, np.repeat(_GL_W, _GL_PHI) * (2.0 * math.pi / _GL_PHI)


def _glossy_table(material) -> np.ndarray:
    """(len(_GL_VIEWS), 3) the glossy albedo at the table's view cosines (cached)."""
    key = repr(material)
    got = _GLOSSY_TABLES.get(key)
    if got is not None:
        return got
    mat = replace(material, per_pixel_lobe=False,
                  roughness=max(float(material.roughness), GLOSSY_QUADRATURE_ROUGHNESS))
    table = np.zeros((len(_GL_VIEWS), 3))
    if not mat.is_diffuse_only:
        dirs, w = _hemisphere()
        views = np.column_stack([np.sqrt(1.0 - _GL_VIEWS ** 2), 0 * _GL_VIEWS, _GL_VIEWS])
        n = np.tile([0.0, 0.0, 1.0], (len(views), 1))
        spec = np.asarray(brdf.specular_cosine(mat, n, views, dirs), np.float64)
        if spec.ndim == 2:                           # a colourless lobe: times its colour
            spec = spec[..., None] * np.asarray(mat.specular_color, np.float64)
        table = np.einsum("vdc,d->vc", spec, w)
    _GLOSSY_TABLES[key] = table
    return table


def glossy_albedo(material, cos_o) -> np.ndarray:
    """(N, 3) the share of light arriving evenly over the hemisphere that a material's
    glossy part sends toward views at ``cos_o`` (N,): the cosine-weighted integral of its
    lobe (core.shading.brdf.specular_cosine, Fresnel, layering and multiscatter included)
    by quadrature; by reciprocity also the share of light from ``cos_o`` it reflects."""
    table = _glossy_table(material)
    c = np.clip(np.asarray(cos_o, np.float64).reshape(-1), _GL_VIEWS[0], 1.0)
    return np.column_stack([np.interp(c, _GL_VIEWS, table[:, k]) for k in range(3)])


def reflectance(material, weight_of_views=None) -> np.ndarray:
    """(3,) the share of light a reflector sends back (cosine-weighted over incidence):
    its diffuse base's (:func:`diffuse_reflectance`) and its glossy part's, all sent on
    as diffuse light."""
    return (diffuse_reflectance(material, weight_of_views)
            + _MU_W @ glossy_albedo(material, _MU))


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
    ``occluded(origins, directions, distances, rows)`` -> (N,) bool tests the shadow
    rays of the points ``rows`` (None: unshadowed)."""
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


def distant_source(direction, radiance, radius: float, point_like: bool = False) -> Lamp:
    """A compact source of the World (core.sphere.sources: a disc of ``radius`` and uniform
    ``radiance`` toward ``direction``) as the sun lamp of the same irradiance at normal
    incidence (``radiance`` is that irradiance already when ``point_like``)."""
    e = np.asarray(radiance, np.float64)
    if not point_like:
        e = e * (2.0 * math.pi * (1.0 - math.cos(float(radius))))
    d = np.asarray(direction, np.float64)
    return Lamp("SUN", color=tuple(e), direction=tuple(-d / max(np.linalg.norm(d), 1e-300)),
                angle=2.0 * float(radius))


def _visible(occluded, x, n, to, dist, weight) -> np.ndarray:
    """1 where the shadow ray toward the lamp is free (only rays that carry light are
    traced), else 0."""
    vis = (weight > 0.0).astype(np.float64)
    if occluded is None or not vis.any():
        return vis
    sel = np.nonzero(vis)[0]
    blocked = occluded(x[sel], to[sel], dist[sel], sel)
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
    for _ in range(max(int(bounces), 1) - 1):
        L = rho * _gather(columns, weights, L, np.float64)
        total += L
    return total


def receive(columns: np.ndarray, weights: np.ndarray, radiance: np.ndarray,
            rest: np.ndarray | None = None, rest_light: np.ndarray | None = None) -> np.ndarray:
    """(P, 3) bounced irradiance of each receiver: its row over the clusters' radiance, plus
    its row's ``rest`` (P,) times the radiance it is read at (``rest_light`` (P, 3),
    :func:`rest_radiance`)."""
    out = _gather(columns, weights, np.asarray(radiance, np.float32), np.float32)
    if rest is not None:
        out += (np.asarray(rest, np.float64)[:, None] * rest_light).astype(np.float32)
    return out


def _gather(columns, weights, values, dtype) -> np.ndarray:
    """(N, 3) ``sum_w weights[n, w] values[columns[n, w]]`` in ``dtype``, a block of rows at
    a time (a block's ``values[columns]`` is its rows x width x 3: a thousand instances'
    clusters at once would be hundreds of MB)."""
    out = np.empty((len(columns), 3), dtype)
    for a in range(0, len(columns), GATHER_BLOCK):
        b = a + GATHER_BLOCK
        out[a:b] = np.einsum("kw,kwc->kc", np.asarray(weights[a:b], dtype), values[columns[a:b]])
    return out


def seen_radiance(columns: np.ndarray, weights: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(K, 3) the mean radiance each cluster sees: its row's gather over its row's sum (the
    cosine-weighted share of its hemisphere that sees the scene); 0 where it sees none."""
    total = np.asarray(weights, np.float64).sum(axis=1)
    got = _gather(columns, weights, np.asarray(radiance, np.float64), np.float64)
    return got / np.where(total > 0.0, total, np.inf)[:, None]


def rest_radiance(seen: np.ndarray, cluster_of_triangle: np.ndarray, tri_points: np.ndarray,
                  areas: np.ndarray, points: int) -> np.ndarray:
    """(P, 3) the radiance a receiver's row's rest (the entries past its width) is read at:
    the mean radiance the clusters of its own triangles see (``seen``, :func:`seen_radiance`),
    weighted by the triangles' areas (``tri_points`` (T, 3) the point of each corner,
    ``cluster_of_triangle`` (T,) the cluster of each triangle's side)."""
    tp = np.asarray(tri_points, np.int64).reshape(-1, 3)
    a = np.maximum(np.asarray(areas, np.float64), 0.0)
    e = np.asarray(seen, np.float64)[np.asarray(cluster_of_triangle, np.int64)] * a[:, None]
    idx = tp.reshape(-1)
    total = np.bincount(idx, weights=np.repeat(a, 3), minlength=points)
    out = np.stack([np.bincount(idx, weights=np.repeat(e[:, c], 3), minlength=points)
                    for c in range(3)], axis=1)
    return out / np.maximum(total, 1e-300)[:, None]
