"""The environment prefiltered by SG lobes of every sharpness (Wang et al. 2009 §6): a mip
pyramid of SG convolutions read at a lobe's sharpness and axis."""

from __future__ import annotations

import math

import numpy as np

from ..sphere.directions import Cubemap, cubemap, direction_to_texel, face_coordinates
from . import algebra as core_sg
from .lighting import KERNEL_CUTOFF, LUMINANCE, box_down, check_radiance


def _downsample(L, N, Ns):
    """Solid-angle weighted box filter of a (6N^2, 3) cube to Ns texels per edge:
    ``(radiance (6Ns^2, 3), directions (6Ns^2, 3), solid angles)``.  Each coarse
    texel's direction is the luminance-weighted mean of its children's centres
    (so a one-texel sun keeps its place), its centre when dark."""
    fine = cubemap(N)
    if Ns == N:
        return L, np.asarray(fine.directions), np.asarray(fine.solid_angles)
    f = N // Ns
    w = fine.solid_angles.reshape(6, N, N)
    ws = w.reshape(6, Ns, f, Ns, f).sum(axis=(2, 4))
    y = (L @ LUMINANCE).reshape(6, N, N) * w
    m = (y[..., None] * np.asarray(fine.directions).reshape(6, N, N, 3)).reshape(
        6, Ns, f, Ns, f, 3).sum(axis=(2, 4))
    ysum = y.reshape(6, Ns, f, Ns, f).sum(axis=(2, 4))
    coarse = cubemap(Ns)
    dirs = np.asarray(coarse.directions).reshape(6, Ns, Ns, 3).copy()
    lit = ysum > 0
    md = m[lit] / ysum[lit][:, None]
    dirs[lit] = md / np.linalg.norm(md, axis=1, keepdims=True)
    return box_down(L, N, Ns, fine.solid_angles), dirs.reshape(-1, 3), ws.reshape(-1)


def face_bilinear(level, face, s, t):
    """Bilinear lookup within a face (edge-clamped) of a (6, N, N, C) array --
    the same arithmetic as ``shaders/lib/sg.glsl``'s texelFetch version."""
    N = level.shape[1]
    x = np.clip((s + 1.0) * 0.5 * N - 0.5, 0.0, N - 1.0)
    y = np.clip((t + 1.0) * 0.5 * N - 0.5, 0.0, N - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), N - 1)
    y0 = np.minimum(np.floor(y).astype(np.int64), N - 1)
    x1 = np.minimum(x0 + 1, N - 1)
    y1 = np.minimum(y0 + 1, N - 1)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    a = level[face, y0, x0] * (1 - fx) + level[face, y0, x1] * fx
    b = level[face, y1, x0] * (1 - fx) + level[face, y1, x1] * fx
    return a * (1 - fy) + b * fy


def _bucket_radius(nc):
    """Largest angle between a texel centre of the nc-cube and its corners."""
    e = np.linspace(-1.0, 1.0, nc + 1)
    c = 0.5 * (e[:-1] + e[1:])
    worst = 0.0
    for s0, s1, sc in zip(e[:-1], e[1:], c):           # face +Z suffices by symmetry
        for t0, t1, tc in zip(e[:-1], e[1:], c):
            ctr = np.array([sc, tc, 1.0]) / math.sqrt(sc * sc + tc * tc + 1.0)
            for s_, t_ in ((s0, t0), (s0, t1), (s1, t0), (s1, t1)):
                cor = np.array([s_, t_, 1.0]) / math.sqrt(s_ * s_ + t_ * t_ + 1.0)
                worst = max(worst, math.acos(min(1.0, float(ctr @ cor))))
    return worst


