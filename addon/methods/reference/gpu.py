"""REFERENCE's sums per shading point on the GPU (shaders/methods/reference_sums_frag.glsl):
the glossy sum of core.methods.reference.shading.specular_radiance, one texel per point, every
material of an object (a textured slot's variants too) in one pass, and the diffuse sum of
its diffuse_irradiance (IRRADIANCE).  The CPU prepares what is
per point and cheap (the view bent above the horizon, each lobe's weight with Cycles'
multiscatter factor at the point's cos_o); the GPU does the points × visible texels."""

from __future__ import annotations

import hashlib

import numpy as np

from ....core.shading import brdf as core_brdf, microfacet
from ....core.shading.materials import slot_material
from ...frame import keys
from ...gpu import drawing, shaders, visibility

#: points per row of the pass's target (and of its point data)
WIDTH = 1024
#: texels per row of the environment's data (a power of two: the pass indexes it by mask and shift)
ENV_WIDTH = 1024
#: the side of the square blocks of pixels the pass's points fill in order (tiled_pixels)
TILE = 4
#: rows of points per draw (65536 points; whole blocks): a draw a GPU driver would reset (about 2 s on
#: Windows) needs millions of points at 6×128²
CHUNK_ROWS = 64
# the newest sums per (object, bits, lighting, what the pass reads of the points): a textured
# slot's frame shades its objects three times (its colour, white, black), and where the
# colour does not reach the glossy lobes (no metal) the three passes are one
_SUMS = keys.cache(8)


def _texture(values: np.ndarray):
    return drawing.float_texture(np.ascontiguousarray(values, dtype=np.float32))


def material_rows(materials: list, count: int) -> np.ndarray:
    """(count, 8, 4) float32: per material index its alpha, distribution and glossy lobes
    (core.shading.brdf.sharp_lobes; none for a diffuse-only one), the layout of matData."""
    out = np.zeros((max(count, 1), 8, 4), np.float32)
    for m in range(count):
        mat = slot_material(materials, m)
        if mat.is_diffuse_only:
            continue
        lobes = core_brdf.sharp_lobes(mat)
        out[m, 0] = (mat.alpha, 0.0 if mat.lobe_distribution == "BECKMANN" else 1.0,
                     len(lobes), 0.0)
        for j, (kind, _weight, f0, B, eta) in enumerate(lobes[:2]):
            out[m, 1 + 3 * j] = (kind, eta, 0.0, 0.0)
            out[m, 2 + 3 * j, :3] = f0
            out[m, 3 + 3 * j, :3] = B
    return out


def point_rows(normals, views, point_materials, materials, index=None) -> np.ndarray:
    """(4, P, 4) float32: per point [normal, material], [view bent above the horizon
    (core.shading.brdf.bend_views), cos_o], each glossy lobe's weight times its
    multiscatter factor (the weights core.shading.brdf.specular_terms gives its terms), and
    in the first lobe's row the point's ``index`` into the visibility bits (default: its
    row)."""
    n = core_brdf.unit_rows(normals, "normals")
    v, cos_o = core_brdf.bend_views(n, core_brdf.unit_rows(views, "views"))
    P = len(n)
    out = np.zeros((4, P, 4), np.float32)
    out[0, :, :3] = n
    out[0, :, 3] = point_materials
    out[1, :, :3] = v
    out[1, :, 3] = cos_o
    out[2, :, 3] = np.arange(P) if index is None else index
    for m in np.unique(point_materials):
        mat = slot_material(materials, m)
        if mat.is_diffuse_only:
            continue
        sel = np.nonzero(point_materials == m)[0]
        for j, (kind, weight, *_rest) in enumerate(core_brdf.sharp_lobes(mat)[:2]):
            which = "metal" if (mat.fresnel == "DIELECTRIC" and kind == core_brdf.SHARP_F82) \
                else "main"
            out[2 + j, sel, :3] = weight * core_brdf.multiscatter_factor(mat, cos_o[sel], which)
    return out


