"""REFERENCE: the pixel-basis triple product per shading point (Inger, Farbman, Lischinski 2013, §3, eq. 1).

    B(x, wo) = sum_k  L(w_k) V(x, w_k) rho(x, w_k, wo) max(0, n . w_k) dw_k

over every cubemap texel k, with ``dw_k`` the texel's exact solid angle.  This
is the "baseline" every faster method is measured against; it is exact for
the cubemap discretisation of lighting and visibility.

Lambert is view independent, so its part is split off:

    B = albedo/pi * W(n, wo) * sum_k L_k V_k cos_k dw_k  +  sum_k L_k V_k f_spec(w_k, wo) cos_k dw_k

The first sum (``diffuse_irradiance``) only changes with the lighting and is
cached by callers; ``W`` (:func:`~.brdf.diffuse_view_weight`, Cycles'
Principled layering: 1 for a plain Diffuse BSDF) and the second sum need the
view and are evaluated per frame.
"""

from __future__ import annotations


import numpy as np

from ...shading.brdf import diffuse_view_weight, specular_cosine, specular_terms
from ...shading.materials import Material, slot_material
from ...sphere.directions import Cubemap
from ...sphere.envmap import CubeLighting
from ...scene.visibility import unpack_visibility
from ...common.parallel import for_blocks, block_points, part


def diffuse_irradiance(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap,
                       lighting: CubeLighting, tick=None, seen=None) -> np.ndarray:
    """E(x) = sum_k L_k V_k max(0, n.w_k) dw_k per point, (P, 3) float32.

    ``w_k`` is the lighting's mean direction vector in texel k, so the cosine is
    the texel's mean cosine (exact for texels above the horizon).  ``seen``: (P,) bool,
    the points summed (core.scene.mesh.seen_points), the others 0 (None: all).
    """
    if seen is not None:
        rows = np.flatnonzero(seen)
        out = np.zeros((len(seen), 3), dtype=np.float32)
        out[rows] = diffuse_irradiance(np.asarray(vis_bits)[rows], np.asarray(normals)[rows],
                                       cube, lighting, tick)
        return out
    normals = np.asarray(normals, dtype=np.float32)
    dirs = np.asarray(lighting.directions, dtype=np.float32)
    # L dw folded together; the bits multiply as 0/1 bytes (no bool or float copy)
    Ldw = (np.asarray(lighting.radiance, dtype=np.float64)
           * cube.solid_angles[:, None]).astype(np.float32)
    out = np.zeros((len(normals), 3), dtype=np.float32)
    block = block_points(cube.resolution)
    bits = np.asarray(vis_bits, dtype=np.uint8)

    def block_irradiance(a, b):
        cos = normals[a:b] @ dirs.T
        np.maximum(cos, 0.0, out=cos)
        np.multiply(cos, np.unpackbits(bits[a:b], axis=1, count=cube.size), out=cos)
        out[a:b] = cos @ Ldw

    for_blocks(len(normals), block, block_irradiance, tick)
    return out


def sky_visibility(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap) -> np.ndarray:
    """Cosine-weighted open fraction of each point's hemisphere, (P,) in [0, 1]."""
    normals = np.asarray(normals, dtype=np.float32)
    dirs = cube.directions.astype(np.float32)
    dw = cube.solid_angles.astype(np.float32)
    out = np.zeros(len(normals), dtype=np.float32)
    block = block_points(cube.resolution)

    def block_sky(a, b):
        w = normals[a:b] @ dirs.T
        np.maximum(w, 0.0, out=w)
        w *= dw
        total = w.sum(axis=1)
        np.multiply(w, np.unpackbits(np.asarray(vis_bits[a:b], np.uint8), axis=1,
                                     count=cube.size), out=w)
        out[a:b] = w.sum(axis=1) / np.maximum(total, 1e-12)

    for_blocks(len(normals), block, block_sky)
    return out


def bent_normals(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap) -> np.ndarray:
    """Each point's bent normal, (P, 3) unit: the cosine-weighted mean of its visible
    directions (the way the open sky lies); its normal where nothing is visible."""
    normals = np.asarray(normals, dtype=np.float32)
    dirs = cube.directions.astype(np.float32)
    dw = cube.solid_angles.astype(np.float32)
    out = np.array(normals, dtype=np.float32, copy=True)
    block = block_points(cube.resolution)

    def block_bent(a, b):
        w = normals[a:b] @ dirs.T
        np.maximum(w, 0.0, out=w)
        w *= dw
        w *= np.unpackbits(np.asarray(vis_bits[a:b], np.uint8), axis=1, count=cube.size)
        mean = w @ dirs
        length = np.linalg.norm(mean, axis=1, keepdims=True)
        seen = length[:, 0] > 1e-12
        out[a:b][seen] = mean[seen] / length[seen]

    for_blocks(len(normals), block, block_bent)
    return out


#: an edge "jumps" when its endpoints' sky visibility differs by more than this
COARSE_JUMP = 0.25
#: a mesh is too coarse for its shadows when more than this share of its edges jump
COARSE_SHARE = 0.05


def coarse_edge_share(vis_bits: np.ndarray, normals: np.ndarray, point_of_corner: np.ndarray,
                      triangles: np.ndarray, cube: Cubemap, jump: float = COARSE_JUMP,
                      sky: np.ndarray | None = None) -> float:
    """Share of a mesh's edges (the three of every triangle) whose endpoints' sky
    visibility (:func:`sky_visibility` of their shading points; ``sky`` when already
    taken) differs by more than ``jump``: where shadows change faster than the
    tessellation can show, so per-vertex shading blurs or aliases them.  0 for a mesh
    without triangles."""
    tri_points = np.asarray(point_of_corner)[np.asarray(triangles)].reshape(-1, 3)
    if len(tri_points) == 0:
        return 0.0
    if sky is None:
        sky = sky_visibility(vis_bits, normals, cube)
    edges = np.concatenate([tri_points[:, [0, 1]], tri_points[:, [1, 2]], tri_points[:, [2, 0]]])
    return float((np.abs(sky[edges[:, 0]] - sky[edges[:, 1]]) > jump).mean())


