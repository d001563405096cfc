# SPDX-License-Identifier: GPL-3.0-or-later
r"""Lighting for the SG renderer of Wang et al. 2009 (§6).

Equation numbers are that paper's; SG lobes are
``G(i; axis, lam, mu) = mu exp(lam (i . axis - 1))`` (eq. 2, :mod:`.sg`).

* :func:`fit_environment_sgs` -- the SG mixture ``L*`` of the environment used
  by the *diffuse* term (eq. 39): a few lobes that keep the irradiance;
  :func:`fit_scene_amplitudes` re-solves their amplitudes for a scene's points.
* :class:`PrefilteredEnvironment` -- ``Gamma_L(p, lam)`` of eq. 34-35 for the
  *specular* term: the environment convolved with SG kernels of a ladder of
  sharpnesses, a "MIPMAP of cubemaps" indexed by ``lam``.
* :func:`lamp_sgs` -- point / spot / sun lamps as one SG each (eq. 32-33).

World rotation: everything here works on the *unrotated* environment (texture
space: a ``WorldLighting`` with ``rotation = I`` resampled to the cubemap).  A
world direction ``d`` reads texture direction ``R d`` with ``R =
WorldLighting.rotation``; :meth:`PrefilteredEnvironment.lookup` takes that
``rotation``, so turning the HDRI needs no refilter, and the diffuse SG axes
rotate by ``R^T`` (:func:`rotate_to_world`, eq. 7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import sg as core_sg
from .directions import Cubemap, cubemap, direction_to_texel, face_coordinates
from .fitting import nonnegative_least_squares

__all__ = [
    "fit_environment_sgs", "fit_scene_amplitudes", "environment_irradiance", "sg_mixture_radiance",
    "rotate_to_world", "PrefilteredEnvironment", "face_coordinates",
    "Lamp", "lamp_sgs", "lamp_irradiance", "LAMP_LAMBDA_MAX", "ENV_LAMBDA_CANDIDATES",
]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: sharpness ladder the greedy environment fit chooses from (capped by the cubemap).
ENV_LAMBDA_CANDIDATES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0,
                         1024.0, 2048.0, 4096.0)


def _check_radiance(cube_radiance, cube: Cubemap):
    L = np.asarray(cube_radiance, dtype=np.float64)
    if L.shape != (cube.size, 3):
        raise ValueError(f"cube_radiance must be ({cube.size}, 3), got {L.shape}")
    if not np.all(np.isfinite(L)):
        raise ValueError("environment radiance has NaN/Inf texels")
    return np.maximum(L, 0.0)


def _lobe_matrix(dirs, axes, lam):
    """(D, J) values of unit-amplitude lobes at ``dirs`` (D, 3)."""
    d = dirs @ np.asarray(axes, dtype=np.float64).T
    return np.exp(np.asarray(lam, dtype=np.float64)[None, :] * (np.minimum(d, 1.0) - 1.0))


def sg_mixture_radiance(dirs, axes, lam, mu):
    """``sum_j G(d; axes_j, lam_j, mu_j)`` (D, 3) for directions (D, 3)."""
    return _lobe_matrix(np.asarray(dirs, dtype=np.float64), axes, lam) @ np.asarray(mu, dtype=np.float64)


def _irradiance_operator(cube: Cubemap, normal_resolution: int = 8):
    normals = cubemap(normal_resolution).directions
    C = np.maximum(normals @ np.asarray(cube.mean_directions).T, 0.0) * cube.solid_angles[None, :]
    return normals, C


def environment_irradiance(cube_radiance, cube: Cubemap, normals):
    """Unshadowed irradiance ``E(n) = sum_k L_k max(0, n . w_k) dw_k`` (exact cube sum)."""
    L = _check_radiance(cube_radiance, cube)
    C = np.maximum(np.asarray(normals, dtype=np.float64) @ np.asarray(cube.mean_directions).T, 0.0)
    return (C * cube.solid_angles[None, :]) @ L


def rotate_to_world(axes, rotation):
    """Texture-space lobe axes -> world (``d_tex = R d_world``, so ``p_world = R^T p_tex``; eq. 7)."""
    return np.asarray(axes, dtype=np.float64) @ np.asarray(rotation, dtype=np.float64)


#: the diffuse SG fit scores broad lobes (and its irradiance) on the cubemap box-filtered
#: to this resolution; sharp lobes on the full one.
FIT_RESOLUTION = 32


def _box_down(values, N, Ns, w):
    """Solid-angle weighted mean of per-texel values (6N^2, C) over Ns-cube texels."""
    f = N // Ns
    v = (values.reshape(6, N, N, -1) * w.reshape(6, N, N, 1)).reshape(6, Ns, f, Ns, f, -1)
    ws = w.reshape(6, Ns, f, Ns, f).sum(axis=(2, 4))
    return (v.sum(axis=(2, 4)) / ws[..., None]).reshape(6 * Ns * Ns, -1)


def fit_environment_sgs(cube_radiance, cube: Cubemap, max_lobes: int = 8, tol: float = 0.03):
    """SG mixture ``L*(i) = sum_j G(i; p_j, lam_j, mu_j)`` of an environment for the
    diffuse term (§6, after Tsai & Shih 2006): few lobes, brightest areas first.

    1. Greedy on the radiance: each new lobe is the (axis, sharpness) with the
       largest reduction of the luminance residual, ``<g, r>^2/<g, g>``.  Broad
       candidates: the texels of a 6x8^2 cubemap with the sharpnesses of
       :data:`ENV_LAMBDA_CANDIDATES` up to ``(32/pi)^2``, scored on the residual
       box-filtered to a 6x32^2 cube; sharp candidates: the brightest residual
       texel of the given cube with every sharpness up to ``(N/pi)^2`` (a lobe
       about one texel wide), scored on the full cube -- so a small sun gets a lobe
       as sharp as the cube resolves and casts a sharp shadow through eq. 30.  The
       residual is then the luminance minus its solid-angle weighted non-negative
       least-squares fit by the chosen lobes (on the full cube).
    2. RGB amplitudes by non-negative least squares on the **irradiance** over the
       normals of a 6x8^2 cubemap -- what eq. 39 uses (a scene-aware re-solve of
       them is :func:`fit_scene_amplitudes`).
    3. Stop when the relative L2 error of that irradiance is <= ``tol``, or at
       ``max_lobes``.  Lobes are only added, so the radiance residual never grows
       (no joint non-linear refinement of axes and sharpnesses: it can diverge;
       docs/measurements.md, SSDF_SG).

    Returns ``(axes (J, 3), lam (J,), mu (J, 3), rel_error)`` in the cube's
    space (texture space for an unrotated world).  A black world gives J = 0.
    """
    L = _check_radiance(cube_radiance, cube)
    N = cube.resolution
    dirs = np.asarray(cube.directions, dtype=np.float64)
    w = np.asarray(cube.solid_angles, dtype=np.float64)
    sw = np.sqrt(w)
    Nc = FIT_RESOLUTION if (N > FIT_RESOLUTION and N % FIT_RESOLUTION == 0) else N
    coarse = cubemap(Nc)
    dirs_c = np.asarray(coarse.directions, dtype=np.float64)
    w_c = np.asarray(coarse.solid_angles, dtype=np.float64)
    L_c = L if Nc == N else _box_down(L, N, Nc, w)
    normals, C = _irradiance_operator(coarse)
    E = C @ L_c
    En = math.sqrt(float(np.sum(E * E)))
    empty = (np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), 0.0)
    if En <= 0.0:
        return empty
    Y = L @ LUMINANCE
    cap_c = max(ENV_LAMBDA_CANDIDATES[0], (Nc / math.pi) ** 2)
    cap_f = max(ENV_LAMBDA_CANDIDATES[0], (N / math.pi) ** 2)
    lams_c = np.array([x for x in ENV_LAMBDA_CANDIDATES if x <= cap_c] or [ENV_LAMBDA_CANDIDATES[0]])
    lams_f = np.array([x for x in ENV_LAMBDA_CANDIDATES if x <= cap_f] or [ENV_LAMBDA_CANDIDATES[0]])
    cand = np.asarray(cubemap(8).directions, dtype=np.float64)
    dot_c = cand @ dirs_c.T                                    # (384, Dc)
    axes, lamv = [], []
    rel, mu = 1.0, np.zeros((0, 3))
    residual = Y.copy()

    def best_of(cands, dots, lams, r, wt, best):
        rw = r * wt
        for lm in lams:
            G = np.exp(lm * (dots - 1.0))
            num = G @ rw
            den = (G * G) @ wt
            gain = np.where(num > 0, num * num / den, 0.0)
            k = int(np.argmax(gain))
            if best is None or gain[k] > best[0]:
                best = (gain[k], cands[k], lm)
        return best

    while len(axes) < max_lobes:
        r_c = residual if Nc == N else _box_down(residual[:, None], N, Nc, w)[:, 0]
        best = best_of(cand, dot_c, lams_c, r_c, w_c, None)
        brightest = dirs[int(np.argmax(residual))]
        best = best_of(brightest[None], (brightest @ dirs.T)[None], lams_f, residual, w, best)
        if best is None or best[0] <= 0.0:
            break
        axes.append(best[1])
        lamv.append(float(best[2]))
        G = _lobe_matrix(dirs, np.array(axes), np.array(lamv))           # (D, J)
        residual = Y - G @ nonnegative_least_squares(G * sw[:, None], Y * sw)
        A = C @ (G if Nc == N else _box_down(G, N, Nc, w))
        mu = np.stack([nonnegative_least_squares(A, E[:, c]) for c in range(3)], axis=1)
        rel = math.sqrt(float(np.sum(np.square(A @ mu - E)))) / En
        if rel <= tol:
            break
    if not axes:
        return empty
    return np.array(axes), np.array(lamv), mu, rel


def fit_scene_amplitudes(transfer, target, row_weights=None, prior=None,
                         prior_weight: float = 0.0):
    """RGB amplitudes ``mu`` (J, 3) of fixed light lobes that best reproduce the
    shading at a set of scene points: ``argmin_{mu >= 0} sum_s w_s |T_s mu - E_s|^2
    + a |mu - prior|^2`` per channel (non-negative least squares).

    ``transfer`` (S, J): each unit-amplitude lobe's diffuse transfer at the points
    as the renderer computes it (for SSDF_SG, eq. 39 with the SSDF visibility:
    ``core.ssdf_sg.diffuse_lobe_transfer``); ``target`` (S, 3) the exact shadowed
    irradiance there (``core.reference.diffuse_irradiance``); ``row_weights`` (S,)
    or (S, 3) non-negative (e.g. surface area times diffuse albedo).  ``prior``
    (J, 3) with ``prior_weight`` > 0 adds a ridge toward it, ``a = prior_weight *
    mean diagonal of T^T W T`` (what few points cannot decide stays near the
    prior, e.g. the environment fit's amplitudes).  The lobes' axes and sharpnesses
    come from the environment (:func:`fit_environment_sgs`); only their amplitudes
    are chosen for the scene, so that the error that reaches the image -- fit,
    clamped-cosine and visibility approximations together -- is the one minimised."""
    T = np.asarray(transfer, dtype=np.float64)
    Et = np.asarray(target, dtype=np.float64)
    S, J = T.shape
    if Et.shape != (S, 3):
        raise ValueError(f"target must be ({S}, 3), got {Et.shape}")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(Et))):
        raise ValueError("transfer/target have NaN/Inf values")
    w = np.ones((S, 3)) if row_weights is None else np.broadcast_to(
        np.asarray(row_weights, dtype=np.float64).reshape(S, -1), (S, 3))
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("row_weights must be finite and >= 0")
    if prior is not None:
        prior = np.asarray(prior, dtype=np.float64).reshape(J, 3)
        if not (np.all(np.isfinite(prior)) and np.isfinite(prior_weight) and prior_weight >= 0):
            raise ValueError("prior/prior_weight must be finite (weight >= 0)")
    sw = np.sqrt(w)
    out = np.zeros((J, 3))
    for c in range(3):
        A, b = T * sw[:, c:c + 1], Et[:, c] * sw[:, c]
        if prior is not None and prior_weight > 0 and J:
            a = prior_weight * float(np.sum(A * A)) / J
            A = np.vstack([A, math.sqrt(a) * np.eye(J)])
            b = np.concatenate([b, math.sqrt(a) * prior[:, c]])
        out[:, c] = nonnegative_least_squares(A, b)
    return out


# --------------------------------------------------------------------------- prefiltered environment

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
    return _box_down(L, N, Ns, fine.solid_angles), dirs.reshape(-1, 3), ws.reshape(-1)


def _bilinear(level, face, s, t):
    """Bilinear lookup within a face (edge-clamped) of a (6, N, N, C) array --
    the same arithmetic as ``shaders/sg_common.glsl``'s texelFetch version."""
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


#: kernel values below e^-KERNEL_CUTOFF of the peak are skipped by the local convolution.
KERNEL_CUTOFF = 20.0


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
        L = _check_radiance(cube_radiance, cube)
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
                out[sel] += _bilinear(self.levels[l], face[sel], s[sel], t[sel]) * wgt[sel, None]
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


# --------------------------------------------------------------------------- lamps (eq. 32-33)

#: sharpness given to lamps of zero size (eq. 32 would be infinite).
LAMP_LAMBDA_MAX = 1e5


@dataclass
class Lamp:
    """A Blender lamp in Cycles' units.

    kind:      "POINT", "SPOT", "SUN" or "AREA".
    color:     RGB colour times power (POINT/SPOT/AREA, watts) or strength (SUN, W/m^2
               = irradiance at normal incidence).
    position:  world position (POINT/SPOT; AREA: its centre).
    direction: unit direction the lamp shines *towards* (SUN/SPOT/AREA: the object's -Z).
    radius:    sphere radius (POINT/SPOT, ``shadow_soft_size``).
    angle:     angular diameter (SUN).
    spot_size, spot_blend: SPOT cone (full angle) and blend.
    half_x, half_y: AREA: the world vectors from its centre to the middle of its edges
               (its local x and y axes times half its size, object scale included).
    shape:     AREA: "SQUARE", "RECTANGLE", "DISK" or "ELLIPSE".
    """

    kind: str
    color: tuple = (1.0, 1.0, 1.0)
    position: tuple = (0.0, 0.0, 0.0)
    direction: tuple = (0.0, 0.0, -1.0)
    radius: float = 0.1
    angle: float = 0.00918
    spot_size: float = math.radians(45.0)
    spot_blend: float = 0.15
    half_x: tuple = (0.0, 0.0, 0.0)
    half_y: tuple = (0.0, 0.0, 0.0)
    shape: str = "SQUARE"

    def __post_init__(self):
        self.kind = str(self.kind).upper()
        if self.kind not in ("POINT", "SPOT", "SUN", "AREA"):
            raise ValueError(f"lamp kind must be POINT, SPOT, SUN or AREA, got {self.kind!r}")
        vals = [*np.ravel(self.color), *np.ravel(self.position), *np.ravel(self.direction),
                self.radius, self.angle, self.spot_size, self.spot_blend,
                *np.ravel(self.half_x), *np.ravel(self.half_y)]
        if not np.all(np.isfinite(np.asarray(vals, dtype=np.float64))):
            raise ValueError("lamp has NaN/Inf parameters")
        d = np.asarray(self.direction, dtype=np.float64)
        self.direction = d / max(np.linalg.norm(d), 1e-300)

    @property
    def area(self) -> float:
        """An AREA lamp's emitting area (0 for the others)."""
        if self.kind != "AREA":
            return 0.0
        full = 4.0 * float(np.linalg.norm(np.cross(self.half_x, self.half_y)))
        return full * (math.pi / 4.0 if self.shape in ("DISK", "ELLIPSE") else 1.0)


def _spot_attenuation(lamp: Lamp, to_point):
    """Cycles' ``spot_attenuation``: smoothstep over ``(cos - cos_half) / ((1 - cos_half) blend)``."""
    cos_half = math.cos(0.5 * lamp.spot_size)
    t = to_point @ lamp.direction
    smooth = (1.0 - cos_half) * lamp.spot_blend
    if smooth <= 0.0:
        return (t > cos_half).astype(np.float64)
    x = np.clip((t - cos_half) / smooth, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def lamp_sgs(lamps, positions=None):
    """One SG per lamp (eq. 32-33) as seen from each shading point.

    * POINT/SPOT at ``l`` with radius ``r`` seen from ``x``: axis ``(l - x)/|l - x|``,
      sharpness ``f_a^{-1}(2 pi r^2 / |l - x|^2)`` (eq. 32; ``= -ln(0.1) |l-x|^2 / r^2``),
      amplitude such that the lobe's integral is the lamp's irradiance at normal
      incidence ``Phi / (4 pi |l - x|^2)`` (Cycles' point light of power ``Phi``)
      -- times the spot cone attenuation for SPOT.
    * SUN from direction ``-d`` with angular diameter ``a``: axis ``-d``, sharpness
      ``f_a^{-1}(2 pi (a/2)^2)`` (eq. 33), lobe integral = strength.

    Sharpness is capped at :data:`LAMP_LAMBDA_MAX`.  ``positions`` (P, 3) are
    needed for POINT/SPOT.  Returns ``axes (P, J, 3)``, ``lam (P, J)``,
    ``mu (P, J, 3)`` (P = 1 without positions).
    """
    lamps = list(lamps)
    if positions is None:
        if any(l.kind != "SUN" for l in lamps):
            raise ValueError("point/spot lamps need shading positions")
        x = np.zeros((1, 3))
    else:
        x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(x)):
            raise ValueError("positions have NaN/Inf values")
    P, J = x.shape[0], len(lamps)
    axes = np.zeros((P, J, 3))
    lam = np.zeros((P, J))
    mu = np.zeros((P, J, 3))
    ln_eps = -math.log(core_sg.SUPPORT_EPSILON)
    for j, lamp in enumerate(lamps):
        col = np.asarray(lamp.color, dtype=np.float64).reshape(3)
        if lamp.kind == "SUN":
            axes[:, j] = -lamp.direction
            half = 0.5 * max(lamp.angle, 0.0)
            lj = ln_eps / (half * half) if half > 0 else LAMP_LAMBDA_MAX
            lam[:, j] = min(lj, LAMP_LAMBDA_MAX)
            mu[:, j] = col / core_sg.integral(lam[0, j], 1.0)
            continue
        v = np.asarray(lamp.position, dtype=np.float64)[None, :] - x
        d2 = np.maximum(np.sum(v * v, axis=1), 1e-300)
        axes[:, j] = v / np.sqrt(d2)[:, None]
        r2 = max(lamp.radius, 0.0) ** 2
        lj = np.where(r2 > 0, ln_eps * d2 / max(r2, 1e-300), LAMP_LAMBDA_MAX)
        lam[:, j] = np.minimum(lj, LAMP_LAMBDA_MAX)
        e = 1.0 / (4.0 * math.pi * d2)
        if lamp.kind == "SPOT":
            e = e * _spot_attenuation(lamp, -axes[:, j])
        mu[:, j] = (e / core_sg.integral(lam[:, j], 1.0))[:, None] * col[None, :]
    return axes, lam, mu


def lamp_irradiance(lamp: Lamp, positions, normals, n_theta=48, n_phi=64):
    """Exact irradiance ``int L max(0, n . i) di`` of one lamp (sphere of uniform
    radiance for POINT/SPOT, disc of uniform radiance for SUN) at points with
    ``normals``, by quadrature over the lamp's solid angle (for tests).  The spot
    attenuation is taken at the lamp centre direction, as in Cycles."""
    x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    col = np.asarray(lamp.color, dtype=np.float64).reshape(3)
    if lamp.kind == "SUN":
        axis = np.broadcast_to(-lamp.direction, x.shape)
        half = np.full(x.shape[0], 0.5 * lamp.angle)
        cap = 2.0 * math.pi * (1.0 - np.cos(half))
        total = np.broadcast_to(col, (x.shape[0], 3))          # strength = E at normal incidence
        radiance_scale = 1.0 / np.maximum(cap, 1e-300)[:, None]
    else:
        v = np.asarray(lamp.position, dtype=np.float64)[None, :] - x
        dist = np.linalg.norm(v, axis=1)
        axis = v / dist[:, None]
        half = np.arcsin(np.clip(lamp.radius / dist, 0.0, 1.0))
        cap = 2.0 * math.pi * (1.0 - np.cos(half))
        # sphere of radiance Lr: E_normal = Lr pi sin^2(half) = Phi / (4 pi d^2) (Cycles)
        e_far = 1.0 / (4.0 * math.pi * dist * dist)
        if lamp.kind == "SPOT":
            e_far = e_far * _spot_attenuation(lamp, -axis)
        radiance_scale = (e_far / np.maximum(math.pi * np.sin(half) ** 2, 1e-300))[:, None]
        total = np.broadcast_to(col, (x.shape[0], 3))
    xg, wg = np.polynomial.legendre.leggauss(n_theta)
    out = np.zeros((x.shape[0], 3))
    for p in range(x.shape[0]):
        if half[p] <= 1e-9:               # zero-size lamp: the limit E_normal * max(0, n . axis)
            e_normal = total[p] if lamp.kind == "SUN" else total[p] * e_far[p]
            out[p] = e_normal * max(float(axis[p] @ n[p]), 0.0)
            continue
        th = 0.5 * half[p] * (xg + 1.0)
        wt = 0.5 * half[p] * wg * np.sin(th)
        ph = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
        a = axis[p]
        t = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        b = np.cross(a, t)
        dirs = (np.sin(th)[:, None, None] * (np.cos(ph)[None, :, None] * t + np.sin(ph)[None, :, None] * b)
                + np.cos(th)[:, None, None] * a)
        cosn = np.maximum(dirs @ n[p], 0.0)
        val = np.sum(cosn * wt[:, None]) * (2 * math.pi / n_phi)
        out[p] = val * radiance_scale[p] * total[p]
    return out
