"""BLOCKS: locally adaptive per-block products (Inger, Farbman, Lischinski 2013, §4).

The stored visibility is re-encoded per 16x16 cubemap block as differential
change indices (eq. 5), serialized as base-128 varints and stored in the .blend
next to the bit-packed form (blob ``blocks`` of :mod:`..storage`: ``derive``/``store``
at precompute; ``sync`` loads it).  Each frame runs Algorithm 1 for every (vertex,
block) pair with the BRDF sampled per vertex for the current view
(:mod:`...core.methods.blocks.shading`).  Lighting block forms (§4.3) and the view-independent line-9
products are cached per world.
"""

from __future__ import annotations

import numpy as np

from ....core.methods.blocks import shading as core_blocks, encoding as blocks_encoding, light_tables
from ....core.common import parallel
from ...frame import keys
from ...blender import storage
from ..contract import Shading

#: name of the stored blob (addon.blender.storage)
BLOB = "blocks"
#: recommended minimum cubemap resolution (the paper uses 6x64^2 and 6x128^2)
MIN_RESOLUTION = 64

# Lighting tables per env key (one world at a time).
TABLES = keys.cache(1)
# Differential visibility read from the .blend per stored blob (storage.key).
STORED = keys.cache(16)
# Encoded from the bit-packed visibility when nothing compressed is stored.
_ENCODED = keys.cache(16)
# Active pairs per differential visibility; line-9 products per (pairs, lighting).
_PAIRS = keys.cache(16)
LIGHT_VIS = keys.cache(16)
#: statistics of the last shade() (Tables 1-2 of the paper), for the bench and the UI
LAST_STATS: dict = {}


def thresholds_for(tolerance: float):
    """Rule thresholds (pixel, 16, 4, skip) on the lobe's value relative to its peak."""
    t = float(tolerance)
    return (t, t * 1e-1, t * 1e-2, t * 1e-7)


def _stored_visibility(arrays, meta):
    """(differential visibility, stream bytes) of a stored ``blocks`` blob."""
    stream = arrays.get("stream")
    if stream is None:
        raise storage.Unreadable("no BLOCKS stream in the stored data")
    try:
        return blocks_encoding.deserialize_visibility(stream.tobytes()), int(stream.size)
    except ValueError as exc:
        raise storage.Unreadable(f"BLOCKS stream unreadable ({exc})") from None


class BlocksShading(Shading):


    def view_dependent(self, state) -> bool:
        return any(not m.is_diffuse_only or m.fresnel == "DIELECTRIC"
                   for st in state.objects for m in st.materials)

    # ------------------------------------------------------------ precompute
    def derive(self, job):
        """Differential visibility (eq. 5) of every object, serialized as varints."""
        out = {}
        for o in job.objects:
            if job.cancel_requested:
                raise parallel.Cancelled()
            dv = blocks_encoding.encode_visibility(o.bits, job.resolution)
            out[o.name] = blocks_encoding.serialize_visibility(dv)
        return out

    def store(self, scene, job, derived):
        if not derived:
            return
        for o in job.objects:
            data = derived.get(o.name)
            if data is None:
                continue
            stream = np.asarray(data, dtype=np.uint8).reshape(-1)
            storage.put(storage.owner(o.name), BLOB, storage.pack({"stream": stream}))

    # ------------------------------------------------------------ frames
    def sync(self, state):
        for st in state.objects:
            st.data.pop("blocks_dv", None)
            ob = storage.owner(st.name)
            if st.status != "ok" or ob is None:
                continue
            got = storage.load(ob, BLOB, STORED, _stored_visibility, state.note)
            if got is None:
                continue
            dv, nbytes = got
            if dv.count != st.points.count or dv.resolution != state.resolution:
                continue
            st.data["blocks_dv"] = dv
            st.data["blocks_stream_bytes"] = nbytes

    def visibility_of(self, st, resolution):
        """The object's differential visibility: stored, else encoded from its bits."""
        dv = st.data.get("blocks_dv")
        if dv is not None and dv.resolution == resolution:
            return dv, "stored"
        dv = keys.per_visibility(_ENCODED, (st.name, id(st.bits), resolution), st.bits,
                                 lambda: blocks_encoding.encode_visibility(st.bits, resolution))
        return dv, "encoded"

    def shade(self, state, eye, view_dir):
        res = int(state.resolution)
        if res < MIN_RESOLUTION:
            state.note(f"BLOCKS works on 16x16 blocks: at 6x{res}x{res} a cube face has only "
                       f"{res // 16}x{res // 16} of them; precompute with Directions 6x64x64 "
                       "or 6x128x128 as in the paper")
        L = keys.environment_cubemap(state.world, res)
        key = keys.env_key(state.world, res)
        tables = keys.held(TABLES, key, (), lambda: light_tables.light_tables(L, res))
        thresholds = thresholds_for(state.settings.get("blocks_tolerance", 0.1))
        stats = core_blocks.BlocksStats()
        sources = []
        out = []
        for i, st in enumerate(state.objects):
            state.tick(i / len(state.objects))      # progress; ESC stops here
            pts = st.points
            dv, source = self.visibility_of(st, res)
            sources.append(source)
            pairs = keys.per_visibility(_PAIRS, (st.name, id(dv)), dv,
                                        lambda: light_tables.active_pairs(dv))
            light_vis = keys.per_visibility(
                LIGHT_VIS, (st.name, id(pairs), key), pairs,
                lambda: light_tables.light_vis_sums(pairs, tables))
            irradiance = keys.per_visibility(
                LIGHT_VIS, (st.name, id(pairs), key, "E"), pairs,
                lambda: light_tables.lambert_irradiance(light_vis, pts.normals))
            view_dirs = None
            if view_dir is not None:
                view_dirs = np.broadcast_to(np.asarray(view_dir, dtype=np.float64),
                                            pts.normals.shape)
            radiance = core_blocks.shade_points(
                pairs, light_vis, tables, pts.positions, pts.normals, pts.materials,
                st.materials, eye, view_dirs=view_dirs, irradiance=irradiance,
                thresholds=thresholds, stats=stats)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        LAST_STATS.clear()
        LAST_STATS.update(stats=stats, sources=sources)
        return out

