"""WAVELET: Haar-wavelet relighting, the classic all-frequency baselines.

* Diffuse (Ng, Ramamoorthi, Hanrahan 2003, "non-linear wavelet lighting
  approximation"): the lighting is Haar-transformed on the cube
  faces and only its ``terms`` largest coefficients are kept; per point the
  transport ``T_k = V_k max(0, n.w_k) dw_k`` is stored in the Haar basis
  (sparse: its ``transfer_terms`` largest coefficients, as Ng 03 quantises and
  discards small transport coefficients), and the irradiance is the dot product
  of the two coefficient vectors over the kept lighting terms.
* Glossy (Ng et al. 2004 triple product, the comparison of Inger et al. 2013, §5): per
  point and view the BRDF x cosine x solid angle ``rho~`` is transformed and
  truncated to a kept fraction (1 % by default), the lighting likewise, the
  visibility is kept exactly; the integral is the Haar *triple product* ``sum
  C_ijk L_i V_j rho_k`` evaluated with the tripling-coefficient structure of
  :mod:`.haar` (scaling terms, identical-wavelet pairs times the third
  function's parent accumulation, sibling triples), vectorised over points.

Both sums equal the pixel-basis REFERENCE when nothing is truncated (Parseval
and the tripling theorem); the truncation is the method's only error (plus the
cube-mean cosine used in the stored diffuse transport, which REFERENCE takes
per lighting).  Colour: one index set for the three lighting channels, ranked by
the channels' summed magnitude, optionally weighted by support area (Ng 03's
area-weighted selection).
"""

from __future__ import annotations

import numpy as np

from . import haar
from ...shading.brdf import specular_terms
from ...shading.materials import Material
from ...sphere.directions import Cubemap
from ...sphere.envmap import CubeLighting
from ...common.parallel import for_blocks, block_points
from ...scene.visibility import unpack_visibility

#: points per vectorised block (each holds a few (block, 6*N*N) float arrays)
BLOCK_POINTS = 128


class LightingApproximation:
    """The lighting's ``terms`` largest Haar coefficients (RGB share one index set).

    ``indices`` (k,) ascending, ``values`` (k, 3); ``dense`` (S, 3) truncated
    coefficient vector; ``parents`` (S, 3) its parent accumulations (Ng 04's
    per-lighting table, used by the triple product); ``pixels`` (S, 3) the
    approximated radiance per texel (inverse transform) and ``relative_error``
    its L2 error relative to the full lighting (Parseval: over coefficients).
    """

    def __init__(self, radiance: np.ndarray, terms: int, area_weighted: bool = False):
        L = np.asarray(radiance, dtype=np.float64)
        if L.ndim != 2 or L.shape[1] != 3:
            raise ValueError("radiance must be (6*N*N, 3)")
        if not np.isfinite(L).all():
            raise ValueError("lighting has non-finite texels")
        size = L.shape[0]
        self.n = haar.resolution_of_size(size)
        coeffs = haar.cube_forward(L.T).T                       # (S, 3)
        score = np.abs(coeffs).sum(axis=1)
        weights = haar.support_areas(self.n) if area_weighted else None
        self.terms = int(min(max(int(terms), 1), size))
        idx, _ = haar.nonlinear_approximation(score, self.terms, weights=weights)
        self.indices = idx
        self.values = coeffs[idx]
        self.dense = np.zeros_like(coeffs)
        self.dense[idx] = self.values
        total = float(np.sum(coeffs * coeffs))
        kept = float(np.sum(self.values * self.values))
        self.relative_error = float(np.sqrt(max(total - kept, 0.0) / total)) if total > 0 else 0.0
        self.parents = np.stack([haar.HaarFunction(self.dense[:, c], self.n,
                                                   parent_table=True).parents
                                 for c in range(3)], axis=1)
        self._pixels = None

    @property
    def pixels(self) -> np.ndarray:
        if self._pixels is None:
            self._pixels = haar.cube_inverse(self.dense.T).T
        return self._pixels


# ---------------------------------------------------------------------------
# Diffuse: Ng 03 double product


class SparseTransfer:
    """Per-point transport in the Haar basis, the ``terms`` largest coefficients each:
    ``indices`` (P, m) int32 and ``values`` (P, m) float32."""

    __slots__ = ("indices", "values", "n")

    def __init__(self, indices, values, n):
        self.indices, self.values, self.n = indices, values, n

    @property
    def nbytes(self) -> int:
        return self.indices.nbytes + self.values.nbytes


def diffuse_transfer(vis_bits: np.ndarray, normals: np.ndarray, cube: Cubemap,
                     terms: int, tick=None) -> SparseTransfer:
    """``T_k = V_k max(0, n.w_k) dw_k`` per point (``w_k`` the texel's mean direction),
    Haar-transformed and truncated to its ``terms`` largest coefficients (``tick``:
    progress between blocks)."""
    normals = np.asarray(normals, dtype=np.float32)
    P, S = len(normals), cube.size
    m = int(min(max(int(terms), 1), S))
    idx_out = np.zeros((P, m), dtype=np.int32)
    val_out = np.zeros((P, m), dtype=np.float32)
    dirs = cube.directions.astype(np.float32)
    dw = cube.solid_angles.astype(np.float32)

    def block(a, b):
        t = normals[a:b] @ dirs.T
        np.maximum(t, 0.0, out=t)
        t *= unpack_visibility(vis_bits[a:b], S)
        t *= dw
        idx, vals = haar.nonlinear_approximation(haar.cube_forward(t, np.float32), m)
        idx_out[a:b] = idx
        val_out[a:b] = vals

    for_blocks(P, block_points(cube.resolution, BLOCK_POINTS), block, tick)
    return SparseTransfer(idx_out, val_out, cube.resolution)


