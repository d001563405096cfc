"""Blender's lamps for SG shading (Wang et al. 2009, eq. 32-33): a lamp's position, power and
shape, its spherical Gaussians as seen from a point, and its exact unshadowed irradiance."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import algebra as core_sg
from .lighting import LAMP_LAMBDA_MAX


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
    name:      the Blender object's name (what the panel and the render log call it).
    group:     the light group whose ``Combined_<group>`` render pass it is drawn in
               (no part of its light).
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
    name: str = ""
    group: str = ""

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
