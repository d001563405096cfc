"""Haar wavelets on the cubemap: non-linear approximation (Ng et al. 2003) and
triple product integrals (Ng et al. 2004), the comparison basis of Inger et al. 2013, §3/§5.

Transform
---------
Every cube face (``N x N`` texels, ``N`` a power of two) gets its own 2D
*non-standard* Haar decomposition: one orthonormal 1D Haar step along rows and
columns of the current scaling block, recursing on the low-low quarter.  The
coefficients use the Mallat layout in an ``N x N`` array per face:

* ``[0, 0]``: the face's scaling coefficient (level 0);
* level ``l`` (``s = 2**l`` squares per edge, ``l = 0`` coarsest) holds, for the
  square ``(i, j)`` of side ``1/s`` of the face,

  - type 1 (``+`` left half, ``-`` right half)  at ``[i, s + j]``,
  - type 2 (``+`` top half, ``-`` bottom half)  at ``[s + i, j]``,
  - type 3 (``+`` on the diagonal quarters)     at ``[s + i, s + j]``.

Cube-level arrays are flattened exactly like the cubemap's texels:
``(face, row, col)`` -> ``face*N*N + row*N + col``, so coefficient ``w`` of a cube
lives on face ``w // (N*N)``.

:func:`forward` applied to *pixel values* is an orthogonal matrix ``W``
(:func:`transform_matrix`): ``sum_p f_p g_p = sum_i F_i G_i`` (Parseval), so
double products are plain dot products of coefficient vectors.

Normalisation of the tripling coefficients
------------------------------------------
:func:`tripling_coefficient` returns ``C_ijk = integral over a face of
psi_i psi_j psi_k`` for the basis normalised on the *unit square* (scaling
function 1, level-``l`` wavelets ``+-2**l``), i.e. exactly the values of Ng 04's
theorem: 1 for three scaling functions; ``2**l`` for three distinct wavelet types
on one square of level ``l``; 1 for two identical wavelets with the scaling
function; ``+-2**l'`` for two identical wavelets with a strictly coarser
wavelet (level ``l'``) whose support contains theirs (sign: that wavelet's sign
on the quadrant holding them); 0 otherwise (and 0 across faces).  The discrete
basis vectors of :func:`forward` are ``psi / N`` on the pixels, hence

    sum_p f_p g_p h_p = (1/N) * sum_ijk C_ijk F_i G_j H_k        (F = forward(f), ...)

and :func:`triple_product` returns the left-hand side: the pixel-basis sum.

Solid angle (documented choice)
-------------------------------
The cubemap texels do not have equal solid angles.  Ng 03 weights its lighting
coefficients by area; here the exact texel solid angle ``dw_k`` (and, for
Lambert/BRDF shading, ``max(0, n.w_k)``) is folded into the *transport* factor,
never into the lighting:

    rho~_k = rho_k * max(0, n.w_k) * dw_k      (triple product, Inger et al. 2013, eq. 2)
    T_k    = V_k   * max(0, n.w_k) * dw_k      (double product, Ng 03 diffuse)

so that REFERENCE's ``B = sum_k L_k V_k rho_k max(0,n.w_k) dw_k`` is
``triple_product(L, V, rho~)`` and ``double_product(L, T)`` exactly when every
coefficient is kept; the lighting stays plain radiance and its wavelet
coefficients are the ones a non-linear approximation ranks.  Ng 03's optional
"area-weighted selection" (favouring coarse terms) is available through the
``weights`` argument of :func:`nonlinear_approximation` with
:func:`support_areas`.

Triple product algorithm (Ng 04 §5) and its cost
------------------------------------------------
By the theorem, ``sum C_ijk F_i G_j H_k`` has only three kinds of terms:

1. the scaling term ``F_0 G_0 H_0`` per face;
2. *pairs*: for each wavelet ``w`` where two of the functions are both
   non-zero, ``A_w B_w * C_bar(w)`` where ``C_bar(w) = C_0 + sum over the
   strictly coarser wavelets ``w'`` above ``w`` of sign * 2**l' * C_w'`` is the
   *parent accumulation* of the third function at the square of ``w`` (its
   partial reconstruction from the coarser levels -- three such sums, one per
   choice of the third function);
3. *siblings*: ``2**l * A_w (B_t2 C_t3 + B_t3 C_t2)`` for the wavelets ``w``
   (type ``t``) of the sparsest function and the two other types ``t2, t3`` of
   the same square.

The evaluator drives each sum with the sparser of the functions involved and
looks the others up (``O(1)`` for dense arrays, ``O(log n)`` binary search for
sparse lists).  Parent accumulation gathers the ``3 * log2(N)`` ancestors of
each driving coefficient from precomputed tables, vectorised, so the work is
``O((n_L + n_rho) * log2 N)`` lookups for sparse lighting and BRDF and a dense
or sparse visibility -- linear in the number of non-zero coefficients up to
the ``log2 N <= 7`` factor that Ng 04 removes with a memoised tree traversal.
A :class:`HaarFunction` built with ``parent_table=True`` (once per lighting,
``O(N^2 log N)``) makes its parent accumulations ``O(1)`` lookups.  Compare the
pixel-basis REFERENCE: ``O(6 N^2)`` per point.
"""

