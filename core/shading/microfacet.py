"""Microfacet primitives as Cycles evaluates them (no bpy): the roughness -> alpha map,
the GGX and Beckmann NDFs, Smith's ``Lambda`` and ``G1``, and the Fresnel terms (dielectric,
Schlick-style IOR remaps, F82 tint).  ``core/shading/brdf.py`` builds materials and their lobes on
them (its docstring states the models); ``core/shading/brdf_tables.py`` tabulates their albedos.
"""

from __future__ import annotations

import numpy as np

#: Smallest alpha of the microfacet lobes that match Cycles (roughness ~ 0.0316; Cycles' own
#: singular threshold is lower).  The SG fits have their own floor, core.sg.ndf.SG_ALPHA_MIN.
MICROFACET_ALPHA_MIN = 1e-3

DISTRIBUTIONS = ("BECKMANN", "GGX", "MULTI_GGX")
# Floor for cosines inside Lambda (keeps tan^2 finite: <= 1e24).
_COS_FLOOR = 1e-12
# Floor for cos^2 inside the Beckmann NDF (exp(-huge) -> 0, no 0/0).
_COS2_FLOOR = 1e-30


def roughness_to_alpha(roughness: float) -> float:
    """Blender roughness -> microfacet alpha: ``max(clamp(r, 0, 1)**2, MICROFACET_ALPHA_MIN)``."""
    r = float(roughness)
    if not np.isfinite(r):
        r = 0.0
    r = min(max(r, 0.0), 1.0)
    return max(r * r, MICROFACET_ALPHA_MIN)


def check_distribution(distribution: str) -> str:
    d = str(distribution).upper()
    if d == "MULTI_GGX":
        return "GGX"
    if d not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    return d


def _clamp_alpha(alpha) -> np.ndarray:
    a = np.asarray(alpha, dtype=np.float64)
    return np.clip(np.nan_to_num(a, nan=MICROFACET_ALPHA_MIN), MICROFACET_ALPHA_MIN, None)


def microfacet_D(distribution, alpha, cos_theta_m) -> np.ndarray:
    r"""Normalised isotropic NDF ``D(m)`` evaluated at ``cos_theta_m = n.m``.

    ``integral_{hemisphere} D(m) (n.m) dm = 1``.  With ``a2 = alpha^2`` and
    ``c = cos_theta_m``::

        BECKMANN: D = exp(-(1 - c^2) / (c^2 a2)) / (pi a2 c^4)
        GGX:      D = a2 / (pi ((1 - c^2) + a2 c^2)^2)

    (Cycles ``bsdf_D``.)  ``alpha`` is floored at :data:`MICROFACET_ALPHA_MIN`; ``D = 0``
    for ``c <= 0``.  Returns ``float64`` with the broadcast shape of the inputs.
    """
    dist = check_distribution(distribution)
    a2 = _clamp_alpha(alpha) ** 2
    c = np.asarray(cos_theta_m, dtype=np.float64)
    c2 = np.clip(c * c, 0.0, 1.0)
    s2 = 1.0 - c2
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        if dist == "BECKMANN":
            c2s = np.maximum(c2, _COS2_FLOOR)
            d = np.exp(-s2 / (c2s * a2)) / (np.pi * a2 * c2s * c2s)
        else:
            den = s2 + a2 * c2
            d = a2 / (np.pi * den * den)
    return np.where(c > 0.0, d, 0.0)


def lambda_of_t2(dist: str, t2) -> np.ndarray:
    """Cycles' Smith ``Lambda`` from ``t2 = alpha^2 tan^2(theta)``
    (``bsdf_lambda_from_sqr_alpha_tan_n``; :func:`smith_lambda` has the formulas) for
    ``dist`` "GGX" or "BECKMANN", in the dtype of ``t2`` (BLOCKS' float32 evaluator
    calls it with float32)."""
    t2 = np.asarray(t2)
    if dist == "GGX":
        return 0.5 * (np.sqrt(1.0 + t2) - 1.0)
    a = 1.0 / np.sqrt(np.maximum(t2, 0.39))
    lam = ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a)
    return np.where(t2 < 0.39, 0.0, lam)


def lambda_raw(dist: str, a2, cos_theta) -> np.ndarray:
    """Smith Lambda for ``a2 = alpha^2`` *without* the MICROFACET_ALPHA_MIN floor."""
    c = np.maximum(np.nan_to_num(np.asarray(cos_theta, dtype=np.float64), nan=0.0), _COS_FLOOR)
    c = np.minimum(c, 1.0)
    return lambda_of_t2(dist, a2 * np.maximum(1.0 / (c * c) - 1.0, 0.0))


def smith_lambda(distribution, alpha, cos_theta) -> np.ndarray:
    r"""Cycles' Smith ``Lambda`` for a direction at ``cos_theta = n.w``.

    With ``t2 = alpha^2 tan^2(theta)``::

        GGX:      Lambda = (sqrt(1 + t2) - 1) / 2                   (exact)
        BECKMANN: a = 1/sqrt(t2);
                  Lambda = (1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2)
                  if t2 >= 0.39 (a <~ 1.6), else 0                 (approximation)

    (Cycles ``bsdf_lambda`` / ``bsdf_lambda_from_sqr_alpha_tan_n``.)  The
    masking function is ``G1 = 1 / (1 + Lambda)``.  ``cos_theta`` is floored at
    ``1e-12`` (so directions at or below the horizon get a huge but finite
    Lambda, i.e. ``G1 ~ 0``).  Returns ``float64``.
    """
    dist = check_distribution(distribution)
    return lambda_raw(dist, _clamp_alpha(alpha) ** 2, cos_theta)