def _sg_convolve(out_dirs, src_dirs, src_w, src_L, lam):
    """``sum_k G(w_k; p, lam) L_k dw_k / sum_k G(w_k; p, lam) dw_k`` for every output
    direction ``p``.  Sharp kernels only see sources within ``theta_max``
    (``lam (1 - cos theta_max) = KERNEL_CUTOFF``): outputs and sources are bucketed by
    the texels of a coarse cube and each output bucket is convolved densely with the
    sources of the buckets whose centres lie within ``theta_max`` plus both bucket
    radii -- exact up to the e^-20 cut-off, and O(P * cap) instead of O(P * D)."""
    res = np.empty((out_dirs.shape[0], src_L.shape[1]))
    # float32 products/exponentials (the levels are float32): relative error of the
    # kernel ~ lam * 6e-8 <= 1e-4 for the sharpest level at N = 64
    out_dirs = np.asarray(out_dirs, dtype=np.float32)
    src_dirs = np.asarray(src_dirs, dtype=np.float32)
    src_w = np.asarray(src_w, dtype=np.float32)
    src_L = np.asarray(src_L, dtype=np.float32)
    lam32 = np.float32(lam)
    cos_max = 1.0 - KERNEL_CUTOFF / lam
    theta_max = math.acos(cos_max) if cos_max > -1.0 else math.pi
    if theta_max > 0.6:
        chunk = max(1, 4_000_000 // src_w.size)
        for a in range(0, out_dirs.shape[0], chunk):
            G = out_dirs[a:a + chunk] @ src_dirs.T
            np.minimum(G, np.float32(1.0), out=G)
            G -= np.float32(1.0)
            G *= lam32
            np.exp(G, out=G)
            G *= src_w[None, :]
            res[a:a + chunk] = (G @ src_L) / G.sum(axis=1, keepdims=True)
        return res
    nc = max(1, min(64, int(math.ceil(0.5 * math.pi / theta_max))))
    coarse = cubemap(nc)
    radius = _bucket_radius(nc)
    ob = direction_to_texel(out_dirs, nc)
    sb = direction_to_texel(src_dirs, nc)
    o_order = np.argsort(ob, kind="stable")
    s_order = np.argsort(sb, kind="stable")
    o_start = np.searchsorted(ob[o_order], np.arange(coarse.size + 1))
    s_start = np.searchsorted(sb[s_order], np.arange(coarse.size + 1))
    centres = np.asarray(coarse.directions)
    near = centres @ centres.T >= math.cos(min(math.pi, theta_max + 2.0 * radius))
    for b in range(coarse.size):
        oi = o_order[o_start[b]:o_start[b + 1]]
        if oi.size == 0:
            continue
        nb = np.flatnonzero(near[b])
        si = np.concatenate([s_order[s_start[c]:s_start[c + 1]] for c in nb])
        G = out_dirs[oi] @ src_dirs[si].T
        np.minimum(G, np.float32(1.0), out=G)
        G -= np.float32(1.0)
        G *= lam32
        np.exp(G, out=G)
        G *= src_w[si][None, :]
        res[oi] = (G @ src_L[si]) / G.sum(axis=1, keepdims=True)
    return res


class PrefilteredEnvironment:
    """``Gamma_L(p, lam)`` of eq. 34-35 tabulated as a pyramid of cubemaps.

    Level ``l`` holds the environment convolved with the *normalised* kernel
    ``G(i; p, lam_l, 1) / int G`` (the kernel-weighted mean radiance around ``p``):

    * level 0: ``lam = 0`` (the mean radiance, constant),
    * levels 1..n-2: ``lam = lam_1 r^(l-1)`` with ``lam_1 = 1/8`` and ratio
      ``r = sqrt(2)`` up to the largest value <= ``(2N/pi)^2`` (a lobe about one
      texel wide),
    * level n-1: ``lam = inf``: the environment itself.

    Each finite level is computed by brute force, ``sum_k G(w_k; p, lam) L_k dw_k
    / sum_k G(w_k; p, lam) dw_k`` over the texels of the environment box-filtered to
    ``Ns = min(N, 2^ceil(log2(2.5 sqrt(lam))))`` texels per face edge (>= 8;
    texels at most ~0.6 of the lobe width ``1/sqrt(lam)``; each coarse texel sits
    at the luminance-weighted mean direction of its children), evaluated at all
    ``N x N`` texel centres of the output; sharp kernels only gather sources
    within their e^-20 support (:func:`_sg_convolve`).

    :meth:`lookup` interpolates linearly in ``log lam`` between levels
    (linearly in ``lam`` below ``lam_1`` and in ``1/lam`` above the last
    finite level) and bilinearly within a face (edge-clamped, no filtering
    across faces).  :meth:`inner_product` gives eq. 35: ``mu Gamma_L(p, lam)``.
    """

    def __init__(self, cube_radiance, cube: Cubemap, lambdas=None, lambda_first: float = 0.125,
                 ratio: float = math.sqrt(2.0)):
        L = check_radiance(cube_radiance, cube)
        N = cube.resolution
        self.resolution = N
        if lambdas is None:
            top = (2.0 * N / math.pi) ** 2
            k = int(math.floor(math.log(top / lambda_first) / math.log(ratio) + 1e-9))
            finite = lambda_first * ratio ** np.arange(k + 1)
        else:
            finite = np.asarray(sorted(float(x) for x in lambdas if 0 < x < np.inf))
            r = finite[1:] / finite[:-1] if finite.size > 1 else np.array([ratio])
            if finite.size < 1 or not np.allclose(r, r[0]) or r[0] <= 1.0:
                raise ValueError("lambdas must be a geometric ladder (positive, finite, increasing)")
            ratio = float(r[0])
        self.lambda_first = float(finite[0])
        self.ratio = float(ratio)
        self.lambdas = np.concatenate([[0.0], finite, [np.inf]])
        n_levels = self.lambdas.size
        levels = np.empty((n_levels, 6, N, N, 3), dtype=np.float32)
        w = cube.solid_angles
        mean = (L * w[:, None]).sum(axis=0) / w.sum()
        levels[0] = mean.astype(np.float32)
        out_dirs = np.asarray(cube.directions)
        for li, lam in enumerate(finite, start=1):
            Ns = 8
            while Ns < N and Ns < 2.5 * math.sqrt(lam):
                Ns *= 2
            Ns = min(Ns, N)
            Ls, sdirs, sw = _downsample(L, N, Ns)
            res = _sg_convolve(out_dirs, sdirs, sw, Ls, float(lam))
            levels[li] = res.reshape(6, N, N, 3).astype(np.float32)
        levels[-1] = L.reshape(6, N, N, 3).astype(np.float32)
        self.levels = levels

    @property
    def n_levels(self) -> int:
        return self.levels.shape[0]

    def level_coordinate(self, lam):
        """Fractional level index of sharpness ``lam`` (the GLSL twin computes the same)."""
        lam = np.maximum(np.asarray(lam, dtype=np.float64), 0.0)
        top = self.lambdas[-2]
        nf = self.n_levels - 2                      # finite levels 1..nf
        low = lam / self.lambda_first               # [0, 1) below lam_1
        mid = 1.0 + np.log(np.maximum(lam, self.lambda_first) / self.lambda_first) / math.log(self.ratio)
        high = nf + 1.0 - top / np.maximum(lam, top)  # in [nf, nf + 1)
        return np.where(lam < self.lambda_first, low, np.where(lam <= top, mid, high))

    def lookup(self, directions, lam, rotation=None):
        """Kernel-weighted mean radiance ``Gamma_L(p, lam) / int G(.; p, lam, 1)`` (P, 3)
        for world directions ``p`` (P, 3) and sharpnesses ``lam`` (P,).
        ``rotation``: the world's ``R`` (texture direction = ``R p``)."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        if rotation is not None:
            d = d @ np.asarray(rotation, dtype=np.float64).T
        lam = np.broadcast_to(np.asarray(lam, dtype=np.float64), d.shape[:1])
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(lam))):
            raise ValueError("lookup directions/sharpnesses must be finite")
        face, s, t = face_coordinates(d)
        x = self.level_coordinate(lam)
        l0 = np.minimum(np.floor(x).astype(np.int64), self.n_levels - 1)
        l1 = np.minimum(l0 + 1, self.n_levels - 1)
        f = (x - l0)[:, None]
        out = np.zeros((d.shape[0], 3))
        for l in np.unique(np.concatenate([l0, l1])):
            wgt = np.where(l0 == l, 1.0 - f[:, 0], 0.0) + np.where(l1 == l, f[:, 0], 0.0)
            sel = np.flatnonzero(wgt > 0.0)
            if sel.size:
                out[sel] += face_bilinear(self.levels[l], face[sel], s[sel], t[sel]) * wgt[sel, None]
        return out

    def inner_product(self, axes, lam, mu, rotation=None):
        """Eq. 35: ``G(i; p, lam, mu) . L = mu int G(.; p, lam, 1) * lookup(p, lam)`` (P, 3)."""
        lam = np.asarray(lam, dtype=np.float64)
        mean = self.lookup(axes, lam.reshape(-1), rotation)
        k = core_sg.integral(lam.reshape(-1), 1.0)[:, None]
        mu = np.asarray(mu, dtype=np.float64).reshape(-1, np.shape(mu)[-1] if np.ndim(mu) > 1 else 1)
        return (mu * k * mean).reshape(np.shape(lam) + (3,))

    def atlas(self):
        """The levels as one RGBA32F image for the GPU: (n_levels * 6 * N, N, 4),
        row ``(level * 6 + face) * N + row``, column ``col`` (alpha = 1)."""
        n, N = self.n_levels, self.resolution
        out = np.ones((n * 6 * N, N, 4), dtype=np.float32)
        out[..., :3] = self.levels.reshape(n * 6 * N, N, 3)
        return out
