"""GGX's view slice as a few warped SG lobes along the plane of incidence (Wang et al. 2009 §4
warps one NDF lobe; its §4.2 fits anisotropic NDFs with several isotropic lobes): the fit to
Cycles' slice, its energy and moments, per (roughness, view cosine) node of GGX_WARP_TABLE,
and the table's look-up."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..common.fitting import levenberg_marquardt
from ..shading.microfacet import lambda_raw
from ..sphere.directions import orthonormal_frame
from .ndf import (
    SG_ALPHA_MIN,
    COS_MIN,
    LAMBDA_MAX,
    graded_theta_quadrature,
    broadcast_rows,
    fit_coaxial_ndf,
    iso_ndf_lobes,
    ndf_value,
)

#: view-cosine nodes of :data:`GGX_WARP_TABLE` (node 0 is fitted at ``n.o = WARP_MU_MIN``).
WARP_MU = np.linspace(0.0, 1.0, 21)


WARP_MU_MIN = 0.02


#: Blender-roughness nodes of :data:`GGX_WARP_TABLE`.
WARP_R = np.linspace(0.0, 1.0, 21)


#: warped lobes of the GGX view slice: a row of round lobes along the plane of incidence
#: makes its elongated shape (two: the r 0.5 rim 30-40 % dark; docs/measurements.md)
GGX_WARP_LOBES = 4


#: weight of the slice's moments in the fit (energy, centroid, second moments; relative to
#: the slice's L2 norm): under smooth light the centroid matters more than the L2 shape
WARP_MOMENT_WEIGHT = 5.0


#: weight of the pull toward the node a fit continues (relative to the slice's norm): pins
#: a lobe where it does not matter, so the table stays continuous.
WARP_RIDGE = 1e-3


#: (tilt, log-sharpness) tried for a lobe the fit left without amplitude (its gradient is 0)
_WARP_SEEDS = tuple((d, l) for d in (-0.9, -0.6, -0.3, 0.0, 0.3) for l in (-1.0, 0.0, 1.0, 2.0))


def _warp_quadrature(a, mu_o, per_panel=8, nphi=48):
    """Light directions ``i`` (N, 3) and their solid angles for the slice at view
    ``o = (sqrt(1 - mu_o^2), 0, mu_o)`` (normal +z): a graded quadrature of the half vector
    (:func:`graded_theta_quadrature`, half the azimuths: the slice is symmetric about the
    plane of incidence, weights doubled) mapped by ``i = 2 (o.h) h - o``,
    ``d i = 4 (o.h) d h``; directions below the horizon dropped."""
    th, wt = graded_theta_quadrature(a, per_panel)
    ph = (np.arange(nphi) + 0.5) * (math.pi / nphi)
    T, PH = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], -1).reshape(-1, 3)
    wh = (wt[:, None] / (2.0 * nphi) * 2.0 + 0.0 * PH).reshape(-1)
    o = np.array([math.sqrt(max(1.0 - mu_o * mu_o, 0.0)), 0.0, mu_o])
    oh = h @ o
    i = 2.0 * oh[:, None] * h - o
    keep = (oh > 0.0) & (i[:, 2] > 0.0)
    return o, h[keep], i[keep], (wh * 4.0 * oh)[keep]


def _warp_sharpness(a, mu_o):
    """The plain warp's sharpness (eq. 18-21) of the NDF's nominal lobe ``2 / a^2``."""
    return np.minimum(2.0 / (a * a) / (4.0 * np.maximum(mu_o, WARP_MU_MIN)), LAMBDA_MAX)


class _Slice(NamedTuple):
    """Cycles' single-scattering GGX slice times the cosine on :func:`_warp_quadrature`'s
    points (``t``, times the square-root weights ``sw``) and its moments (``mom @ t``)."""

    a: float
    mu_o: float
    i: np.ndarray
    sw: np.ndarray
    t: np.ndarray
    tn: float
    mom: np.ndarray
    scale: float            # of the moment rows: WARP_MOMENT_WEIGHT |t| / |mom t|


def _ggx_slice(r, mu_o):
    a = max(float(r) ** 2, SG_ALPHA_MIN)
    mu_o = max(float(mu_o), WARP_MU_MIN)
    _, h, i, wi = _warp_quadrature(a, mu_o)
    a2 = a * a
    g2 = 1.0 / (1.0 + lambda_raw("GGX", a2, np.maximum(i[:, 2], COS_MIN))
                + lambda_raw("GGX", a2, mu_o))
    sw = np.sqrt(wi)
    t = ndf_value("GGX", h, a) * g2 / (4.0 * mu_o) * sw
    # moments: energy, centroid (i_y's is 0: the slice is symmetric about the plane of
    # incidence), second moments
    mom = np.stack([np.ones_like(sw), i[:, 0], i[:, 2], i[:, 0] ** 2, i[:, 1] ** 2,
                    i[:, 0] * i[:, 2]]) * sw
    tn = float(np.linalg.norm(t))
    return _Slice(a, mu_o, i, sw, t, tn, mom,
                  WARP_MOMENT_WEIGHT * tn / max(float(np.linalg.norm(mom @ t)), 1e-300))


def _slice_lobes(S, x):
    """The lobes ``x = (d_1..d_K, l_1..l_K)`` times the cosine on ``S``'s points (N, K)."""
    K = len(x) // 2
    el = np.clip(math.acos(S.mu_o) + x[:K], -0.5 * math.pi, 0.5 * math.pi)  # above the horizon
    ax = np.stack([-np.sin(el), np.zeros(K), np.cos(el)], 1)
    lam = np.minimum(_warp_sharpness(S.a, S.mu_o) * np.exp(np.minimum(x[K:], 30.0)), LAMBDA_MAX)
    return np.exp(lam * (S.i @ ax.T - 1.0)) * (S.i[:, 2] * S.sw)[:, None]


