"""REFERENCE: the pixel-basis triple product over every cubemap texel (exact for the
cubemap; the yardstick every other method is measured against).  The sums run as GPU passes
where a GPU context is at hand (``scene.prt.reference_gpu``; the diffuse one, cached per
lighting, only on a hardware GPU), numpy otherwise."""

from __future__ import annotations

import hashlib

import numpy as np

from ....core.sphere import directions
from ....core.methods.reference import shading as reference
from ....core.common import parallel
from ....core.shading.materials import slot_material
from ...frame import keys
from ...gpu import drawing
from ..contract import Shading, glossy_or_layered
from . import gpu as reference_gpu

# View-independent diffuse sums per (object, visibility, lighting).
IRRADIANCE_CACHE = keys.cache(64)
# The visible texels near each point's horizon per (object, visibility): what the diffuse
# sums of another lighting (a turned HDRI) check the cosine's clamp at
HORIZON_CACHE = keys.cache(64)


class ReferenceShading(Shading):

    def view_dependent(self, state) -> bool:
        return glossy_or_layered(state)

    def shades_on_gpu(self, state) -> bool:
        return (bool(state.settings.get("reference_gpu", True)) and drawing.gpu_available()
                and not drawing.software_gpu())

    def shade(self, state, eye, view_dir):
        cube = directions.cubemap(state.resolution)
        L = keys.environment_cubemap(state.world, state.resolution)
        env_key = keys.env_key(state.world, state.resolution)
        use_gpu = bool(state.settings.get("reference_gpu", True)) and drawing.gpu_available()
        out = []
        n = len(state.objects)
        for i, st in enumerate(state.objects):
            pts = st.points
            # progress per block of points (ESC stops between them): the irradiance is
            # the first half of an object when it is not cached, its glossy part the rest
            tick = parallel.part(state.tick, i / n, (i + 1) / n)
            state.tick(i / n)
            cached = []
            # an F12 frame sums only the points its camera may see (the others are drawn
            # by no pixel: 0 there); a viewport's sums serve every view, so all points
            seen = state.seen_points(st)
            if seen is not None and seen.all():
                seen = None                    # every point: the viewport's sums
            seen_key = None if seen is None else hashlib.sha1(np.packbits(seen)).hexdigest()

            def irradiance_sums(st=st, pts=pts, tick=tick, seen=seen):
                cached.append(1)
                # a dense sum (every visible texel, no BRDF): BLAS is the faster on a
                # software rasterizer's cores (diffuse Suzanne and ground: 0.13 s, the
                # pass 0.23 s), the pass on a GPU
                if use_gpu and not drawing.software_gpu():
                    try:
                        return reference_gpu.irradiance(st, pts.normals, cube, L)
                    except Exception as exc:          # numpy gives the same sums
                        state.note(f"REFERENCE GPU pass failed ({exc}); shading with numpy")
                pairs = keys.per_visibility(
                    HORIZON_CACHE, (st.name, st.fingerprint), st.bits,
                    lambda: reference.horizon_pairs(st.bits, pts.normals, cube))
                return reference.diffuse_irradiance(st.bits, pts.normals, cube, L,
                                                    parallel.part(tick, 0.0, 0.5), seen,
                                                    pairs)
            irradiance = keys.per_visibility(
                IRRADIANCE_CACHE, (st.name, id(st.bits), env_key, seen_key), st.bits,
                irradiance_sums)
            if cached:
                tick = parallel.part(tick, 0.5, 1.0)
            view_dirs = None
            if view_dir is not None:
                view_dirs = np.broadcast_to(np.asarray(view_dir, dtype=np.float64),
                                            pts.normals.shape)
            glossy = use_gpu and any(not slot_material(st.materials, m).is_diffuse_only
                                     for m in np.unique(pts.materials))
            radiance = reference.shade_points(st.bits, pts.positions, pts.normals, pts.materials,
                                              st.materials, eye, cube, L,
                                              irradiance=irradiance, view_dirs=view_dirs,
                                              tick=tick, glossy=not glossy)
            if glossy:
                try:
                    radiance += reference_gpu.specular_radiance(
                        st, pts.normals, pts.materials, st.materials, cube, L,
                        reference.point_views(pts.positions, eye, view_dir), env_key,
                        state.seen_points(st))
                except Exception as exc:          # numpy gives the same sums
                    state.note(f"REFERENCE GPU pass failed ({exc}); shading with numpy")
                    use_gpu = False
                    radiance = reference.shade_points(
                        st.bits, pts.positions, pts.normals, pts.materials, st.materials, eye,
                        cube, L, irradiance=irradiance, view_dirs=view_dirs, tick=tick)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out
