"""SH: diffuse shadowed transfer in spherical harmonics (Sloan et al. 2002)."""

from __future__ import annotations

import numpy as np

from ....core.shading import materials
from ....core.sphere import directions
from ....core.methods.reference import shading as reference
from ....core.methods.sh import harmonics as sh
from ....core.pipeline import frame_status
from ...frame import keys
from ..contract import Shading

# SH transfer vectors per (object, visibility, order).
_TRANSFER_CACHE = keys.cache(64)
# SH lighting projectors per order (each caches its unrotated projection).
_PROJECTORS = keys.cache(4)


class SHShading(Shading):


    def shade(self, state, eye, view_dir):
        order = int(state.settings["sh_order"])
        cube = directions.cubemap(state.resolution)
        projector = keys.held(_PROJECTORS, order, (), lambda: sh.LightingProjector(order))
        light = projector.coefficients(state.world, keys.env_key(state.world, 0)[0])
        out = []
        glossy = []
        n = len(state.objects)
        for i, st in enumerate(state.objects):
            pts = st.points
            state.tick(i / n)
            transfer = keys.per_visibility(
                _TRANSFER_CACHE, (st.name, id(st.bits), order), st.bits,
                lambda: sh.transfer(st.bits, pts.normals, cube, order,
                                    tick=lambda f: state.tick((i + f) / n)))
            sums = sh.shade_diffuse(transfer, light)
            radiance = np.zeros_like(sums)
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = materials.slot_material(st.materials, slot)
                vd = None
                if mat.fresnel == "DIELECTRIC":
                    vd = reference.point_views(pts.positions[sel], eye, view_dir)
                radiance[sel] = reference.lambert_layer(mat, sums[sel], pts.normals[sel], vd)
                if not mat.is_diffuse_only:
                    glossy.append(st.name)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        if glossy:
            state.note("SH draws diffuse transfer only; the glossy part of these materials is "
                       "left out: " + frame_status.listing(sorted(set(glossy))))
        return out

