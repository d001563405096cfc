"""BLOCKS' own microfacet lobe in float32 (the evaluator :mod:`.blocks` samples it at
(vertex, direction) pairs) and the Appendix-A-style choice of each (vertex, block) pair's
BRDF representation (:func:`glossy_levels`).

The formulas are those of :mod:`.brdf` (Cycles' ``bsdf_microfacet_eval``: the NDF, the
Smith ``Lambda`` of :func:`.microfacet.lambda_of_t2`, the Fresnel and multiscatter factors)
written for float32 arrays of any shape and for paired samples, where :mod:`.brdf`
evaluates every pair of a point set and a direction set in float64.
"""

from __future__ import annotations

import numpy as np

from ...shading import brdf as _brdf
from .encoding import PIXEL, BlockGeometry
from ...common.cache import Cache
from ...shading.microfacet import lambda_of_t2

#: Default rule thresholds on q = D(closest half-vector) / D(peak) (see glossy_levels).
DEFAULT_LEVEL_THRESHOLDS = (1e-2, 1e-3, 1e-4, 1e-9)


def _beckmann_grazing_cos(a2) -> float:
    """``cos_i`` above which Beckmann's ``Lambda_i`` is 0 (``a2 tan^2(theta_i) < 0.39``),
    with a margin of 0.1 % for float32 rounding."""
    return float(np.sqrt(float(a2) / (float(a2) + 0.39) * 1.001))