def smith_G1(distribution, alpha, cos_theta) -> np.ndarray:
    """Smith masking ``G1 = 1 / (1 + Lambda(cos_theta))`` (Cycles ``bsdf_G``, 2-arg form)."""
    return 1.0 / (1.0 + smith_lambda(distribution, alpha, cos_theta))


# --------------------------------------------------------------------------- #
# Fresnel terms (Cycles kernel/closure/bsdf_util.h)
# --------------------------------------------------------------------------- #

def fresnel_dielectric(cos_i, eta) -> np.ndarray:
    """Unpolarised dielectric Fresnel reflectance (Cycles ``fresnel_dielectric_cos``).

    ``eta`` is the relative IOR (transmitted over incident side); total
    internal reflection gives 1.  Uses ``|cos_i|``.  Returns ``float64``, or
    ``float32`` for a ``float32`` array input (the per-direction hot path).
    """
    c = np.abs(np.asarray(cos_i))
    if c.dtype != np.float32:
        c = c.astype(np.float64)
    shape = c.shape
    c = c.reshape(-1)
    dt = c.dtype.type
    eta = float(eta)
    g = c * c
    g += dt(eta * eta - 1.0)
    ok = g > 0.0
    np.maximum(g, dt(1e-30), out=g)
    np.sqrt(g, out=g)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        A = (g - c) / (g + c)
        gc = g * c
        B = (gc + c * c - 1.0) / (gc - c * c + 1.0)
        A *= A
        B *= B
        B += dt(1.0)
        A *= B
        A *= dt(0.5)
    A = np.nan_to_num(A, nan=1.0, copy=False)
    A[~ok] = 1.0
    return A.reshape(shape)


def F0_from_ior(ior: float) -> float:
    """``((ior - 1) / (ior + 1))^2`` (Cycles ``F0_from_ior``)."""
    ior = float(ior)
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def ior_from_F0(f0: float) -> float:
    """Inverse of :func:`F0_from_ior` for ``ior >= 1``, ``f0`` clamped to ``[0, 0.99]``."""
    s = np.sqrt(min(max(float(f0), 0.0), 0.99))
    return float((1.0 + s) / (1.0 - s))


def fresnel_dielectric_Fss(eta: float) -> float:
    """Cycles' fit of ``2 int_0^1 F_diel(mu, eta) mu dmu`` (Kulla & Conty 2017)."""
    eta = float(eta)
    if eta < 1.0:
        return 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


def f82_tint_B(f0, tint) -> np.ndarray:
    """Cycles' ``fresnel_f82tint_B``: the ``B`` of ``F82Tint = Schlick - B cos (1-cos)^6``
    such that ``F(acos(1/7)) = Schlick(acos(1/7)) * tint``."""
    f0 = np.asarray(f0, dtype=np.float64)
    tint = np.asarray(tint, dtype=np.float64)
    f = 6.0 / 7.0
    f5 = f ** 5
    schlick = f0 + (1.0 - f0) * f5
    return schlick * (7.0 / (f5 * f)) * (1.0 - tint)


def fresnel_f82(cos_i, f0, B) -> np.ndarray:
    """``saturate(mix(F0, 1, (1-c)^5) - B c (1-c)^6)`` (Cycles ``fresnel_f82``);
    ``cos_i`` (...,) with ``f0``/``B`` broadcasting against ``cos_i[..., None]``."""
    c = np.asarray(cos_i, dtype=np.float64)[..., None]
    s = np.clip(1.0 - c, 0.0, 1.0)
    s5 = s ** 5
    f0 = np.asarray(f0, dtype=np.float64)
    return np.clip(f0 + (1.0 - f0) * s5 - np.asarray(B, dtype=np.float64) * c * s5 * s, 0.0, 1.0)


def dielectric_s(cos_i, eta: float) -> np.ndarray:
    """Principled remap factor ``saturate((F_diel(cos, eta) - F0) / (1 - F0))``
    (keeps a ``float32`` input's dtype)."""
    F0 = F0_from_ior(eta)
    F = fresnel_dielectric(cos_i, eta)
    if F0 >= 1.0 - 1e-12:
        return np.ones_like(F)
    dt = F.dtype.type
    F -= dt(F0)
    F *= dt(1.0 / (1.0 - F0))
    return np.clip(F, 0.0, 1.0, out=F)


def lobe_signature(entries) -> tuple[str, ...]:
    """The shader defines of the lobe signature a draw's materials share (shaders/lib/
    microfacet.glsl: ``LOBE_DIST``, ``LOBE_COUNT``, ``LOBE_KIND0``, ``LOBE_KIND1``), so that
    a draw compiles only its own Fresnel kinds and distribution in.  ``entries``: per
    material drawn, (distribution 0 Beckmann / 1 GGX, lobe count, the first lobe's
    ``core.shading.brdf.sharp_lobes`` kind, the second's); a value the materials do not share is left to
    be read at run time.  The distribution and a lobe's kind count only where a material has
    that lobe."""
    rows = [tuple(int(round(float(v))) for v in e) for e in entries]

    def shared(values):
        values = set(values)
        return values.pop() if len(values) == 1 else None
    out = []
    for name, value in (("LOBE_DIST", shared(d for d, n, _k0, _k1 in rows if n >= 1)),
                        ("LOBE_COUNT", shared(n for _d, n, _k0, _k1 in rows)),
                        ("LOBE_KIND0", shared(k0 for _d, n, k0, _k1 in rows if n >= 1)),
                        ("LOBE_KIND1", shared(k1 for _d, n, _k0, k1 in rows if n >= 2))):
        if value is not None:
            out.append(f"{name} {value}")
    return tuple(out)