from __future__ import annotations

import numpy as np

from ...common.cache import memo

__all__ = [
    "forward", "inverse", "cube_forward", "cube_inverse", "transform_matrix",
    "decode_index", "support_areas", "nonlinear_approximation", "keep_count",
    "sparse_to_dense", "tripling_coefficient", "HaarFunction", "triple_product",
    "double_product", "pixel_triple_sum",
]


def _check_resolution(n: int) -> int:
    n = int(n)
    if n < 1 or n & (n - 1):
        raise ValueError(f"Haar resolution must be a power of two, got {n}")
    return n


def _levels(n: int) -> int:
    return n.bit_length() - 1


# ---------------------------------------------------------------------------
# Transform


def _butterfly(a, b, c, d):
    """One 2x2 Haar step: 0.5 * [[1,1,1,1],[1,-1,1,-1],[1,1,-1,-1],[1,-1,-1,1]] @ (a,b,c,d).

    The matrix is symmetric and orthogonal, hence its own inverse: the same step
    maps the four pixels of a square to (scaling, type 1, type 2, type 3) and back.
    """
    return (0.5 * (a + b + c + d), 0.5 * (a - b + c - d),
            0.5 * (a + b - c - d), 0.5 * (a - b - c + d))


def _square_copy(values, name, dtype=np.float64):
    """A copy of ``(..., N, N)`` faces (N a power of two) as ``dtype``, and N."""
    a = np.array(values, dtype=dtype, copy=True)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2]:
        raise ValueError(f"{name} expects (..., N, N) square faces")
    return a, _check_resolution(a.shape[-1])


def forward(face_values, dtype=np.float64) -> np.ndarray:
    """Orthonormal 2D non-standard Haar transform of ``(..., N, N)`` faces (computed in
    ``dtype``: float32 halves the time where its precision suffices)."""
    a, n = _square_copy(face_values, "forward", dtype)
    lead = a.shape[:-2]
    while n > 1:
        h = n // 2
        p = a[..., :n, :n].reshape(lead + (h, 2, h, 2))
        ll, t1, t2, t3 = _butterfly(p[..., :, 0, :, 0], p[..., :, 0, :, 1],
                                    p[..., :, 1, :, 0], p[..., :, 1, :, 1])
        a[..., :h, :h] = ll
        a[..., :h, h:n] = t1
        a[..., h:n, :h] = t2
        a[..., h:n, h:n] = t3
        n = h
    return a


def inverse(coeffs) -> np.ndarray:
    """Inverse of :func:`forward` on ``(..., N, N)`` coefficient arrays."""
    a, N = _square_copy(coeffs, "inverse")
    lead = a.shape[:-2]
    h = 1
    while h < N:
        n = 2 * h
        ll, t1 = a[..., :h, :h], a[..., :h, h:n]
        t2, t3 = a[..., h:n, :h], a[..., h:n, h:n]
        out = np.empty(lead + (h, 2, h, 2))
        (out[..., :, 0, :, 0], out[..., :, 0, :, 1],
         out[..., :, 1, :, 0], out[..., :, 1, :, 1]) = _butterfly(ll, t1, t2, t3)
        a[..., :n, :n] = out.reshape(lead + (n, n))
        h = n
    return a


