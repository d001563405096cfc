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

from dataclasses import dataclass

import numpy as np

from ...shading.brdf import diffuse_view_weight, specular_cosine, specular_terms
from ...shading.materials import Material, slot_material
from ...sphere.directions import Cubemap
from ...sphere.envmap import CubeLighting
from ...scene.visibility import unpack_visibility
from ...common.parallel import for_blocks, block_points, part


#: the band of the :class:`HorizonPairs` at 6x32^2 (:func:`horizon_band`): a visible texel
#: whose centre's cosine to the point's normal is below it is listed (the horizon may cross
#: it); a texel whose light's mean direction lies farther from its centre than it allows is
#: checked at every point instead
HORIZON_BAND = 0.02


def horizon_band(cube: Cubemap) -> float:
    """The pairs' band at ``cube``'s resolution: :data:`HORIZON_BAND` scaled with the
    texels' size (a light's offset within its texel shrinks with it; a fixed band would
    list about as many pairs as a fine cubemap has bits)."""
    return HORIZON_BAND * 32.0 / cube.resolution


@dataclass(frozen=True)
class HorizonPairs:
    """The (point, texel) pairs of visible texels near or below the point's horizon,
    ``n . c_k <`` :func:`horizon_band` (``c_k`` the texel's centre): the only texels whose
    light's mean direction can lie below the horizon, where the clamp of the cosine matters
    (:func:`diffuse_irradiance`).  They depend on the visibility and the normals, not the
    lighting: callers cache them per visibility.  Compact (4 B a pair at 6x32^2 and
    6x64^2): point p's pairs are ``starts[p]:starts[p + 1]``, each cosine rounded down to
    float16 (a pair it lets through is checked exactly)."""

    starts: np.ndarray      # (P + 1,) int64
    texels: np.ndarray      # (M,) uint16 (uint32 past 65536 texels)
    cosines: np.ndarray     # (M,) float16, at most n . c_k

    @property
    def nbytes(self) -> int:
        return self.starts.nbytes + self.texels.nbytes + self.cosines.nbytes

    def rows(self) -> np.ndarray:
        """(M,) each pair's point."""
        count = len(self.starts) - 1
        return np.repeat(np.arange(count, dtype=np.int32), np.diff(self.starts))


def _below(values: np.ndarray) -> np.ndarray:
    """``values`` as float16, each at most its float32 value."""
    half = values.astype(np.float16)
    up = half.astype(np.float32) > values
    half[up] = np.nextafter(half[up], np.float16(-np.inf))
    return half


def horizon_pairs(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap,
                  tick=None) -> HorizonPairs:
    """The :class:`HorizonPairs` of every point (rows of ``vis_bits``)."""
    normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
    centres = cube.directions.astype(np.float32)
    bits = np.asarray(vis_bits, dtype=np.uint8)
    band = horizon_band(cube)
    index = np.uint16 if cube.size <= 65536 else np.uint32
    spans = {}

    def block_pairs(a, b):
        nc = normals[a:b] @ centres.T
        # packed, so the visible texels among them are found a byte at a time
        near = np.packbits(nc < band, axis=1)
        near &= bits[a:b]
        r, byte = np.nonzero(near)
        r8, j = np.nonzero(np.unpackbits(near[r, byte][:, None], axis=1))
        r, k = r[r8], byte[r8].astype(np.int64) * 8 + j
        spans[a] = (np.bincount(r, minlength=b - a), k.astype(index), _below(nc[r, k]))

    for_blocks(len(normals), block_points(cube.resolution), block_pairs, tick)
    got = [spans[a] for a in sorted(spans)]
    if not got:
        return HorizonPairs(np.zeros(1, np.int64), np.zeros(0, index), np.zeros(0, np.float16))
    counts, texels, cosines = (np.concatenate(parts) for parts in zip(*got))
    return HorizonPairs(np.concatenate([[0], np.cumsum(counts)]).astype(np.int64), texels,
                        cosines)


