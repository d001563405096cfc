"""Cycles' surfaces as core materials: a Lambert base with one microfacet lobe or the
Principled layering, the Principled inputs' remaps, the default surface and the slot a face
is drawn with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .microfacet import DISTRIBUTIONS, F0_from_ior, ior_from_F0, roughness_to_alpha

_FRESNELS = ("NONE", "SCHLICK", "DIELECTRIC", "F82")


def _rgb(v, name):
    t = tuple(float(x) for x in v)
    if len(t) != 3:
        raise ValueError(f"{name} must have 3 components")
    return tuple(x if np.isfinite(x) else 0.0 for x in t)


@dataclass(frozen=True)
class Material:
    """Lambert base + one microfacet-glossy lobe (or Cycles' Principled layering).

    Attributes
    ----------
    diffuse_albedo:
        RGB reflectance ``rho`` of the Lambert lobe; the BRDF is ``rho / pi``
        (times :func:`diffuse_view_weight`, which is 1 except for
        ``fresnel="DIELECTRIC"``, where ``diffuse_albedo`` is the Principled
        base colour).
    specular_color:
        ``fresnel="NONE"``: the Glossy BSDF colour (closure weight);
        ``"SCHLICK"``/``"F82"``: ``F0``; ``"DIELECTRIC"``: the generalized-Schlick
        ``f0 = F0_from_ior(ior) * specular_tint`` (Cycles' ``fresnel->f0``).
        For ``"NONE"``/``"SCHLICK"`` all zero disables the glossy lobe (see
        :attr:`is_diffuse_only`).
    roughness:
        Blender roughness ``r``; ``alpha = clamp(r, 0, 1)**2``, floored at
        :data:`MICROFACET_ALPHA_MIN` for the lobe (the tables use ``clamp(r, 0, 1)``).
    distribution:
        ``"BECKMANN"``, ``"GGX"`` or ``"MULTI_GGX"`` (GGX lobe with Cycles'
        multiple-scattering energy compensation).
    fresnel:
        ``"NONE"``, ``"SCHLICK"``, ``"DIELECTRIC"`` (Principled) or ``"F82"``.
    ior:
        ``"DIELECTRIC"``: relative IOR ``eta`` of the specular layer (after
        Cycles' specular-IOR-level remapping).  ``eta == 1`` means no layer.
    f82_tint:
        F82 tint of the metal lobe (``"F82"``, or ``"DIELECTRIC"`` with
        ``metallic > 0``); ``(1, 1, 1)`` is plain Schlick.
    metallic:
        ``"DIELECTRIC"`` only: weight of the F82 metal lobe (``F0`` =
        ``clamp(diffuse_albedo, 0, 1)``); the dielectric lobe and the base are
        scaled by ``1 - metallic``.
    per_pixel_lobe:
        The glossy lobes are narrower than the cubemap resolves (:func:`is_sharp`) and
        drawn per pixel from :func:`sharp_lobes` instead: every per-vertex evaluation
        here skips them (:attr:`is_diffuse_only` is True), the Lambert base keeps its
        Principled layering weight.
    """

    diffuse_albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    specular_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roughness: float = 0.5
    distribution: str = "BECKMANN"
    fresnel: str = "NONE"
    ior: float = 1.5
    f82_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    metallic: float = 0.0
    per_pixel_lobe: bool = False

    def __post_init__(self):
        dist = str(self.distribution).upper()
        fres = str(self.fresnel).upper()
        if dist not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {self.distribution!r}")
        if fres not in _FRESNELS:
            raise ValueError(f"fresnel must be one of {_FRESNELS}, got {self.fresnel!r}")
        object.__setattr__(self, "distribution", dist)
        object.__setattr__(self, "fresnel", fres)
        try:
            object.__setattr__(self, "diffuse_albedo", _rgb(self.diffuse_albedo, "diffuse_albedo"))
            object.__setattr__(self, "specular_color", _rgb(self.specular_color, "specular_color"))
            object.__setattr__(self, "f82_tint", _rgb(self.f82_tint, "f82_tint"))
        except TypeError as exc:
            raise ValueError(str(exc)) from exc
        object.__setattr__(self, "roughness", float(self.roughness))
        ior = float(self.ior)
        object.__setattr__(self, "ior", ior if np.isfinite(ior) and ior > 0.0 else 1.0)
        m = float(self.metallic)
        object.__setattr__(self, "metallic", min(max(m, 0.0), 1.0) if np.isfinite(m) else 0.0)

    @property
    def is_diffuse_only(self) -> bool:
        """True when there is no glossy lobe at all.

        ``"NONE"``/``"SCHLICK"``: ``specular_color`` all zero.  ``"F82"``: never.
        ``"DIELECTRIC"``: ``metallic == 0`` and no dielectric layer
        (``ior == 1``, as Cycles skips the layer for ``eta == 1``).  Also True when
        the lobes are drawn per pixel (:attr:`per_pixel_lobe`).
        """
        if self.per_pixel_lobe:
            return True
        if self.fresnel == "F82":
            return False
        if self.fresnel == "DIELECTRIC":
            return not (self._has_dielectric_lobe or self.metallic > 0.0)
        return not any(c != 0.0 for c in self.specular_color)

    @property
    def _has_dielectric_lobe(self) -> bool:
        return self.fresnel == "DIELECTRIC" and self.metallic < 1.0 and self.ior != 1.0

    @property
    def has_diffuse(self) -> bool:
        """True when the Lambert lobe can be non-zero."""
        if self.fresnel == "DIELECTRIC" and self.metallic >= 1.0:
            return False
        return any(c != 0.0 for c in self.diffuse_albedo)

    @property
    def alpha(self) -> float:
        """Microfacet alpha actually used: ``max(clamp(r,0,1)^2, MICROFACET_ALPHA_MIN)``."""
        return roughness_to_alpha(self.roughness)

    @property
    def table_roughness(self) -> float:
        """``clamp(r, 0, 1)``: the roughness coordinate of Cycles' tables."""
        r = float(self.roughness)
        return min(max(r, 0.0), 1.0) if np.isfinite(r) else 0.0

    @property
    def lobe_distribution(self) -> str:
        """NDF of the lobe: ``"GGX"`` for ``"MULTI_GGX"``."""
        return "GGX" if self.distribution == "MULTI_GGX" else self.distribution


def principled_material(base_color=(0.8, 0.8, 0.8), metallic=0.0, roughness=0.5, ior=1.5,
                        specular_ior_level=0.5, specular_tint=(1.0, 1.0, 1.0),
                        distribution="MULTI_GGX") -> Material:
    """:class:`Material` for Cycles' Principled BSDF inputs (sheen, coat,
    transmission, subsurface, emission, thin film, alpha, anisotropy and
    diffuse roughness left out).  The defaults are the node defaults, i.e.
    Cycles' default surface.  Follows ``svm_node_closure_bsdf``: clamps,
    the specular-IOR-level remap ``f0 *= 2 level; eta = ior_from_F0(f0)`` and
    ``fresnel->f0 = saturate(f0 * specular_tint)``.
    """
    base = tuple(max(float(c), 0.0) for c in tuple(base_color)[:3])
    metallic = min(max(float(metallic), 0.0), 1.0)
    roughness = min(max(float(roughness), 0.0), 1.0)
    ior_in = max(float(ior), 1e-5)
    level = max(float(specular_ior_level), 0.0)
    tint = np.maximum(np.asarray(tuple(specular_tint)[:3], dtype=np.float64), 0.0)
    eta = ior_in
    f0 = F0_from_ior(eta)
    if level != 0.5:
        f0 *= 2.0 * level
        eta = ior_from_F0(f0)
        if ior_in < 1.0:
            eta = 1.0 / eta
    dist = str(distribution).upper()
    dist = "MULTI_GGX" if dist in ("MULTI_GGX", "MULTI_GGX_GLASS") else "GGX"
    return Material(diffuse_albedo=base, specular_color=tuple(np.clip(f0 * tint, 0.0, 1.0)),
                    roughness=roughness, distribution=dist, fresnel="DIELECTRIC", ior=eta,
                    f82_tint=tuple(np.minimum(tint, 1.0)), metallic=metallic)


#: What Cycles uses for a surface without a material: a Principled BSDF with the node
#: defaults (``ShaderManager::add_default`` in ``intern/cycles/scene/shader.cpp``: base 0.8,
#: metallic 0, roughness 0.5, IOR 1.5, specular IOR level 0.5, specular tint 1,
#: Multiscatter GGX) -- not a Lambert 0.8, which is ~1-4 % off depending on the view (the
#: specular layer takes energy from the base at grazing angles).
DEFAULT_MATERIAL = principled_material()


def slot_material(table, slot):
    """The material a face of material index ``slot`` is drawn with, from the per-slot
    ``table`` of its object, as Cycles assigns it: the index clamped into the object's
    slots (``clamp_material_index`` in ``intern/cycles/blender/mesh.cc``); an object
    without slots has the default surface :data:`DEFAULT_MATERIAL`."""
    if len(table) == 0:
        return DEFAULT_MATERIAL
    return table[min(max(int(slot), 0), len(table) - 1)]
