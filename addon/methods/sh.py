"""SH: diffuse shadowed transfer in spherical harmonics (Sloan et al. 2002)."""

from __future__ import annotations

import numpy as np

from ...core import brdf, directions, reference, sh
from .. import runtime
from . import Method, register

# SH transfer vectors per (object, visibility, order).
_TRANSFER_CACHE: dict = {}
# SH lighting projectors per order (each caches its unrotated projection).
_PROJECTORS: dict = {}


class SHMethod(Method):
    id = "SH"
    label = "Spherical Harmonics"
    description = ("Diffuse shadowed transfer in spherical harmonics (Sloan 2002): low "
                   "frequency, fastest; draws the diffuse part of materials only")
    budget = ("sh_order", [2, 3, 4, 5])

    def scene_properties(self):
        from bpy.props import IntProperty
        return {"sh_order": IntProperty(
            name="SH Order", default=4, min=2, max=5, update=runtime.redraw_viewports,
            description="Spherical-harmonic bands kept by the SH method (order n: n*n "
                        "coefficients)")}

    def shade(self, state, eye, view_dir):
        order = int(state.settings["sh_order"])
        cube = directions.cubemap(state.resolution)
        projector = _PROJECTORS.setdefault(order, sh.LightingProjector(order))
        light = projector.coefficients(state.world, runtime.env_key(state.world, 0)[0])
        out = []
        glossy = []
        n = len(state.objects)
        for i, st in enumerate(state.objects):
            pts = st.points
            state.tick(i / n)
            transfer = runtime.per_visibility(
                _TRANSFER_CACHE, (st.name, id(st.bits), order), st.bits,
                lambda: sh.transfer(st.bits, pts.normals, cube, order,
                                    tick=lambda f: state.tick((i + f) / n)))
            sums = sh.shade_diffuse(transfer, light)
            radiance = np.zeros_like(sums)
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = st.materials[int(slot)] if 0 <= slot < len(st.materials) else brdf.Material()
                vd = None
                if mat.fresnel == "DIELECTRIC":
                    if view_dir is not None:
                        vd = np.broadcast_to(np.asarray(view_dir, np.float64), (len(sel), 3))
                    else:
                        vd = reference.view_directions(pts.positions[sel], eye)
                radiance[sel] = reference.lambert_layer(mat, sums[sel], pts.normals[sel], vd)
                if not mat.is_diffuse_only:
                    glossy.append(st.name)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        if glossy:
            state.note("SH draws diffuse transfer only; the glossy part of these materials is "
                       "left out: " + ", ".join(sorted(set(glossy))))
        return out


register(SHMethod())