def resolution_of_size(size: int) -> int:
    n = int(round(np.sqrt(size / 6)))
    if 6 * n * n != size:
        raise ValueError(f"{size} values are not a cubemap (6*N*N)")
    return _check_resolution(n)


def cube_forward(values, dtype=np.float64) -> np.ndarray:
    """Per-face Haar transform of cubemap-flattened ``(..., 6*N*N)`` values."""
    v = np.asarray(values)
    n = resolution_of_size(v.shape[-1])
    return forward(v.reshape(v.shape[:-1] + (6, n, n)), dtype).reshape(v.shape)


def cube_inverse(coeffs) -> np.ndarray:
    """Inverse of :func:`cube_forward`."""
    c = np.asarray(coeffs, dtype=np.float64)
    n = resolution_of_size(c.shape[-1])
    return inverse(c.reshape(c.shape[:-1] + (6, n, n))).reshape(c.shape)


def transform_matrix(n: int) -> np.ndarray:
    """``(N*N, N*N)`` matrix ``W`` with ``forward(x).ravel() == W @ x.ravel()``."""
    n = _check_resolution(n)
    eye = np.eye(n * n).reshape(n * n, n, n)
    return forward(eye).reshape(n * n, n * n).T


# ---------------------------------------------------------------------------
# Index bookkeeping


@memo(16)
def face_tables(n: int):
    """Per-face lookup tables indexed by the face-local coefficient index."""
    n = _check_resolution(n)
    nn, lmax = n * n, _levels(n)
    r, c = np.divmod(np.arange(nn), n)
    m = np.maximum(np.maximum(r, c), 1)
    level = np.floor(np.log2(m)).astype(np.int64)
    s = np.left_shift(1, level)
    wtype = np.where(r < s, 1, np.where(c < s, 2, 3))
    scaling = (r == 0) & (c == 0)
    wtype[scaling] = 0
    level[scaling] = 0
    s[scaling] = 1
    si = np.where(wtype >= 2, r - s, r)
    sj = np.where((wtype == 1) | (wtype == 3), c - s, c)

    def local(lv, t, i, j):
        sl = np.left_shift(1, lv)
        row = np.where(t >= 2, sl + i, i)
        col = np.where((t == 1) | (t == 3), sl + j, j)
        return row * n + col

    # the two other wavelet types of the same square, and 2**l
    other = np.array([[2, 3], [1, 3], [1, 2]])
    ot = other[np.maximum(wtype, 1) - 1]
    sib = np.stack([local(level, ot[:, 0], si, sj), local(level, ot[:, 1], si, sj)], axis=1)
    sib[scaling] = 0
    sib_scale = np.where(scaling, 0.0, s.astype(np.float64))

    # ancestors: the three wavelets of every strictly coarser level above the square
    anc = np.zeros((nn, max(lmax, 1), 3), dtype=np.int64)
    anc_w = np.zeros((nn, max(lmax, 1), 3))
    for lp in range(lmax):
        valid = (~scaling) & (level > lp)
        shift = np.maximum(level - lp, 1)
        ai, aj = si >> shift, sj >> shift
        hr, hc = (si >> (shift - 1)) & 1, (sj >> (shift - 1)) & 1
        sr, sc = 1 - 2 * hr, 1 - 2 * hc
        for t, sign in ((1, sc), (2, sr), (3, sr * sc)):
            anc[:, lp, t - 1] = np.where(valid, local(lp, t, ai, aj), 0)
            anc_w[:, lp, t - 1] = np.where(valid, sign * float(1 << lp), 0.0)
    for arr in (level, wtype, si, sj, sib, sib_scale, anc, anc_w, scaling):
        arr.setflags(write=False)
    return dict(level=level, type=wtype, si=si, sj=sj, scaling=scaling, sib=sib,
                sib_scale=sib_scale, anc=anc, anc_w=anc_w)