def _slice_misfit(S, g):
    """Relative misfit of ``g`` (the lobes' sum times the cosine on ``S``'s points): its
    difference from the slice and that of its moments."""
    return np.concatenate([g - S.t, S.scale * (S.mom @ (g - S.t))]) / S.tn


def fit_ggx_warp(r, mu_o, x0=None, lobes=GGX_WARP_LOBES, neighbours=(), iterations=80):
    """Least-squares fit of the GGX view slice of Blender roughness ``r`` at view cosine
    ``mu_o`` by ``lobes`` isotropic SG lobes (Wang et al. 2009 fit anisotropic NDFs by
    several isotropic lobes, §4.2): lobe ``k``'s axis is the mirror direction tilted by
    ``d_k`` (radians, in the plane of incidence, away from the normal for ``d_k > 0``, kept
    above the horizon), its sharpness the plain warp's ``2 / (4 a^2 n.o)`` (eq. 18-21)
    times ``exp(l_k)``, its amplitude free and non-negative.  Minimises
    ``int_{n.i>0} (sum_k G_k(i) (n.i) - D(h) G2(i, o) / (4 n.o))^2 di`` against Cycles'
    single-scattering GGX slice times the cosine (Fresnel 1) plus the squared misfit of
    its moments (energy, centroid, second moments; weight :data:`WARP_MOMENT_WEIGHT`: under
    smooth light they matter more than the shape), amplitudes by non-negative least
    squares, ``(d_k, l_k)`` by Levenberg-Marquardt from ``x0`` (pulled toward it by
    :data:`WARP_RIDGE`; None: coaxial lobes of :func:`fit_coaxial_ndf`).  ``neighbours``:
    table nodes ``(r, mu_o, params)``; the mean of these lobes and each neighbour's, scaled
    to the slice's energy, is fitted alike to the slice half-way (so the table's bilinear
    interpolation is a fit too).  A lobe left without amplitude is re-seeded
    (:data:`_WARP_SEEDS`) where that helps.  The isotropic warp of §4.3 cannot follow the
    slice at oblique views (Wang et al. 2009 say so): it is broad in the plane of incidence
    and narrow across it, its peak off the mirror direction and cut by the horizon.
    Returns ``(params (3 K,) = (d_1..d_K, l_1..l_K, f_1..f_K), rel_error, rel_error of the
    plain warp of the two NDF lobes scaled to the slice's energy)`` with ``f_k`` the lobes'
    shares of the amplitude (the slice is scaled to Cycles' ``E`` where it is used,
    :func:`_ggx_normalisation`)."""
    from ..common.fitting import nonnegative_least_squares
    K = int(lobes)
    S = _ggx_slice(r, mu_o)
    mids = [(_ggx_slice(0.5 * (r + rn), 0.5 * (S.mu_o + max(float(mn), WARP_MU_MIN))),
             np.asarray(qn, dtype=np.float64)) for rn, mn, qn in neighbours]

    def solve(x):
        B = _slice_lobes(S, x)
        amp = nonnegative_least_squares(np.vstack([B, S.scale * (S.mom @ B)]),
                                        np.concatenate([S.t, S.scale * (S.mom @ S.t)]))
        return B, amp

    if x0 is None:
        lam, _, _ = fit_coaxial_ndf("GGX", S.a, K)
        x0 = np.concatenate([np.zeros(K), np.log(np.maximum(lam * S.a * S.a / 2.0, 1e-6))])
    prior = np.array(x0[:2 * K], dtype=np.float64)

    def resid(x):
        B, amp = solve(x)
        out = [_slice_misfit(S, B @ amp)]
        f = amp / max(float(np.sum(amp)), 1e-300)
        for Sm, qn in mids:
            g = _slice_lobes(Sm, 0.5 * (x + qn[:2 * K])) @ (0.5 * (f + qn[2 * K:]))
            e = float(np.sum(g * Sm.sw))
            out.append(_slice_misfit(Sm, g * (float(np.sum(Sm.t * Sm.sw)) / e if e > 0 else 0.0)))
        return np.concatenate(out + [WARP_RIDGE * (x - prior)])

    def descend(x):
        x, res = levenberg_marquardt(resid, x, iterations,
                                     fd_step=lambda v: 1e-6 * max(1.0, abs(v)), min_gain=1e-10)
        return x, float(res @ res)

    x, cost = descend(prior.copy())
    for _ in range(K):                       # a lobe without amplitude has no gradient: re-seed
        amp = solve(x)[1]
        dead = np.flatnonzero(amp <= 1e-9 * max(float(amp.max()), 1e-300))
        if not dead.size:
            break
        trials = []
        for d, l in _WARP_SEEDS:
            y = x.copy()
            y[dead[0]], y[K + dead[0]] = d, l
            res = resid(y)
            trials.append((float(res @ res), tuple(y)))
        y, c = descend(np.array(min(trials)[1]))
        if c >= cost * (1.0 - 1e-6):
            break
        x, cost = y, c
    el0 = math.acos(S.mu_o)
    x[:K] = np.clip(el0 + x[:K], -0.5 * math.pi, 0.5 * math.pi) - el0
    B, amp = solve(x)
    err = float(np.linalg.norm(B @ amp - S.t)) / S.tn
    # the plain warp of the NDF's two lobes, normalised to the slice's energy (E, not fitted)
    lam_d, mu_d = iso_ndf_lobes("GGX", S.a)
    ax0 = np.array([-math.sin(el0), 0.0, math.cos(el0)])
    B0 = np.exp(np.minimum(lam_d / (4.0 * S.mu_o), LAMBDA_MAX) * (S.i @ ax0 - 1.0)[:, None]) @ mu_d
    B0 = B0 * S.i[:, 2] * S.sw
    scale = float(np.sum(B0 * S.sw)) and float(np.sum(S.t * S.sw)) / float(np.sum(B0 * S.sw))
    err0 = float(np.linalg.norm(B0 * scale - S.t)) / S.tn
    return np.concatenate([x, amp / max(float(np.sum(amp)), 1e-300)]), err, err0


