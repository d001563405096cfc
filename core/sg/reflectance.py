"""An SG material's parameters (Wang et al. 2009 §4): the Lambert base, the NDF model and its
roughness or anisotropy, the Fresnel mode, the Principled inputs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ndf import SG_ALPHA_MIN, FRESNEL_MODES, MODELS


def _rgb_array(v, name):
    a = np.asarray(v, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"{name} must have 3 components in its last axis, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN/Inf values")
    return a


def _positive_array(v, name, floor):
    a = np.asarray(v, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN/Inf values")
    return np.maximum(a, floor)


@dataclass
class SGMaterial:
    """Parameters of one SG-represented BRDF (eq. 8 with a microfacet ``rho_s``, eq. 9).

    Per-point (textured) values may be arrays broadcastable to ``(P,)`` for
    scalars and ``(P, 3)`` for colours.

    model:      one of :data:`MODELS`.
    diffuse:    Lambert albedo (``kd = diffuse / pi``); for ``fresnel="PRINCIPLED"``
                the Principled base colour (also the metal F0).
    specular:   ``ks`` (colour of the specular lobe; F0 for ``"SCHLICK"``, the
                dielectric ``f0`` colour for ``"PRINCIPLED"``).
    roughness:  slope ``a`` of the isotropic models (module docstring).
    alpha_x, alpha_y:  ``WARD_ANISO`` slopes along the tangent / bitangent.
    nu, nv:     ``ASHIKHMIN_SHIRLEY`` exponents along the tangent / bitangent.
    fresnel:    one of :data:`FRESNEL_MODES`.
    ior:        relative index of refraction ``eta`` of eq. 14.
    metallic:   ``"PRINCIPLED"`` metal weight.
    multiscatter: scale the lobes by Cycles' multiple-scattering energy compensation
                (Multiscatter GGX): :func:`multiscatter_factors`.
    lobes:      False when the glossy lobes are drawn elsewhere (per pixel,
                :func:`without_glossy`): only the Lambert base is shaded from this material.
    """

    model: str = "COOK_TORRANCE"
    diffuse: object = (0.8, 0.8, 0.8)
    specular: object = (0.04, 0.04, 0.04)
    roughness: object = 0.3
    alpha_x: float = 0.3
    alpha_y: float = 0.1
    nu: float = 75.0
    nv: float = 1200.0
    fresnel: str = "NONE"
    ior: object = 1.5
    metallic: object = 0.0
    multiscatter: bool = False
    lobes: bool = True

    def __post_init__(self):
        self.model = str(self.model).upper()
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        self.fresnel = str(self.fresnel).upper()
        if self.fresnel not in FRESNEL_MODES:
            raise ValueError(f"fresnel must be one of {FRESNEL_MODES}, got {self.fresnel!r}")
        self.diffuse = np.maximum(_rgb_array(self.diffuse, "diffuse"), 0.0)
        self.specular = np.maximum(_rgb_array(self.specular, "specular"), 0.0)
        self.roughness = _positive_array(self.roughness, "roughness", SG_ALPHA_MIN)
        self.alpha_x = float(_positive_array(self.alpha_x, "alpha_x", SG_ALPHA_MIN))
        self.alpha_y = float(_positive_array(self.alpha_y, "alpha_y", SG_ALPHA_MIN))
        self.nu = float(_positive_array(self.nu, "nu", 0.0))
        self.nv = float(_positive_array(self.nv, "nv", 0.0))
        self.ior = _positive_array(self.ior, "ior", 1e-3)
        self.metallic = np.clip(_positive_array(self.metallic, "metallic", 0.0), 0.0, 1.0)
        self.multiscatter = bool(self.multiscatter)

    @property
    def is_anisotropic(self) -> bool:
        return self.model in ("WARD_ANISO", "ASHIKHMIN_SHIRLEY")

    def aniso_params(self):
        """``(a, b)``: (alpha_x, alpha_y) or (nu, nv)."""
        if self.model == "WARD_ANISO":
            return self.alpha_x, self.alpha_y
        return self.nu, self.nv
