"""WAVELET: Haar wavelets on the cube faces -- Ng 03 non-linear lighting approximation
for the diffuse part, Ng 04 triple product for the glossy part (core/wavelet.py)."""

from __future__ import annotations

import numpy as np

from ...core import brdf, directions, haar, reference, wavelet
from .. import drawing, keys
from . import Method, glossy_or_layered, register

# Sparse Haar transport per (object, visibility, kept terms).
_TRANSFER_CACHE = keys.cache(8)
# Lighting approximations per (lighting key, kept terms); the newest few.
_LIGHT_CACHE = keys.cache(4)


def _lighting(state, cube_lighting, terms: int) -> wavelet.LightingApproximation:
    key = (keys.env_key(state.world, state.resolution), int(terms))
    return keys.held(_LIGHT_CACHE, key, (),
                     lambda: wavelet.LightingApproximation(cube_lighting.radiance, terms))


class WaveletMethod(Method):
    id = "WAVELET"
    label = "Haar Wavelets"
    description = ("Haar wavelets on the cube faces: the lighting's N largest terms for "
                   "diffuse transfer (Ng 2003), a triple product keeping a fraction of the "
                   "lighting and BRDF coefficients for glossy materials (Ng 2004)")
    budget = ("wavelet_terms", [32, 128, 512, 2048])

    def budget_between(self, lower, upper):
        """Term count at the geometric mean (the values are spaced by factors)."""
        mid = int(round(float(np.sqrt(float(lower) * float(upper)))))
        return mid if lower < mid < upper else None

    def scene_properties(self):
        from bpy.props import FloatProperty, IntProperty
        upd = drawing.redraw_viewports
        return {
            "wavelet_terms": IntProperty(
                name="Lighting Terms", default=256, min=1, max=98304, update=upd,
                description="Haar coefficients of the lighting kept for diffuse transfer "
                            "(non-linear approximation: the largest ones)"),
            "wavelet_glossy_percent": FloatProperty(
                name="Glossy Kept %", default=1.0, min=0.01, max=100.0, precision=2,
                update=upd, subtype="PERCENTAGE",
                description="Percentage of the lighting's and of each BRDF's Haar "
                            "coefficients kept in the glossy triple product"),
            "wavelet_transfer_percent": FloatProperty(
                name="Transport Kept %", default=10.0, min=0.1, max=100.0, precision=1,
                update=upd, subtype="PERCENTAGE",
                description="Percentage of each point's diffuse transport coefficients "
                            "stored (the largest ones)"),
        }

    def view_dependent(self, state) -> bool:
        return glossy_or_layered(state)

    def shade(self, state, eye, view_dir):
        cube = directions.cubemap(state.resolution)
        L = keys.environment_cubemap(state.world, state.resolution)
        settings = state.settings
        diffuse_light = _lighting(state, L, settings["wavelet_terms"])
        glossy_terms = haar.keep_count(settings["wavelet_glossy_percent"] / 100.0, cube.resolution)
        transfer_terms = haar.keep_count(settings["wavelet_transfer_percent"] / 100.0,
                                         cube.resolution)
        out = []
        n = len(state.objects)
        for i, st in enumerate(state.objects):
            pts = st.points
            state.tick(i / n)
            tick = reference.part(state.tick, i / n, (i + 1) / n)
            transfer = keys.per_visibility(
                _TRANSFER_CACHE, (st.name, id(st.bits), transfer_terms), st.bits,
                lambda: wavelet.diffuse_transfer(st.bits, pts.normals, cube, transfer_terms,
                                                 tick=reference.part(tick, 0.0, 0.5)),
                limit=8)
            irradiance = wavelet.diffuse_irradiance(transfer, diffuse_light)
            radiance = np.zeros((pts.count, 3), dtype=np.float32)
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = brdf.slot_material(st.materials, slot)
                vd = None
                if mat.fresnel == "DIELECTRIC" or not mat.is_diffuse_only:
                    vd = reference.point_views(pts.positions[sel], eye, view_dir)
                radiance[sel] = reference.lambert_layer(mat, irradiance[sel], pts.normals[sel],
                                                        vd)
                if not mat.is_diffuse_only:
                    glossy_light = _lighting(state, L, glossy_terms)
                    radiance[sel] += wavelet.glossy_radiance(
                        st.bits[sel], pts.normals[sel], vd, cube, L, mat, glossy_light,
                        glossy_terms, tick=reference.part(tick, 0.5, 1.0))
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out


register(WaveletMethod())