def ggx_warp_error(r, mu_o, params):
    """Relative L2 error of the lobes ``params`` (:func:`fit_ggx_warp`'s, e.g. the table's
    at or between nodes), scaled to the slice's energy, against the slice times the cosine."""
    S = _ggx_slice(r, mu_o)
    q = np.asarray(params, dtype=np.float64)
    K = len(q) // 3
    g = _slice_lobes(S, q[:2 * K]) @ np.maximum(q[2 * K:], 0.0)
    e = float(np.sum(g * S.sw))
    g = g * (float(np.sum(S.t * S.sw)) / e if e > 0 else 0.0)
    return float(np.linalg.norm(g - S.t)) / S.tn


#: the column of :data:`GGX_WARP_TABLE` fitted first (r 0.5), the others continued from it
WARP_SEED_COLUMN = 10


def ggx_warp_neighbours(table, ir, j):
    """The fitted nodes ``(r, mu_o, params)`` that the fit of ``table[ir, j]`` continues in
    :func:`ggx_warp_table_fit`: first the neighbour toward :data:`WARP_SEED_COLUMN` in r
    (its start), then the next n.o node up (empty at ``(WARP_SEED_COLUMN, n.o = 1)``)."""
    out = []
    if ir != WARP_SEED_COLUMN:
        k = ir - 1 if ir > WARP_SEED_COLUMN else ir + 1
        out.append((WARP_R[k], WARP_MU[j], table[k, j]))
    if j + 1 < len(WARP_MU):
        out.append((WARP_R[ir], WARP_MU[j + 1], table[ir, j + 1]))
    return out