def _beckmann_grazing(val, cos_i, a2, lam_o, lowest):
    """Beckmann's ``G2``: ``val`` computed with ``Lambda_i = 0`` gets
    ``(1 + Lambda_o) / (1 + Lambda_o + Lambda_i)`` where the light is grazing enough for
    ``Lambda_i > 0`` (``a2 tan^2(theta_i) >= 0.39``), in place.  ``lowest``: the
    smallest ``cos_i`` (a float: nothing to do above the cut), or per row of a 2-D
    ``cos_i`` (only the rows that reach below the cut are looked at)."""
    f32 = np.float32
    one = f32(1.0)
    top = f32(_beckmann_grazing_cos(a2))
    shape = np.shape(cos_i)
    if np.ndim(lowest):
        rows = np.flatnonzero(lowest <= top)
        if not rows.size:
            return
        sub = cos_i[rows]
        g = np.flatnonzero((sub <= top) & (sub > 0.0))    # below the horizon: zeroed anyway
        at = (rows[g // shape[1]], g % shape[1])
        g = at[0] * shape[1] + at[1]
    elif lowest > top:
        return
    else:
        ci = np.asarray(cos_i)
        g = np.flatnonzero((ci <= top) & (ci > 0.0))
        at = np.unravel_index(g, shape)
    if g.size:
        ci = np.asarray(cos_i)[at]
        lg = lambda_of_t2("BECKMANN", a2 * np.maximum(one / (ci * ci) - one, f32(0.0)))
        lo = np.broadcast_to(lam_o, shape)[at]
        val.reshape(-1)[g] *= (one + lo) / (one + lo + lg)


def microfacet_lobe(distribution: str, a2, cos_i, dot_io, cos_o, lam_o, want_h: bool = True,
                    split: bool = False):
    """``D(h) G2 / (4 cos_o)`` and ``h.wi`` from cosines, float32 -- the formulas of
    :func:`.brdf.microfacet_D`, :func:`.brdf.smith_lambda` and ``brdf._specular_terms``
    (Cycles' ``bsdf_microfacet_eval``) written for float32 arrays of any shape
    (``cos_o``/``lam_o`` broadcast; float64 inputs are computed in float64).
    Zero where ``cos_i <= 0``.  Grazing directions overflow to inf on purpose
    (``G2 -> 0``): callers hold ``np.errstate`` (see :func:`glossy_blocks`).

    ``split``: return ``(val, h, k)`` with the per-vertex factor ``k`` (shape of
    ``cos_o``) left out of ``val`` (the lobe is ``val * k``), so that a caller
    summing ``val`` against the lighting applies it once per vertex; ``k`` is None
    when the distribution has no such factor (GGX: already in ``val``).  ``val`` and
    ``dot_io`` may be overwritten (pass copies to keep them)."""
    f32 = np.float32
    one = f32(1.0)
    floor = f32(_brdf.HALF_LEN2_FLOOR)
    # Nothing is below the horizon (every direction has cos_i > 0, so wi != -wo as cos_o
    # > 0) for most blocks: one minimum spares the masks below.
    lowest = float(cos_i.min()) if np.size(cos_i) else 1.0
    vertex_factor = None
    h = np.sqrt(np.clip(f32(0.5) * (one + dot_io), f32(0.0), one)) if want_h else None
    if distribution == "BECKMANN":
        # D = exp(-tan^2 / a2) / (pi a2 cos^4); G2 = 1 / (1 + Lambda_i + Lambda_o), and
        # Lambda_i = 0 unless t2 = a2 tan^2(theta_i) >= 0.39 (grazing light): the
        # per-vertex part 1 / (pi a2 4 cos_o (1 + Lambda_o)) is one factor, the grazing
        # directions get (1 + Lambda_o) / (1 + Lambda_o + Lambda_i) afterwards.
        # With r = 1 / cos_h^2 = |wo + wi|^2 / (cos_i + cos_o)^2 (clamped to [1, 1e30]):
        # D G2 / (4 cos_o) = exp((1 - r) / a2) r^2 / (pi a2 4 cos_o (1 + Lambda_o)).
        r = np.multiply(dot_io, f32(2.0), out=dot_io if np.ndim(dot_io) else None)
        r += f32(2.0)                               # |wo + wi|^2
        degenerate = None
        if lowest <= 0.0 and r.size and r.min() <= floor:   # wi = -wo: no half-vector
            degenerate = r <= floor
        c = cos_i + cos_o
        c *= c
        r /= c
        np.clip(r, one, f32(1e30), out=r)
        val = np.subtract(one, r)
        val *= one / a2
        np.exp(val, out=val)
        r *= r
        val *= r
        vertex_factor = one / ((f32(np.pi) * a2) * f32(4.0) * cos_o * (one + lam_o))
        _beckmann_grazing(val, cos_i, a2, lam_o, lowest)
        if not split:
            val *= vertex_factor
        if degenerate is not None:
            val[degenerate] = 0.0
    else:
        len2 = dot_io * f32(2.0)
        len2 += f32(2.0)
        degenerate = None
        if lowest <= 0.0 and len2.size and len2.min() <= floor:
            degenerate = len2 <= floor
            np.maximum(len2, floor, out=len2)
        c = cos_i + cos_o
        c *= c
        c /= len2                                   # cos_h^2
        np.minimum(c, one, out=c)
        den = one - c + a2 * c
        val = a2 / (f32(np.pi) * den * den)
        ci = np.clip(cos_i, f32(1e-12), one)
        lam = lambda_of_t2("GGX", a2 * np.maximum(one / (ci * ci) - one, f32(0.0)))
        lam += one + lam_o
        lam *= f32(4.0) * cos_o
        val /= lam
        if degenerate is not None:
            val[degenerate] = 0.0
    if lowest <= 0.0:
        val[cos_i <= 0.0] = 0.0
    if split:
        return val, h, vertex_factor
    return val, h


# half-vector angles of a lobe's thresholds per (distribution, alpha, thresholds)
_ANGLE_CACHE = Cache(64)


class GlossyLobe:
    """The glossy part of a :class:`.brdf.Material` as separable terms, sampled at
    *paired* (vertex, direction) samples -- the same formulas as
    :func:`.brdf.specular_terms` (REFERENCE), which evaluates all pairs of a point
    set and a direction set.  ``prepare(normals, views)`` fixes the vertices."""

    def __init__(self, material, dtype=np.float32):
        self.material = material
        self.dtype = np.dtype(dtype).type
        self.distribution = material.lobe_distribution
        self.alpha = material.alpha

    def prepare(self, normals, views):
        m = self.material
        n = _brdf.unit_rows(normals, "normals")
        v = _brdf.unit_rows(views, "views")
        v, cos_o = _brdf.bend_views(n, v)
        self.n, self.v, self.cos_o = n, v, cos_o
        self.lam_o = _brdf.smith_lambda(self.distribution, self.alpha, cos_o)
        col = np.asarray(m.specular_color, dtype=np.float64)
        terms = []                 # (factor kind, per-vertex weight (P, 3))
        fres = m.fresnel

        def f82(f0, tint, weight):
            f0 = np.clip(np.asarray(f0, dtype=np.float64), 0.0, 1.0)
            B = _brdf.metal_B(f0, tint)
            if not np.any(B):
                terms.append(("one", weight * f0[None, :]))
                terms.append(("schlick5", weight * (1.0 - f0)[None, :]))
                return
            for c in range(3):
                onehot = np.zeros_like(weight)
                onehot[:, c] = weight[:, c]
                terms.append((("f82", float(f0[c]), float(B[c])), onehot))

        if fres == "NONE":
            terms.append(("one", _brdf.multiscatter_factor(m, cos_o) * col[None, :]))
        elif fres == "SCHLICK":
            k = _brdf.multiscatter_factor(m, cos_o)
            terms.append(("one", k * col[None, :]))
            terms.append(("schlick5", k * (1.0 - col)[None, :]))
        elif fres == "F82":
            f82(col, m.f82_tint, _brdf.multiscatter_factor(m, cos_o))
        else:
            if m.metallic > 0.0:
                f82(m.diffuse_albedo, m.f82_tint,
                    m.metallic * _brdf.multiscatter_factor(m, cos_o, "metal"))
            if m._has_dielectric_lobe:
                f0 = np.clip(col, 0.0, 1.0)
                k = (1.0 - m.metallic) * _brdf.multiscatter_factor(m, cos_o)
                terms.append(("one", k * f0[None, :]))
                terms.append(("diel", k * (1.0 - f0)[None, :]))
        dt = self.dtype
        self.terms = [(k, np.asarray(w, dtype=dt)) for k, w in terms]
        self.a2 = dt(self.alpha) ** 2
        self.n32, self.v32 = n.astype(dt), v.astype(dt)
        self.cos_o32 = cos_o.astype(dt)
        self.lam_o32 = self.lam_o.astype(dt)
        # a scalar lobe: colour applied per vertex after the sums
        self.scalar = len(terms) == 1 and terms[0][0] == "one"
        self._fused = None
        if self.distribution == "BECKMANN" and dt is np.float32 and self.a2 >= 5e-5 \
                and self.cos_o32.size and float(self.cos_o32.min()) >= 0.5e-4:
            one = np.ones((n.shape[0], 1), dtype=dt)
            self._fused = (np.hstack([self.n32, self.cos_o32[:, None]]),
                           np.hstack([self.v32, one]) * (dt(2.0) / self.a2))
        return self

    def _terms_of(self, val, h, p):
        """[(factor (..., D), per-vertex weight rows (..., 3))] for lobe values ``val``."""
        out = []
        for kind, w in self.terms:
            if kind == "one":
                f = val
            elif kind == "schlick5":
                f = val * np.clip(np.float32(1.0) - h, 0.0, 1.0) ** 5
            elif kind == "diel":
                f = val * _brdf.dielectric_s(h, self.material.ior)
            else:
                f = val * _brdf.fresnel_f82(h, np.array([kind[1]]), np.array([kind[2]]))[..., 0]
            out.append((f.astype(self.dtype, copy=False), w[p]))
        return out

    def sample(self, p, d) -> np.ndarray:
        """Glossy BRDF x cos (M, 3) at paired samples (vertex ``p`` (M,), unit direction
        ``d`` (M, 3))."""
        d = np.asarray(d, dtype=self.dtype)
        cos_i = np.einsum("ij,ij->i", self.n32[p], d)
        dot_io = np.einsum("ij,ij->i", self.v32[p], d)
        val, h = microfacet_lobe(self.distribution, self.a2, cos_i, dot_io, self.cos_o32[p],
                                 self.lam_o32[p], not self.scalar)
        out = np.zeros((val.size, 3), dtype=self.dtype)
        for f, w in self._terms_of(val, h, p):
            out += f[:, None] * w
        return out

    def dense(self, p, d, edge: bool = True):
        """Terms at every (vertex ``p`` (k,), direction) combination, the directions
        shared ``d`` (D, 3) or per vertex ``d`` (k, D, 3): [(factor (k, D) float32,
        weight (k, 3))]; BRDF x cos = sum factor * weight (the per-vertex factor of
        the lobe is on the weights).  ``edge=False`` promises that every direction is
        well above every vertex's horizon (:meth:`horizon_cos` < every ``cos_i``), which
        spares the fused path its horizon and grazing-light checks."""
        d = np.asarray(d, dtype=self.dtype)
        if d.ndim == 2 and self._fused is not None:
            return self._beckmann_shared(p, d, edge)
        if d.ndim == 2:
            dt = np.ascontiguousarray(d.T)
            cos_i = self.n32[p] @ dt
            dot_io = self.v32[p] @ dt
        else:
            cos_i = np.einsum("kc,kjc->kj", self.n32[p], d)
            dot_io = np.einsum("kc,kjc->kj", self.v32[p], d)
        val, h, k = microfacet_lobe(self.distribution, self.a2, cos_i, dot_io,
                                    self.cos_o32[p][:, None], self.lam_o32[p][:, None],
                                    not self.scalar, split=True)
        terms = self._terms_of(val, h, p)
        if k is not None:                   # the per-vertex factor, on the (k, 3) weights
            terms = [(f, w * k) for f, w in terms]
        return terms

    def horizon_cos(self) -> float:
        """``cos_i`` below which a direction needs more than the lobe's main formula
        (Beckmann: the grazing-light ``Lambda_i``; every lobe: zero below the horizon)."""
        return _beckmann_grazing_cos(self.a2) if self.distribution == "BECKMANN" else 1.0

    def _beckmann_shared(self, p, d, edge=True):
        """:meth:`dense` for Beckmann in float32 against shared directions ``d`` (D, 3),
        with the additions folded into matrix products: ``[n, cos_o] . [d, 1]`` is
        ``cos_i + cos_o`` and ``[2 wo, 2] . [d, 1] / a2`` is ``|wo + wi|^2 / a2``, so
        ``r / a2 = |wo + wi|^2 / (a2 (cos_i + cos_o)^2)`` (``r = 1 / cos_h^2``) and
        ``D G2 / (4 cos_o) = exp(1/a2 - r/a2) (r/a2)^2 * a2 / (4 pi cos_o (1 + Lambda_o))``.
        Only for ``a2 >= 5e-5`` and views not below ``cos_o = 0.5e-4`` (:attr:`_fused`),
        where ``(r/a2)^2`` cannot overflow; float32 rounding of ``r`` moves the exponent
        by about ``3e-7 / a2``, as in the general path."""
        f32 = np.float32
        n4, v4 = self._fused
        dt = np.ascontiguousarray(d.T)
        d1 = np.vstack([dt, np.ones((1, dt.shape[1]), dtype=f32)])
        cos_i = self.n32[p] @ dt if edge else None
        c = n4[p] @ d1                                     # cos_i + cos_o
        r = v4[p] @ d1                                     # |wo + wi|^2 / a2
        h = None if self.scalar else np.sqrt(np.clip(r * (self.a2 / f32(4.0)), 0.0, 1.0))
        c *= c
        r /= c                                             # r / a2
        # |wo + wi| >= n.(wo + wi) = cos_i + cos_o >= cos_o where cos_i > 0, so r >= 1
        # holds in float32 unless cos_o is tiny (a bent grazing view, wi ~ -wo): clamp
        # those rows only (cos_i <= 0 is zeroed below)
        low = np.flatnonzero(self.cos_o32[p] < f32(0.05))
        if low.size:
            r[low] = np.maximum(r[low], f32(1.0) / self.a2)
        val = np.subtract(f32(1.0) / self.a2, r, out=c)   # c is not needed any more
        np.exp(val, out=val)
        r *= r
        val *= r
        if edge:
            lowest = cos_i.min(axis=1) if cos_i.size else np.ones(len(p), dtype=f32)
            _beckmann_grazing(val, cos_i, self.a2, self.lam_o32[p][:, None], lowest)
            rows = np.flatnonzero(lowest <= 0.0)
            if rows.size:                      # below the horizon (and wi = -wo: nan)
                g = np.flatnonzero(cos_i[rows] <= 0.0)
                val[rows[g // val.shape[1]], g % val.shape[1]] = 0.0
        k = self.a2 / (f32(4.0 * np.pi) * self.cos_o32[p] * (f32(1.0) + self.lam_o32[p]))
        return [(f, w * k[:, None]) for f, w in self._terms_of(val, h, p)]

    def peak_ratio(self, cos_h) -> np.ndarray:
        """``D(cos_h) / D(1)``: how far a half-vector is from the lobe peak."""
        return _brdf.microfacet_D(self.distribution, self.alpha, cos_h) / \
            _brdf.microfacet_D(self.distribution, self.alpha, 1.0)

    def threshold_angles(self, thresholds) -> np.ndarray:
        """Half-vector angles at which :meth:`peak_ratio` falls to each threshold
        (it decreases monotonically with the angle for Beckmann and GGX)."""
        key = (self.distribution, float(self.alpha), tuple(float(t) for t in thresholds))
        got = _ANGLE_CACHE.get(key)
        if got is None:
            theta = np.linspace(0.0, np.pi / 2, 20001)
            q = self.peak_ratio(np.cos(theta))
            got = np.array([theta[q > t].max() if (q > t).any() else -1.0 for t in key[2]])
            _ANGLE_CACHE[key] = got
        return got


def glossy_levels(lobe: GlossyLobe, p: np.ndarray, b: np.ndarray, geometry: BlockGeometry,
                  thresholds=DEFAULT_LEVEL_THRESHOLDS) -> np.ndarray:
    """Appendix-A-style choice of the BRDF representation per (vertex, block) pair.

    Appendix A picks 1 / 4 / 16 coefficients or the pixel basis from the angle
    between the view and the block centre reflected about the normal and the
    specular exponent.  For microfacet lobes we use the same two ingredients in
    one number: the NDF at the half-vector of the block closest to the normal,
    relative to its peak, ``q = D(theta_h,min) / D(0)``, where
    ``theta_h,min = max(0, angle(n, h_centre) - r_b / |wo + w_centre|)`` (a
    direction ``r_b`` from the centre moves the half-vector by at most
    ``r_b / |wo + w|``).  ``q > t_pixel`` -> 256 pixels, ``> t_16`` -> 16,
    ``> t_4`` -> 4, else 1 (the lobe is at most ``t_4`` of its peak anywhere
    in the block, the block behaves "essentially as Lambertian")."""
    angles = lobe.threshold_angles(tuple(thresholds))          # theta_h where q = t
    nb = geometry.centre.shape[0]
    flat = p * nb + b
    cen = geometry.centre.astype(np.float32).T
    nc = (lobe.n32 @ cen).reshape(-1)[flat]
    vc = (lobe.v32 @ cen).reshape(-1)[flat]
    norm = np.sqrt(np.maximum(np.float32(2.0) + np.float32(2.0) * vc, np.float32(1e-12)))
    cos_hc = np.clip((nc + lobe.cos_o32[p]) / norm, -1.0, 1.0)
    th = np.arccos(cos_hc) - geometry.radius32[b] / norm     # closest half-vector angle
    levels = np.zeros(p.size, dtype=np.int64)
    levels[th < angles[3]] = 1
    levels[th < angles[2]] = 4
    levels[th < angles[1]] = 16
    levels[th < angles[0]] = PIXEL
    return levels


def near_horizon(lobe: GlossyLobe, p: np.ndarray, b: np.ndarray,
                 geometry: BlockGeometry) -> np.ndarray:
    """Per pair (vertex ``p``, block ``b``): whether some direction of the block may have
    ``cos_i <= lobe.horizon_cos()`` -- the angle between the normal and the block centre
    plus the block's radius reaches the cut (False: every direction is above it)."""
    top = np.arccos(np.float32(min(lobe.horizon_cos(), 1.0)))
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", lobe.n32[p],
                                      geometry.centre[b].astype(np.float32)), -1.0, 1.0))
    return (ang + geometry.radius32[b]) >= top