def environment_rows(cube, lighting) -> tuple[np.ndarray, int]:
    """(3 rows, ENV_WIDTH, 4) blocks of float32: each cubemap texel's unit direction, its
    radiance times its solid angle (the sums' L_k dw_k), its mean direction vector (the
    irradiance's mean cosine); and the rows of a block."""
    N = cube.size
    rows = -(-N // ENV_WIDTH)
    out = np.zeros((3, rows * ENV_WIDTH, 4), np.float32)
    out[0, :N, :3] = lighting.unit_directions
    out[1, :N, :3] = np.asarray(lighting.radiance, np.float64) * cube.solid_angles[:, None]
    out[2, :N, :3] = lighting.directions
    return out.reshape(3 * rows, ENV_WIDTH, 4), rows


def tiled_pixels(count: int, width: int) -> tuple[np.ndarray, int]:
    """Where the pass draws each of ``count`` points: (count,) indices into its target's
    pixels (rows of ``width``), and its rows (a multiple of TILE).  Points ``16 b .. 16 b + 15``
    fill the b-th TILE x TILE block, row by row (reference_sums_frag.glsl's point_of): a GPU
    shades a block's pixels together (a warp; llvmpipe a 4x4 block of SIMD lanes), so
    neighbouring points, which see much the same texels, run the loop over them in step."""
    rows = -(-max(count, 1) // width)
    rows = -(-rows // TILE) * TILE
    k = np.arange(count)
    block, within = k // (TILE * TILE), k % (TILE * TILE)
    per_row = width // TILE
    x = (block % per_row) * TILE + within % TILE
    y = (block // per_row) * TILE + within // TILE
    return y * width + x, rows


def _pass(st, pts, cube, lighting, mats=None):
    """The pass over an object's points (``pts``: its point data, (blocks, P, 4) in point
    order): the glossy sums (P, 3) with the material rows ``mats``, the irradiance without."""
    P = pts.shape[1]
    pix, rows = tiled_pixels(P, WIDTH)
    data = np.zeros((len(pts), rows * WIDTH, 4), np.float32)
    data[:, pix] = pts
    vis_tex, stride = visibility.texture(st)
    env, env_rows = environment_rows(cube, lighting)
    # the textures stay referenced until the pass has read them; the irradiance variant
    # reads neither the material rows nor the point data past its normals
    textures = (("pointData", _texture(data.reshape(-1, WIDTH, 4))), ("visTex", vis_tex),
                ("envData", _texture(env)))
    ints = (("width", WIDTH), ("pointCount", P), ("stride", stride), ("envWidth", ENV_WIDTH),
            ("envRows", env_rows))
    if mats is not None:
        textures += (("matData", _texture(mats)),)
        ints += (("rows", rows),)
    shader = shaders.shader("reference_sums", ("IRRADIANCE",) if mats is None else
                            microfacet.lobe_signature(
                                mats[m, 0, 1:3].tolist() + [mats[m, 1, 0], mats[m, 4, 0]]
                                for m in np.unique(pts[0, :, 3].astype(np.int64))))
    chunk = max(TILE, CHUNK_ROWS - CHUNK_ROWS % TILE)     # whole blocks per draw
    out = np.concatenate([
        drawing.texel_pass(shader, WIDTH, min(rows - first, chunk),
                           ints=ints + (("firstRow", first),), samplers=textures)
        for first in range(0, rows, chunk)])
    return out[pix, :3]


def irradiance(st, normals, cube, lighting) -> np.ndarray:
    """E(x) (P, 3) float32 of an object's points (``st.bits`` their visibility), by the pass."""
    P = len(normals)
    if P == 0:
        return np.zeros((0, 3), np.float32)
    pts = np.zeros((1, P, 4), np.float32)
    pts[0, :, :3] = normals
    return _pass(st, pts, cube, lighting)


def specular_radiance(st, normals, point_materials, materials, cube, lighting, views,
                      lighting_key, seen=None) -> np.ndarray:
    """Glossy radiance (P, 3) float32 of an object's points toward ``views`` (P, 3), by the
    GPU pass: ``st`` holds the visibility bits (``st.bits``, its texture cached per bits);
    ``lighting_key``: what identifies ``lighting`` (addon.frame.keys.env_key); ``seen``:
    (P,) bool, the points summed (core.scene.mesh.seen_points), the others 0 (None: all)."""
    P = len(normals)
    index = np.arange(P) if seen is None else np.flatnonzero(seen)
    out = np.zeros((P, 3), np.float32)
    S = len(index)
    if S == 0:
        return out
    pts = point_rows(normals[index], views[index], point_materials[index], materials, index)
    mats = material_rows(materials, int(np.max(point_materials)) + 1)
    digest = hashlib.blake2b(pts.tobytes() + mats.tobytes(), digest_size=16).digest()

    def run():
        return _pass(st, pts, cube, lighting, mats)
    out[index] = keys.per_visibility(_SUMS, (st.name, id(st.bits), lighting_key, digest),
                                     st.bits, run)
    return out
