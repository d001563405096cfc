"""REFERENCE: the pixel-basis triple product over every cubemap texel (exact for the
cubemap; the yardstick every other method is measured against)."""

from __future__ import annotations

import numpy as np

from ....core.sphere import directions
from ....core.methods.reference import shading as reference
from ....core.common import parallel
from ...frame import keys
from ..contract import Shading, glossy_or_layered

# View-independent diffuse sums per (object, visibility, lighting).
IRRADIANCE_CACHE = keys.cache(64)


class ReferenceShading(Shading):

    def view_dependent(self, state) -> bool:
        return glossy_or_layered(state)

    def shade(self, state, eye, view_dir):
        cube = directions.cubemap(state.resolution)
        L = keys.environment_cubemap(state.world, state.resolution)
        env_key = keys.env_key(state.world, state.resolution)
        out = []
        n = len(state.objects)
        for i, st in enumerate(state.objects):
            pts = st.points
            # progress per block of points (ESC stops between them): the irradiance is
            # the first half of an object when it is not cached, its glossy part the rest
            tick = parallel.part(state.tick, i / n, (i + 1) / n)
            state.tick(i / n)
            cached = []
            irradiance = keys.per_visibility(
                IRRADIANCE_CACHE, (st.name, id(st.bits), env_key), st.bits,
                lambda: cached.append(1) or reference.diffuse_irradiance(
                    st.bits, pts.normals, cube, L, parallel.part(tick, 0.0, 0.5)))
            if cached:
                tick = parallel.part(tick, 0.5, 1.0)
            view_dirs = None
            if view_dir is not None:
                view_dirs = np.broadcast_to(np.asarray(view_dir, dtype=np.float64),
                                            pts.normals.shape)
            radiance = reference.shade_points(st.bits, pts.positions, pts.normals, pts.materials,
                                              st.materials, eye, cube, L,
                                              irradiance=irradiance, view_dirs=view_dirs,
                                              tick=tick)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out

