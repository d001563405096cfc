"""WAVELET: Haar wavelets on the cube faces -- Ng 03 non-linear lighting approximation
for the diffuse part, Ng 04 triple product for the glossy part (core/methods/wavelet/transfer.py)."""

from __future__ import annotations

import numpy as np

from ....core.shading import materials
from ....core.sphere import directions
from ....core.methods.wavelet import haar, transfer as wavelet
from ....core.methods.reference import shading as reference
from ....core.common import parallel
from ...frame import keys
from ..contract import Shading, glossy_or_layered

# Sparse Haar transport per (object, visibility, kept terms).
_TRANSFER_CACHE = keys.cache(8)
# Lighting approximations per (lighting key, kept terms); the newest few.
_LIGHT_CACHE = keys.cache(4)


def _lighting(state, cube_lighting, terms: int) -> wavelet.LightingApproximation:
    key = (keys.env_key(state.world, state.resolution), int(terms))
    return keys.held(_LIGHT_CACHE, key, (),
                     lambda: wavelet.LightingApproximation(cube_lighting.radiance, terms))


class WaveletShading(Shading):



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
            tick = parallel.part(state.tick, i / n, (i + 1) / n)
            transfer = keys.per_visibility(
                _TRANSFER_CACHE, (st.name, id(st.bits), transfer_terms), st.bits,
                lambda: wavelet.diffuse_transfer(st.bits, pts.normals, cube, transfer_terms,
                                                 tick=parallel.part(tick, 0.0, 0.5)),
                limit=8)
            irradiance = wavelet.diffuse_irradiance(transfer, diffuse_light)
            radiance = np.zeros((pts.count, 3), dtype=np.float32)
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = materials.slot_material(st.materials, slot)
                vd = None
                if mat.fresnel == "DIELECTRIC" or not mat.is_diffuse_only:
                    vd = reference.point_views(pts.positions[sel], eye, view_dir)
                radiance[sel] = reference.lambert_layer(mat, irradiance[sel], pts.normals[sel],
                                                        vd)
                if not mat.is_diffuse_only:
                    glossy_light = _lighting(state, L, glossy_terms)
                    radiance[sel] += wavelet.glossy_radiance(
                        st.bits[sel], pts.normals[sel], vd, cube, L, mat, glossy_light,
                        glossy_terms, tick=parallel.part(tick, 0.5, 1.0))
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out