def decode_index(idx, n: int):
    """``(face, level, type, i, j)`` of cube coefficient indices (type 0 = scaling)."""
    n = _check_resolution(n)
    face, q = np.divmod(np.asarray(idx, dtype=np.int64), n * n)
    if np.any(face < 0) or np.any(face >= 6):
        raise ValueError("coefficient index outside the cube")
    t = face_tables(n)
    return face, t["level"][q], t["type"][q], t["si"][q], t["sj"][q]


def support_areas(n: int) -> np.ndarray:
    """Fraction of its face covered by each cube coefficient's support, (6*N*N,)."""
    t = face_tables(_check_resolution(n))
    return np.tile(4.0 ** -t["level"].astype(np.float64), 6)


# ---------------------------------------------------------------------------
# Non-linear approximation


def keep_count(fraction: float, n: int) -> int:
    """Number of cube coefficients for a kept ``fraction`` (at least one)."""
    return int(min(6 * n * n, max(1, round(fraction * 6 * n * n))))


def nonlinear_approximation(coeffs, keep: int, weights=None, dense: bool = False):
    """Keep the ``keep`` largest ``|coeff| * weights`` along the last axis.

    Ranking runs over the whole cube (all faces together), as Ng 03.  Returns
    ``(indices, values)`` with ``indices`` ascending, shape ``(..., keep)`` -- or,
    with ``dense=True``, the truncated array (zeros elsewhere).  Without weights
    this is the best ``keep``-term L2 approximation (orthonormal basis).
    """
    c = np.asarray(coeffs)
    if c.dtype not in (np.float32, np.float64):
        c = c.astype(np.float64)
    size = c.shape[-1]
    keep = int(keep)
    if keep < 0:
        raise ValueError("keep must be non-negative")
    keep = min(keep, size)
    score = np.abs(c) if weights is None else np.abs(c) * np.asarray(weights, dtype=c.dtype)
    if keep == size:
        idx = np.broadcast_to(np.arange(size), c.shape).copy()
    elif keep == 0:
        idx = np.zeros(c.shape[:-1] + (0,), dtype=np.int64)
    else:
        idx = np.argpartition(-score, keep - 1, axis=-1)[..., :keep]
        idx = np.sort(idx, axis=-1)
    vals = np.take_along_axis(c, idx, axis=-1)
    if dense:
        out = np.zeros_like(c)
        np.put_along_axis(out, idx, vals, axis=-1)
        return out
    return idx.astype(np.int64), vals


def sparse_to_dense(indices, values, size: int) -> np.ndarray:
    out = np.zeros(np.shape(values)[:-1] + (int(size),))
    np.put_along_axis(out, np.asarray(indices, dtype=np.int64), np.asarray(values, dtype=np.float64), axis=-1)
    return out


# ---------------------------------------------------------------------------
# Tripling coefficients


def tripling_coefficient(i, j, k, n: int):
    """``C_ijk`` of cube coefficients ``i, j, k`` (unit-square normalisation, Ng 04 theorem).

    Broadcasts over array arguments; a scalar for scalar arguments.
    """
    n = _check_resolution(n)
    i, j, k = np.broadcast_arrays(*(np.asarray(x, dtype=np.int64) for x in (i, j, k)))
    fi, li, ti, ai, bi = decode_index(i, n)
    fj, lj, tj, aj, bj = decode_index(j, n)
    fk, lk, tk, ak, bk = decode_index(k, n)
    same_face = (fi == fj) & (fj == fk)
    out = np.zeros(i.shape)

    # all three scaling functions
    out = np.where((ti == 0) & (tj == 0) & (tk == 0), 1.0, out)

    # three distinct wavelet types on one square
    distinct = ((ti > 0) & (tj > 0) & (tk > 0) & (ti != tj) & (tj != tk) & (ti != tk)
                & (li == lj) & (lj == lk) & (ai == aj) & (aj == ak) & (bi == bj) & (bj == bk))
    out = np.where(distinct, np.ldexp(1.0, li), out)

    # two identical wavelets (x, x) and a different third function y
    def pair(x_eq_y, lx, tx, ax, bx, ly, ty, ay, by, same):
        shift = np.maximum(lx - ly, 1)
        inside = (ly < lx) & ((ax >> shift) == ay) & ((bx >> shift) == by)
        hr, hc = (ax >> (shift - 1)) & 1, (bx >> (shift - 1)) & 1
        sign = np.where(ty == 1, 1 - 2 * hc, np.where(ty == 2, 1 - 2 * hr, (1 - 2 * hr) * (1 - 2 * hc)))
        val = np.where(ty == 0, 1.0, np.where(inside, sign * np.ldexp(1.0, ly), 0.0))
        return np.where(x_eq_y & (tx > 0) & ~same, val, 0.0)

    out = out + pair(i == j, li, ti, ai, bi, lk, tk, ak, bk, k == i)
    out = out + pair(i == k, li, ti, ai, bi, lj, tj, aj, bj, j == i)
    out = out + pair(j == k, lj, tj, aj, bj, li, ti, ai, bi, i == j)
    out = np.where(same_face, out, 0.0)
    return float(out) if out.ndim == 0 else out