def ggx_warp_table_fit(lobes=GGX_WARP_LOBES, log=None):
    """``(len(WARP_R), len(WARP_MU), 3 lobes)`` lobes :func:`fit_ggx_warp` at the nodes
    :data:`WARP_R` x :data:`WARP_MU`, each continued from its fitted neighbours
    (:func:`ggx_warp_neighbours`: the r 0.5 column from ``n.o = 1`` down, then column by
    column outward in r), so that neighbouring nodes hold the same lobes and the bilinear
    interpolation between them fits too.  How :data:`GGX_WARP_TABLE` was made (minutes)."""
    out = np.zeros((len(WARP_R), len(WARP_MU), 3 * lobes))
    order = [WARP_SEED_COLUMN] + list(range(WARP_SEED_COLUMN + 1, len(WARP_R))) + \
        list(range(WARP_SEED_COLUMN - 1, -1, -1))
    for ir in order:
        for j in range(len(WARP_MU) - 1, -1, -1):
            nb = ggx_warp_neighbours(out, ir, j)
            out[ir, j], err, _ = fit_ggx_warp(WARP_R[ir], WARP_MU[j], nb[0][2] if nb else None,
                                              lobes, nb)
            if log is not None:
                log(ir, j, err)
    return out


def ggx_warp_params(r, cos_o, table=None):
    """The lobes (..., 3 K) of :data:`GGX_WARP_TABLE` (or ``table``) at Blender roughness
    ``r`` and view cosine ``cos_o`` (bilinear; shapes broadcast)."""
    r, c = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(cos_o, dtype=np.float64))
    if table is None:
        from .warp_table import GGX_WARP_TABLE as table
    x = np.clip(r, 0.0, 1.0) * (len(WARP_R) - 1)
    y = np.clip(c, 0.0, 1.0) * (len(WARP_MU) - 1)
    i = np.minimum(x.astype(np.int64), len(WARP_R) - 2)
    j = np.minimum(y.astype(np.int64), len(WARP_MU) - 2)
    fx, fy = (x - i)[..., None], (y - j)[..., None]
    return ((1 - fx) * ((1 - fy) * table[i, j] + fy * table[i, j + 1])
            + fx * ((1 - fy) * table[i + 1, j] + fy * table[i + 1, j + 1]))


def ggx_warp_correct(roughness, n, o, P, table=None):
    """The fitted GGX view-slice lobes (:func:`fit_ggx_warp` by :func:`ggx_warp_params` at
    the point's roughness and ``n.o``): axes (P, K, 3), the mirror direction tilted in the
    plane of ``n`` and ``o``; sharpness (P, K); shares of the amplitude (P, K) (the slice
    is normalised to Cycles' ``E`` afterwards)."""
    cos_o = np.clip(np.sum(n * o, axis=1), 0.0, 1.0)
    alpha = np.clip(broadcast_rows(roughness, P), 0.0, 1.0)
    q = ggx_warp_params(np.sqrt(alpha), cos_o, table)                 # (P, 3 K)
    K = q.shape[-1] // 3
    u = cos_o[:, None] * n - o                     # the mirror direction's tangential part
    un = np.linalg.norm(u, axis=-1, keepdims=True)
    fallback, _ = orthonormal_frame(n)
    u = np.where(un > 1e-9, u / np.maximum(un, 1e-300), fallback)
    el = np.arccos(cos_o)[:, None] + q[:, :K]
    axes = np.cos(el)[..., None] * n[:, None, :] + np.sin(el)[..., None] * u[:, None, :]
    lam_w = _warp_sharpness(np.maximum(alpha, SG_ALPHA_MIN), cos_o)[:, None]
    lam = np.minimum(lam_w * np.exp(q[:, K:2 * K]), LAMBDA_MAX)
    return axes, lam, np.maximum(q[:, 2 * K:], 0.0)
