"""The test oracle of BLOCKS: Algorithm 1 of Inger et al. 2013 for one vertex, as
readably as it can be stated (the per-block lighting of §4.3, ProjectBRDF of §4.1 with
its sample-based selection rule, the four cases).  ``core/methods/blocks/shading.py`` evaluates the same
cases batched over many vertices; tests hold the two to each other.

Selection rule of this per-vertex path (:func:`project_brdf`, used by
:func:`integrate_vertex` for any sampled BRDF; generic and data driven -- the batched
frame path uses the analytic Appendix-A-style rule ``core.methods.blocks.lobe.glossy_levels``
instead, which needs no extra samples): the BRDF x cos is also sampled on a 5 x 5
*check grid* (pixels 0, 4, 8, 12, 15 in each direction: corners, edges and centre,
where a horizon kink or a lobe shows first).  The chosen representation is the
smallest ``l`` in (1, 2, 4) whose reconstruction matches every check sample (every
colour channel) within ``rel_tol * max|samples of the block| + abs_tol``; if none does,
the block is sampled at all 256 pixels (pixel basis).  Like any sample-based test it
can miss a lobe narrower than the check spacing (4 pixels); the analytic half of
Appendix A ("increase the sampling rate in the vicinity of a highlight") is available
as ``force_pixel=highlight_blocks(mirror_dirs, N, angle)``.  ``abs_tol`` defaults to
``abs_rel_tol`` (1e-3) times the largest sample of the whole vertex, so blocks that
contribute negligibly are not refined.  As in the paper the decision depends on how
smooth the BRDF is within the block, not on its magnitude (except through that
absolute floor).  Blocks whose visibility is constant 0 are never sampled (Alg. 1
line 1 comes before line 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from prt_relight.core.methods.blocks.shading import CASE_LIGHT_BRDF, CASE_LIGHT_VIS, CASE_NAMES, CASE_TRIPLE
from prt_relight.core.methods.blocks.encoding import BLOCK_PIXELS, BRDF_LEVELS, CHECK_PIXELS, MIXED, ONE, PIXEL, ZERO, DiffVisibility, block_count, block_permutation, dct_basis, projection_system, texel_to_block, to_blocks
from prt_relight.core.shading.brdf import reflectance_cosine
from prt_relight.core.sphere.directions import cubemap


# --------------------------------------------------------------------------- lighting

@dataclass(frozen=True)
class BlockLighting:
    """The three per-block representations of §4.3 (float64).

    ``pixel`` (blocks, 256, 3): ``L_k dw_k`` with the block rows concatenated;
    ``integral`` (blocks, 256, 3): eq. 6, ``D^{-T}`` of ``pixel`` (suffix sums);
    ``dct`` (blocks, 16, 3): coefficients on :func:`dct_basis` (order :data:`DCT_ORDER`).
    """

    resolution: int
    pixel: np.ndarray
    integral: np.ndarray
    dct: np.ndarray

    @property
    def blocks(self) -> int:
        return self.pixel.shape[0]


def block_lighting(radiance, resolution: int) -> BlockLighting:
    """Per-block lighting from cubemap radiance (D, 3) (or a ``CubeLighting``)."""
    rad = getattr(radiance, "radiance", radiance)
    rad = np.asarray(rad, dtype=np.float64)
    if rad.ndim == 1:
        rad = rad[:, None]
    cube = cubemap(int(resolution))
    if rad.shape[0] != cube.size:
        raise ValueError("radiance does not match the cubemap resolution")
    pix = to_blocks(rad * cube.solid_angles[:, None], resolution)            # (nb, 256, C)
    integral = np.cumsum(pix[:, ::-1], axis=1)[:, ::-1]                      # suffix sums
    dct = np.einsum("kp,bpc->bkc", dct_basis(), pix)
    for a in (pix, integral, dct):
        a.setflags(write=False)
    return BlockLighting(int(resolution), pix, np.ascontiguousarray(integral), dct)


def _sparse_dot(table: np.ndarray, dv: DiffVisibility, rows: np.ndarray) -> np.ndarray:
    """sum_k table[r, idx_k] V_d[idx_k] / levels over the stored entries of blocks ``rows``
    of a one-vertex ``dv``; ``table`` is (len(rows), 256, C).  -> (len(rows), C)."""
    nb = dv.blocks
    where = np.full(nb, -1, dtype=np.int64)
    where[rows] = np.arange(rows.size)
    blk = dv.entry_blocks()
    r = where[blk]
    sel = r >= 0
    r = r[sel]
    w = dv.entry_values()[sel].astype(np.float64) / dv.levels
    contrib = table[r, dv.indices[sel].astype(np.int64)] * w[:, None]
    out = np.zeros((rows.size, table.shape[2]))
    for c in range(table.shape[2]):
        out[:, c] = np.bincount(r, weights=contrib[:, c], minlength=rows.size)
    return out


def light_vis_product(light: BlockLighting, dv: DiffVisibility) -> np.ndarray:
    """Alg. 1 line 9 without the BRDF: ``L_int . V_d`` per block of a one-vertex ``dv``,
    (blocks, 3) = sum_k L_k V_k dw_k over the block."""
    kind = dv.kind[0]
    out = np.zeros((light.blocks, light.pixel.shape[2]))
    one = kind == ONE
    out[one] = light.integral[one, 0]
    mixed = np.nonzero(kind == MIXED)[0]
    out[mixed] = _sparse_dot(light.integral[mixed], dv, mixed)
    return out


# --------------------------------------------------------------------------- BRDF

def as_sampler(rho):
    """A BRDF x cos sampler ``f(flat texel indices) -> (k, C)``; arrays (D, C) are indexed."""
    if callable(rho):
        return rho
    arr = np.asarray(rho, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    return lambda texels: arr[texels]


def material_sampler(material, normal, view, resolution: int, directions=None):
    """Sampler of :func:`core.shading.brdf.reflectance_cosine` for one vertex at the texel
    directions (texel centres unless ``directions`` (D, 3) is given)."""
    dirs = cubemap(int(resolution)).directions if directions is None else np.asarray(directions)
    n = np.asarray(normal, dtype=np.float64).reshape(1, 3)
    v = np.asarray(view, dtype=np.float64).reshape(1, 3)

    def f(texels):
        return reflectance_cosine(material, n, v, dirs[np.asarray(texels).reshape(-1)])[0].astype(np.float64)
    return f


def highlight_blocks(directions, resolution: int, angle: float = 0.0) -> np.ndarray:
    """(blocks,) bool: blocks holding the texel of any of ``directions`` (k, 3) or a
    texel centre within ``angle`` radians of one -- the "vicinity of a highlight"
    (e.g. the mirror direction of the view) whose sampling §4.1 / Appendix A raise.
    Pass it as ``force_pixel`` so narrow lobes between the check samples are not missed."""
    d = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
    n = int(resolution)
    mask = np.zeros(block_count(n), dtype=bool)
    mask[texel_to_block(cubemap(n).texel_index(d), n)[0]] = True
    if angle > 0.0:
        cosines = to_blocks(cubemap(n).directions, n) @ d.T          # (nb, 256, k)
        mask |= (cosines >= np.cos(angle)).any(axis=(1, 2))
    return mask


def project_brdf(rho, blocks: np.ndarray, resolution: int, mode="adaptive",
                 rel_tol: float = 0.02, abs_tol: float | None = None, abs_rel_tol: float = 1e-3,
                 force_pixel=None):
    """ProjectBRDF (Alg. 1 line 4) for ``blocks`` -> (levels (m,), coeffs (m, 16, C), pixels).

    ``levels[i]`` is 1, 4, 16 or 256 (:data:`BRDF_LEVELS`); ``coeffs[i, :levels]``
    are the DCT coefficients when ``levels < 256``; ``pixels`` (m, 256, C) holds the
    full samples of pixel-basis blocks (zeros elsewhere).  ``mode``: "adaptive"
    (the rule of the module docstring), "pixel" (every block 256 samples) or a
    fixed 1 / 4 / 16.  ``force_pixel`` (blocks,) bool (see :func:`highlight_blocks`)
    sends those blocks to the pixel basis in adaptive mode."""
    f = as_sampler(rho)
    blocks = np.asarray(blocks, dtype=np.int64)
    m = blocks.size
    perm = block_permutation(resolution)

    def sample(pix):                       # (m, k) block pixel idx -> (m, k, C)
        t = perm[blocks[:, None], pix[None, :] if pix.ndim == 1 else pix].reshape(-1)
        s = np.asarray(f(t), dtype=np.float64)
        return s.reshape(m, -1, s.shape[-1] if s.ndim > 1 else 1)

    if m == 0:
        C = np.asarray(f(np.zeros(1, dtype=np.int64))).reshape(1, -1).shape[1]
        return np.zeros(0, np.int64), np.zeros((0, 16, C)), np.zeros((0, BLOCK_PIXELS, C))
    if mode == "pixel" or mode == PIXEL:
        px = sample(np.arange(BLOCK_PIXELS))
        C = px.shape[2]
        return np.full(m, PIXEL, dtype=np.int64), np.zeros((m, 16, C)), px
    fixed = {1: 1, 4: 2, 16: 4}
    if mode != "adaptive" and mode not in fixed:
        raise ValueError("mode must be 'adaptive', 'pixel', 1, 4 or 16")
    ls = (1, 2, 4) if mode == "adaptive" else (fixed[mode],)
    fits = {}
    for l in ls:
        pix, inv = projection_system(l)
        fits[l] = np.einsum("ij,mjc->mic", inv, sample(pix))        # (m, l*l, C)
    C = next(iter(fits.values())).shape[2]
    coeffs = np.zeros((m, 16, C))
    levels = np.full(m, PIXEL, dtype=np.int64)
    if mode != "adaptive":
        l = ls[0]
        coeffs[:, :l * l] = fits[l]
        levels[:] = l * l
        return levels, coeffs, np.zeros((m, BLOCK_PIXELS, C))
    check = sample(CHECK_PIXELS)                                      # (m, 25, C)
    scale = np.abs(check).max(axis=(1, 2))
    if abs_tol is None:
        abs_tol = abs_rel_tol * float(scale.max())
    thresh = rel_tol * scale + abs_tol
    undecided = np.ones(m, dtype=bool)
    phi_check = dct_basis()[:, CHECK_PIXELS]                          # (16, 25)
    for l in ls:
        k = l * l
        recon = np.einsum("mkc,kp->mpc", fits[l], phi_check[:k])
        ok = undecided & (np.abs(recon - check).max(axis=(1, 2)) <= thresh)
        coeffs[ok, :k] = fits[l][ok]
        levels[ok] = k
        undecided &= ~ok
    if force_pixel is not None:
        forced = np.asarray(force_pixel, dtype=bool)[blocks]
        coeffs[forced] = 0.0
        levels[forced] = PIXEL
        undecided |= forced
    pixels = np.zeros((m, BLOCK_PIXELS, C))
    rest = np.nonzero(undecided)[0]
    if rest.size:
        t = perm[blocks[rest]].reshape(-1)
        s = np.asarray(f(t), dtype=np.float64)
        pixels[rest] = s.reshape(rest.size, BLOCK_PIXELS, -1)
    return levels, coeffs, pixels


# --------------------------------------------------------------------------- Algorithm 1

@dataclass
class BlockIntegral:
    """Result of :func:`integrate_vertex`: ``radiance`` (C,), per block ``values``
    (blocks, C), ``cases`` (blocks,) int8 (CASE_*), ``levels`` (blocks,) BRDF
    coefficients used (0 where never sampled)."""

    radiance: np.ndarray
    values: np.ndarray
    cases: np.ndarray
    levels: np.ndarray

    def case_counts(self) -> dict:
        return {name: int((self.cases == i).sum()) for i, name in enumerate(CASE_NAMES)}

    def level_counts(self) -> dict:
        return {lv: int((self.levels == lv).sum()) for lv in BRDF_LEVELS}


def integrate_blocks(dv: DiffVisibility, light: BlockLighting, rho, mode="adaptive",
                     rel_tol: float = 0.02, abs_tol: float | None = None,
                     abs_rel_tol: float = 1e-3, force_pixel=None):
    """Algorithm 1 for every block of one vertex (``dv`` with count 1), vectorized.

    ``rho``: BRDF x cos per flat texel, an array (D, C) or a sampler (:func:`as_sampler`).
    Returns (values (blocks, C), cases (blocks,), levels (blocks,))."""
    if dv.count != 1:
        raise ValueError("integrate_blocks takes one vertex (use dv.vertex(p))")
    if dv.resolution != light.resolution:
        raise ValueError("visibility and lighting resolutions differ")
    kind = dv.kind[0]
    nb = light.blocks
    C = light.pixel.shape[2]
    values = np.zeros((nb, C))
    cases = np.zeros(nb, dtype=np.int8)
    levels_all = np.zeros(nb, dtype=np.int64)
    active = np.nonzero(kind != ZERO)[0]                       # line 1
    if active.size == 0:
        return values, cases, levels_all
    levels, coeffs, pixels = project_brdf(rho, active, light.resolution, mode, rel_tol,
                                          abs_tol, abs_rel_tol, force_pixel)   # line 4
    if coeffs.shape[2] != C:
        if coeffs.shape[2] == 1:
            coeffs, pixels = (np.repeat(coeffs, C, axis=2), np.repeat(pixels, C, axis=2))
        else:
            raise ValueError("BRDF and lighting channel counts differ")
    levels_all[active] = levels
    one = kind[active] == ONE
    band = levels < PIXEL
    # line 6: Light-BRDF product, DCT (same orthonormal basis) or pixel basis.
    s = one & band
    if s.any():
        b = active[s]
        values[b] = np.einsum("mkc,mkc->mc", coeffs[s] * (np.arange(16) < levels[s][:, None])[:, :, None],
                              light.dct[b])
    s = one & ~band
    if s.any():
        b = active[s]
        values[b] = np.einsum("mpc,mpc->mc", pixels[s], light.pixel[b])
    cases[active[one]] = CASE_LIGHT_BRDF
    # line 9: constant BRDF: rho_1 * (L_int . V_d).
    s = ~one & (levels == 1)
    if s.any():
        b = active[s]
        rho1 = coeffs[s, 0] * dct_basis()[0, 0]                      # A_00 / 16
        values[b] = rho1 * _sparse_dot(light.integral[b], dv, b)
        cases[b] = CASE_LIGHT_VIS
    # line 11: decompress-integrate in the pixel basis.
    s = ~one & (levels > 1)
    if s.any():
        b = active[s]
        rpix = np.where((levels[s] == PIXEL)[:, None, None], pixels[s],
                        np.einsum("mkc,kp->mpc", coeffs[s], dct_basis()))
        prod = light.pixel[b] * rpix
        values[b] = _sparse_dot(np.cumsum(prod[:, ::-1], axis=1)[:, ::-1], dv, b)
        cases[b] = CASE_TRIPLE
    return values, cases, levels_all


def integrate_vertex(dv: DiffVisibility, light: BlockLighting, rho, mode="adaptive",
                     rel_tol: float = 0.02, abs_tol: float | None = None,
                     abs_rel_tol: float = 1e-3, force_pixel=None) -> BlockIntegral:
    """B = sum over blocks of Algorithm 1 for one vertex (see :func:`integrate_blocks`)."""
    values, cases, levels = integrate_blocks(dv, light, rho, mode, rel_tol, abs_tol, abs_rel_tol,
                                             force_pixel)
    return BlockIntegral(values.sum(axis=0), values, cases, levels)