# ---------------------------------------------------------------------------
# Sparse functions and products


class HaarFunction:
    """Cube Haar coefficients, dense ``(6*N*N,)`` or sparse ``(indices, values)``.

    ``get(q)`` looks coefficients up (dense: O(1); sparse: binary search);
    ``parent_table=True`` precomputes the parent accumulation of every
    coefficient (``O(N^2 log N)`` once, e.g. per lighting) so later
    :func:`triple_product` calls look it up in O(1).
    """

    __slots__ = ("n", "dense", "idx", "vals", "parents")

    def __init__(self, data, n: int, parent_table: bool = False):
        self.n = _check_resolution(n)
        size = 6 * self.n * self.n
        self.parents = None
        if isinstance(data, HaarFunction):
            self.dense, self.idx, self.vals = data.dense, data.idx, data.vals
            self.parents = data.parents
        elif isinstance(data, tuple):
            idx = np.asarray(data[0], dtype=np.int64).ravel()
            vals = np.asarray(data[1], dtype=np.float64).ravel()
            if idx.shape != vals.shape:
                raise ValueError("sparse indices and values differ in length")
            if idx.size and (idx.min() < 0 or idx.max() >= size):
                raise ValueError("sparse index outside the cube")
            order = np.argsort(idx, kind="stable")
            idx, vals = idx[order], vals[order]
            if idx.size > 1 and np.any(idx[1:] == idx[:-1]):
                raise ValueError("duplicate sparse indices")
            self.dense, self.idx, self.vals = None, idx, vals
        else:
            d = np.asarray(data, dtype=np.float64)
            if d.shape != (size,):
                raise ValueError(f"dense coefficients must have shape ({size},)")
            self.dense, self.idx, self.vals = d, None, None
        if parent_table and self.parents is None:
            q = np.arange(size)
            self.parents = self._parent_sums(q)

    @property
    def nnz(self) -> int:
        return self.dense.size if self.dense is not None else self.idx.size

    def support(self):
        """(indices, values) of the non-zero coefficients."""
        if self.dense is not None:
            if self.idx is None:
                self.idx = np.flatnonzero(self.dense)
                self.vals = self.dense[self.idx]
        return self.idx, self.vals

    def get(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=np.int64)
        if self.dense is not None:
            return self.dense[q]
        if self.idx.size == 0:
            return np.zeros(q.shape)
        pos = np.minimum(np.searchsorted(self.idx, q), self.idx.size - 1)
        return np.where(self.idx[pos] == q, self.vals[pos], 0.0)

    def _parent_sums(self, q):
        nn = self.n * self.n
        t = face_tables(self.n)
        local = q % nn
        base = q - local
        anc = base[:, None, None] + t["anc"][local]
        return self.get(base) + np.einsum("qlt,qlt->q", self.get(anc), t["anc_w"][local])

    def parent(self, q) -> np.ndarray:
        """Parent accumulation at the square of each (wavelet) coefficient ``q``.

        ``C_0 + sum_{coarser w' above q} sign * 2**l' * C_w'``: N times the mean, over
        the square of ``q``, of the function reconstructed from coarser levels.
        """
        q = np.asarray(q, dtype=np.int64)
        if self.parents is not None:
            return self.parents[q]
        return self._parent_sums(q)