def _light_offsets(cube: Cubemap, directions: np.ndarray) -> np.ndarray:
    """(D,) per texel the sine of the angle between its centre and its light's mean
    direction (2 past a right angle, or for a texel without a direction): a point whose
    cosine to the centre is at least this sees the light above its horizon."""
    length = np.linalg.norm(directions, axis=1)
    cos = np.einsum("kd,kd->k", directions, cube.directions) / np.maximum(length, 1e-30)
    off = np.sqrt(np.clip(1.0 - cos * cos, 0.0, 1.0)) + 1e-6
    off[(cos < 0.0) | (length == 0.0)] = 2.0
    return off.astype(np.float32)


def diffuse_irradiance(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap,
                       lighting: CubeLighting, tick=None, seen=None,
                       pairs: HorizonPairs | None = None) -> np.ndarray:
    """E(x) = sum_k L_k V_k max(0, n.w_k) dw_k per point, (P, 3) float32.

    ``w_k`` is the lighting's mean direction vector in texel k, so the cosine is
    the texel's mean cosine (exact for texels above the horizon).  ``seen``: (P,) bool,
    the points summed (core.scene.mesh.seen_points), the others 0 (None: all).

    Summed as ``n . sum_k V_k w_k L_k dw_k`` (the bits times one (6N², 9) matrix) plus
    ``-n.w_k L_k dw_k`` where that cosine is negative: only where the point's horizon
    passes within the texel's light offset of its centre (:func:`_light_offsets`), so
    among ``pairs`` (:func:`horizon_pairs` of every point, made here when not given), and
    for a texel whose light lies farther from its centre than the pairs' band, at every
    point.  The clamp is kept exactly; only the order of the sums differs.
    """
    normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
    bits = np.asarray(vis_bits, dtype=np.uint8)
    rows = np.arange(len(normals)) if seen is None else np.flatnonzero(seen)
    if pairs is None:
        pairs = horizon_pairs(bits[rows], normals[rows], cube)
        pair_rows = rows[pairs.rows()]
    else:
        pair_rows = pairs.rows()
    dirs = np.asarray(lighting.directions, dtype=np.float32)
    # L dw folded together
    Ldw = (np.asarray(lighting.radiance, dtype=np.float64)
           * cube.solid_angles[:, None]).astype(np.float32)
    moments = (dirs[:, :, None] * Ldw[:, None, :]).reshape(-1, 9)
    out = np.zeros((len(normals), 3), dtype=np.float32)
    block = block_points(cube.resolution)
    sub_normals = normals[rows]

    def block_irradiance(a, b):
        vis = np.unpackbits(bits[rows[a:b]], axis=1, count=cube.size).astype(np.float32)
        m = (vis @ moments).reshape(-1, 3, 3)
        out[rows[a:b]] = np.einsum("pd,pdc->pc", sub_normals[a:b], m)

    for_blocks(len(rows), block, block_irradiance, tick)
    lit = Ldw.any(axis=1)
    offsets = _light_offsets(cube, dirs)
    band = horizon_band(cube)
    covered = offsets <= band
    # the listed pairs whose texel's light may lie below the point's horizon
    off = offsets[pairs.texels]
    near = (pairs.cosines < off) & (off <= band)
    if seen is not None:
        near &= np.asarray(seen, bool)[pair_rows]
    r, k = pair_rows[near], pairs.texels[near]
    cos = np.einsum("pd,pd->p", normals[r], dirs[k])
    below = cos < 0.0
    r, k, cos = r[below], k[below], cos[below]
    for c in range(3):
        out[:, c] -= np.bincount(r, weights=cos * Ldw[k, c], minlength=len(out)).astype(np.float32)
    # texels whose light lies too far from their centre for the pairs: every point
    far = np.flatnonzero(~covered & lit)
    if len(far) and len(rows):
        byte, shift = far >> 3, (7 - (far & 7)).astype(np.uint8)
        for a in range(0, len(rows), 4096):
            sel = rows[a:a + 4096]
            hidden = ((bits[sel[:, None], byte] >> shift) & 1) == 0
            cos = sub_normals[a:a + 4096] @ dirs[far].T
            np.minimum(cos, 0.0, out=cos)
            cos[hidden] = 0.0
            out[sel] -= cos @ Ldw[far]
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