def diffuse_irradiance(transfer: SparseTransfer, light: LightingApproximation) -> np.ndarray:
    """``E = sum_i l_i T_i`` over the kept lighting terms, (P, 3) float32."""
    dense = light.dense.astype(np.float32)
    P = len(transfer.indices)
    out = np.zeros((P, 3), dtype=np.float32)

    def block(a, b):
        lit = dense[transfer.indices[a:b]]                       # (B, m, 3)
        out[a:b] = np.einsum("pm,pmc->pc", transfer.values[a:b], lit)

    for_blocks(P, 4096, block)
    return out


# ---------------------------------------------------------------------------
# Glossy: Ng 04 triple product, vectorised over points


def _parents_of(H: np.ndarray, q: np.ndarray, n: int) -> np.ndarray:
    """Parent accumulation of per-point dense coefficients ``H`` (B, S) at the
    (shared) coefficient indices ``q`` (k,): (B, k)."""
    t = haar.face_tables(n)
    nn = n * n
    local = q % nn
    base = q - local
    anc = base[:, None, None] + t["anc"][local]                  # (k, L, 3)
    w = t["anc_w"][local]                                        # (k, L, 3)
    return H[:, base] + np.einsum("bklt,klt->bk", H[:, anc], w)


def triple_product_points(light: LightingApproximation, V: np.ndarray, rho: np.ndarray,
                          rho_indices: np.ndarray) -> np.ndarray:
    """``sum_p L_p V_p rho_p`` per point from Haar coefficients, (B, 3).

    ``light`` shared sparse lighting (RGB); ``V`` (B, S) dense visibility
    coefficients; ``rho`` (B, S) per-point coefficients, zero outside
    ``rho_indices`` (B, k) (its non-linear approximation).  The terms of the
    tripling theorem (module :mod:`.haar`): per face the scaling product; pairs
    of identical wavelets times the third function's parent accumulation
    (driven by the lighting's support for (L,V) and (L,rho), by rho's support
    for (V,rho)); sibling triples driven by the lighting's support.
    """
    n = light.n
    nn = n * n
    t = haar.face_tables(n)
    B = V.shape[0]
    q = light.indices
    Lq = light.values                                            # (k, 3)
    wav = (q % nn) != 0
    out = np.zeros((B, 3))
    # scaling functions of each face
    sc = np.arange(6) * nn
    out += (V[:, sc] * rho[:, sc]) @ light.dense[sc]
    # (L, V) pairs x parent(rho) and (L, rho) pairs x parent(V), at L's wavelets
    qw, Lw = q[wav], Lq[wav]
    if qw.size:
        out += (V[:, qw] * _parents_of(rho, qw, n)) @ Lw
        out += (rho[:, qw] * _parents_of(V, qw, n)) @ Lw
        # siblings: three distinct types on one square, driven by L
        local = qw % nn
        base = qw - local
        s1, s2 = base + t["sib"][local, 0], base + t["sib"][local, 1]
        sib = t["sib_scale"][local][None, :] * (V[:, s1] * rho[:, s2] + V[:, s2] * rho[:, s1])
        out += sib @ Lw
    # (V, rho) pairs x parent(L), at rho's (per-point) support
    r = rho_indices
    rw = (r % nn) != 0
    pv = np.take_along_axis(V, r, axis=1) * np.take_along_axis(rho, r, axis=1) * rw
    out += np.einsum("bk,bkc->bc", pv, light.parents[r])
    return out / n


def glossy_radiance(vis_bits: np.ndarray, normals: np.ndarray, view_dirs: np.ndarray,
                    cube: Cubemap, lighting: CubeLighting, material: Material,
                    light: LightingApproximation, brdf_terms: int, tick=None) -> np.ndarray:
    """Glossy outgoing radiance by the Haar triple product, (P, 3) float32.

    Per point and separable term of :func:`~.brdf.specular_terms` (Fresnel and
    layer weights are per-point colours), ``rho~ = lobe * dw`` is transformed and
    truncated to its ``brdf_terms`` largest coefficients; the visibility is
    transformed exactly.
    """
    P, S = len(normals), cube.size
    out = np.zeros((P, 3), dtype=np.float32)
    if material.is_diffuse_only or P == 0:
        return out
    dirs = lighting.unit_directions
    dw32 = cube.solid_angles.astype(np.float32)
    k = int(min(max(int(brdf_terms), 1), S))

    def block(a, b):
        V = haar.cube_forward(unpack_visibility(vis_bits[a:b], S), np.float32)
        acc = np.zeros((b - a, 3))
        for lobe, weight in specular_terms(material, normals[a:b], view_dirs[a:b], dirs):
            rho_full = haar.cube_forward(lobe * dw32, np.float32)
            idx, vals = haar.nonlinear_approximation(rho_full, k)
            rho = np.zeros_like(rho_full)
            np.put_along_axis(rho, idx, vals, axis=1)
            acc += triple_product_points(light, V, rho, idx) * weight
        out[a:b] = acc

    for_blocks(P, block_points(cube.resolution, BLOCK_POINTS // 2), block, tick)
    return out
