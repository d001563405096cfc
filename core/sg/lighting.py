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

import numpy as np

from ..sphere.directions import Cubemap, cubemap, face_coordinates
from ..common.fitting import nonnegative_least_squares

__all__ = [
    "fit_environment_sgs", "fit_scene_amplitudes", "environment_irradiance", "sg_mixture_radiance",
    "rotate_to_world", "face_coordinates", "ENV_LAMBDA_CANDIDATES",
]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: sharpness ladder the greedy environment fit chooses from (capped by the cubemap).
ENV_LAMBDA_CANDIDATES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0,
                         1024.0, 2048.0, 4096.0)


def check_radiance(cube_radiance, cube: Cubemap):
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
    L = check_radiance(cube_radiance, cube)
    C = np.maximum(np.asarray(normals, dtype=np.float64) @ np.asarray(cube.mean_directions).T, 0.0)
    return (C * cube.solid_angles[None, :]) @ L


def rotate_to_world(axes, rotation):
    """Texture-space lobe axes -> world (``d_tex = R d_world``, so ``p_world = R^T p_tex``; eq. 7)."""
    return np.asarray(axes, dtype=np.float64) @ np.asarray(rotation, dtype=np.float64)


#: the diffuse SG fit scores broad lobes (and its irradiance) on the cubemap box-filtered
#: to this resolution; sharp lobes on the full one.
FIT_RESOLUTION = 32


def box_down(values, N, Ns, w):
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
    L = check_radiance(cube_radiance, cube)
    N = cube.resolution
    dirs = np.asarray(cube.directions, dtype=np.float64)
    w = np.asarray(cube.solid_angles, dtype=np.float64)
    sw = np.sqrt(w)
    Nc = FIT_RESOLUTION if (N > FIT_RESOLUTION and N % FIT_RESOLUTION == 0) else N
    coarse = cubemap(Nc)
    dirs_c = np.asarray(coarse.directions, dtype=np.float64)
    w_c = np.asarray(coarse.solid_angles, dtype=np.float64)
    L_c = L if Nc == N else box_down(L, N, Nc, w)
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
        r_c = residual if Nc == N else box_down(residual[:, None], N, Nc, w)[:, 0]
        best = best_of(cand, dot_c, lams_c, r_c, w_c, None)
        brightest = dirs[int(np.argmax(residual))]
        best = best_of(brightest[None], (brightest @ dirs.T)[None], lams_f, residual, w, best)
        if best is None or best[0] <= 0.0:
            break
        axes.append(best[1])
        lamv.append(float(best[2]))
        G = _lobe_matrix(dirs, np.array(axes), np.array(lamv))           # (D, J)
        residual = Y - G @ nonnegative_least_squares(G * sw[:, None], Y * sw)
        A = C @ (G if Nc == N else box_down(G, N, Nc, w))
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
    ``core.methods.ssdf_sg.shading.diffuse_lobe_transfer``); ``target`` (S, 3) the exact shadowed
    irradiance there (``core.methods.reference.shading.diffuse_irradiance``); ``row_weights`` (S,)
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


#: kernel values below e^-KERNEL_CUTOFF of the peak are skipped by the local convolution.
KERNEL_CUTOFF = 20.0


# --------------------------------------------------------------------------- lamps (eq. 32-33)

#: sharpness given to lamps of zero size (eq. 32 would be infinite).
LAMP_LAMBDA_MAX = 1e5