def view_directions(positions, eye) -> np.ndarray:
    """Unit directions from each point toward the (perspective) eye, (P, 3) float64."""
    v = np.asarray(eye, dtype=np.float64)[None, :] - np.asarray(positions, dtype=np.float64)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-30)


def point_views(positions, eye=None, view_dir=None) -> np.ndarray:
    """Unit directions toward the viewer, (P, 3) float64: the orthographic camera's
    ``view_dir`` at every point when given, else toward the perspective ``eye``."""
    if view_dir is not None:
        return np.broadcast_to(np.asarray(view_dir, np.float64), (len(positions), 3))
    return view_directions(positions, eye)


def specular_radiance(vis_bits: np.ndarray, positions: np.ndarray, normals: np.ndarray,
                      eye, cube: Cubemap, lighting: CubeLighting, material: Material,
                      view_dirs: np.ndarray | None = None, tick=None) -> np.ndarray:
    """Glossy part of B toward the eye, (P, 3) float32.

    ``eye`` is the camera position (perspective) or, with ``view_dirs`` given,
    ignored in favour of per-point unit directions toward the viewer.  Fresnel,
    layer weights and multiscatter compensation come from
    :func:`~.brdf.specular_terms` (separable terms: one matrix product each).
    """
    P = len(normals)
    out = np.zeros((P, 3), dtype=np.float32)
    if material.is_diffuse_only or P == 0:
        return out
    if view_dirs is None:
        view_dirs = view_directions(positions, eye)
    dirs = lighting.unit_directions
    dw = cube.solid_angles.astype(np.float32)
    L = np.asarray(lighting.radiance, dtype=np.float32)
    block = block_points(cube.resolution)
    scalar = material.fresnel == "NONE" and material.distribution != "MULTI_GGX"

    def block_radiance(a, b):
        vis = unpack_visibility(vis_bits[a:b], cube.size)
        # Only texels some point of the block sees carry light (bits below each
        # point's horizon are 0): on flat or open regions that is half the sphere.
        cols = np.nonzero(vis.any(axis=0))[0]
        visdw = vis[:, cols] * dw[cols]
        d, Lc = dirs[cols], L[cols]
        if scalar:            # scalar lobe; colour applied after the sum
            f = np.asarray(specular_cosine(material, normals[a:b], view_dirs[a:b], d),
                           dtype=np.float32)
            f *= visdw
            out[a:b] = (f @ Lc) * np.asarray(material.specular_color, dtype=np.float32)
            return
        for lobe, weight in specular_terms(material, normals[a:b], view_dirs[a:b], d):
            # not in place: terms may share one array (a part-metal Principled's metal and
            # dielectric lobes both start with the bare lobe)
            out[a:b] += ((lobe * visdw) @ Lc) * weight

    for_blocks(P, block, block_radiance, tick)
    return out


def lambert_layer(material: Material, irradiance: np.ndarray, normals: np.ndarray,
                  view_dirs: np.ndarray | None) -> np.ndarray:
    """Radiance of the Lambert base: ``irradiance * albedo/pi``, times the view-dependent
    weight left by a dielectric layer above it (Principled BSDF)."""
    out = irradiance * (np.asarray(material.diffuse_albedo, dtype=np.float32) / np.float32(np.pi))
    if material.fresnel == "DIELECTRIC":
        out = out * diffuse_view_weight(material, normals, view_dirs)
    return out


def shade_points(vis_bits, positions, normals, materials, material_table, eye, cube, lighting,
                 irradiance=None, view_dirs=None, tick=None, glossy=True) -> np.ndarray:
    """Outgoing radiance (P, 3) of every point, each with its slot's material
    (``materials[p]`` in ``material_table``, :func:`.brdf.slot_material`).

    ``irradiance`` (from :func:`diffuse_irradiance`) may be passed in when cached.
    The diffuse part is ``irradiance * albedo / pi * diffuse_view_weight(n, v)``
    (the view weight is 1 except for Principled layering, where it needs the
    per-point view ``v``: toward ``eye``, or ``view_dirs``).  ``tick(fraction)``:
    progress, called between blocks of points (it may raise to stop).  ``glossy`` False: the
    diffuse part only (a caller that sums the glossy part elsewhere, e.g. on the GPU).
    """
    if irradiance is None:
        irradiance = diffuse_irradiance(vis_bits, normals, cube, lighting, part(tick, 0, 0.5))
        tick = part(tick, 0.5, 1.0)
    out = np.zeros((len(normals), 3), dtype=np.float32)
    materials = np.asarray(materials)
    done, total = 0, max(len(materials), 1)
    for slot in np.unique(materials):
        sel = np.nonzero(materials == slot)[0]
        mat = slot_material(material_table, slot)
        needs_view = mat.fresnel == "DIELECTRIC" or not mat.is_diffuse_only
        vd = None
        if needs_view:
            vd = view_directions(positions[sel], eye) if view_dirs is None else view_dirs[sel]
        out[sel] = lambert_layer(mat, irradiance[sel], normals[sel], vd)
        if glossy and not mat.is_diffuse_only:
            out[sel] += specular_radiance(vis_bits[sel], positions[sel], normals[sel], eye, cube,
                                          lighting, mat, view_dirs=vd,
                                          tick=part(tick, done / total,
                                                    (done + len(sel)) / total))
        done += len(sel)
        if tick is not None:
            tick(done / total)
    return out