def _fn(x, n) -> HaarFunction:
    return x if isinstance(x, HaarFunction) and x.n == n else HaarFunction(x, n)


def _pair_sum(a: HaarFunction, b: HaarFunction, c: HaarFunction, nn: int) -> float:
    drv, oth = (a, b) if a.nnz <= b.nnz else (b, a)
    q, v = drv.support()
    prod = v * oth.get(q)
    keep = (prod != 0.0) & (q % nn != 0)
    q, prod = q[keep], prod[keep]
    if q.size == 0:
        return 0.0
    return float(prod @ c.parent(q))


def triple_product(L, V, rho, n: int) -> float:
    """``sum_p L_p V_p rho_p`` over the cube's pixels, from Haar coefficients.

    Each argument is a dense ``(6*N*N,)`` coefficient vector (:func:`cube_forward`
    of pixel values), a sparse ``(indices, values)`` pair (e.g. from
    :func:`nonlinear_approximation`) or a :class:`HaarFunction`.  Exact when
    nothing is truncated.  Fold ``max(0, n.w) * dw`` into ``rho`` (module doc)
    to get REFERENCE's outgoing radiance.  Cost: ``O((n_L + n_rho) log2 N)``
    lookups for sparse L and rho (module doc), independent of ``6*N*N`` when V
    is sparse.
    """
    n = _check_resolution(n)
    nn = n * n
    fs = [_fn(x, n) for x in (L, V, rho)]
    fl, fv, fr = fs
    sc = np.arange(6) * nn
    total = float(np.sum(fl.get(sc) * fv.get(sc) * fr.get(sc)))
    # pairs of identical wavelets times the parent accumulation of the third
    total += _pair_sum(fl, fv, fr, nn)
    total += _pair_sum(fl, fr, fv, nn)
    total += _pair_sum(fv, fr, fl, nn)
    # three distinct types on one square, driven by the sparsest function
    a, b, c = sorted(fs, key=lambda f: f.nnz)
    q, v = a.support()
    if q.size:
        t = face_tables(n)
        local = q % nn
        base = q - local
        s1, s2 = base + t["sib"][local, 0], base + t["sib"][local, 1]
        total += float(np.sum(t["sib_scale"][local] * v * (b.get(s1) * c.get(s2) + b.get(s2) * c.get(s1))))
    return total / n


def double_product(L, T, n: int | None = None) -> float:
    """Ng 03: ``B = sum_i l_i T_i`` over the kept lighting terms (= ``sum_p L_p T_p``).

    ``L`` sparse ``(indices, values)`` or dense; ``T`` dense or sparse (``n``
    needed only for sparse ``T`` or :class:`HaarFunction` arguments).
    """
    if isinstance(L, tuple) and not isinstance(T, (tuple, HaarFunction)):
        idx, vals = L
        return float(np.asarray(vals, dtype=np.float64) @ np.asarray(T, dtype=np.float64)[np.asarray(idx, dtype=np.int64)])
    if not isinstance(L, (tuple, HaarFunction)) and not isinstance(T, (tuple, HaarFunction)):
        return float(np.asarray(L, dtype=np.float64) @ np.asarray(T, dtype=np.float64))
    if n is None:
        raise ValueError("double_product needs n for sparse transport")
    fl, ft = _fn(L, n), _fn(T, n)
    drv, oth = (fl, ft) if fl.nnz <= ft.nnz else (ft, fl)
    q, v = drv.support()
    return float(v @ oth.get(q))


def pixel_triple_sum(L, V, rho) -> float:
    """The pixel-basis sum ``sum_p L_p V_p rho_p`` (the baseline)."""
    return float(np.sum(np.asarray(L, dtype=np.float64) * np.asarray(V, dtype=np.float64)
                        * np.asarray(rho, dtype=np.float64)))
