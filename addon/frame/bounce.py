"""Bounced light in a frame: the stored transfer rows of the static objects (core.transport,
blob ``bounce``) driven by the frame's direct light at the gather clusters, added to every
receiver's diffuse radiance.

The number of bounces follows the scene's Cycles *Light Paths* (0: nothing is added, the
frame is the direct one).  The World less its compact sources lights the clusters through
their stored visibility; lamps through shadow rays traced at the frame (an
occluder scene of the static objects, kept per geometry), as do the World's compact sources
(a sun).  Turning the HDRI, moving or
recolouring a lamp, editing a material's colour update the bounce with no precompute.
A dynamic object neither sends nor receives bounced light, nor shadows it (its direct
shadows move with it; the transfer is of the static scene).
"""

from __future__ import annotations

import numpy as np

from ...core.methods.reference import shading as reference
from ...core.scene import mesh as core_mesh, placed_occluders
from ...core.shading import brdf
from ...core.shading.materials import slot_material
from ...core.sphere import directions
from ...core.pipeline import frame_status
from ...core.common import codec
from ...core.store import layouts
from ...core.transport import bounce as core_bounce
from ..blender import storage
from . import keys

# decoded bounce blobs per stored blob (storage.key): an object keeps its compressed blob
# (StoredBounce) and decodes it through here, so a scatter of a thousand instances holds at
# most 64 MiB of them decoded at once
_ROWS = keys.cache(128, max_bytes=64 * 2**20)
# the clusters' samples and reflectance per set of stored blobs (and materials)
_SCENE = keys.cache(4)
# the static occluders' Embree scene per geometry (lamps' shadow rays)
_OCCLUDERS = keys.cache(1)
# the clusters' World irradiance per (blobs, lighting)
_WORLD = keys.cache(2)


class StoredBounce:
    """An object's stored bounce transfer, read without bpy: its compressed blob, taken on
    the main thread at the sync and decoded (core.store.layouts.bounce_arrays) when read,
    kept in :data:`_ROWS` (bounded), not by the object."""
    __slots__ = ("key", "blob", "clusters")

    def __init__(self, key, blob: bytes, clusters: int):
        self.key, self.blob, self.clusters = key, blob, int(clusters)

    def __call__(self) -> dict:
        return keys.held(_ROWS, self.key, (),
                         lambda: layouts.bounce_arrays(*codec.unpack(self.blob)))


def stored_rows(ob, points: int, note=None):
    """A :class:`StoredBounce` of an object's stored bounce transfer of its current
    precompute, or None (none stored, or its rows are not of its points)."""
    k = storage.key(ob, layouts.BOUNCE)
    got = storage.load(ob, layouts.BOUNCE, _ROWS, layouts.bounce_arrays, note)
    if got is None or len(got["columns"]) != points:
        return None
    return StoredBounce(k, storage.blob(ob, layouts.BOUNCE), got["clusters"])


def occlusion_test(objs):
    """``occluded(origins, dirs, dists, start=None)`` -> (N,) bool against the synced
    objects ``objs`` (lamps' shadow rays), kept per geometry: an instance through its
    source's triangles (core.scene.placed_occluders: a scatter's triangles are not placed);
    ``start`` (N,) the index into ``objs`` of the object each ray leaves (-1: none)."""
    key = tuple(st.fingerprint for st in objs)
    scene, own = keys.held(_OCCLUDERS, key, (), lambda: _placed_occluders(objs))
    diag = core_mesh.bounding_diagonal(core_mesh.bounds([st.arrays for st in objs]))
    step = 1e-4 * max(diag, 1e-6)

    def occluded(origins, dirs, dists, start=None):
        return scene.occluded(origins + step * dirs, dirs, np.minimum(dists - 2 * step, 1e30),
                              None if start is None else own[np.asarray(start, np.int64)])
    return occluded


def _placed_occluders(objs):
    """``(PlacedOccluders, (len(objs) + 1,) instance of each object or -1)``: the objects
    that are not instances placed, the instances through their sources."""
    plain, sources, index, instances = [], [], {}, []
    own = np.full(len(objs) + 1, -1, np.int64)            # own[-1]: a ray of no object
    for i, st in enumerate(objs):
        if st.local_source is None:
            plain.append(core_mesh.occluder_mesh(st.arrays)[0])
            continue
        fingerprint, local = st.local_source
        if fingerprint not in index:
            index[fingerprint] = len(sources)
            sources.append(core_mesh.occluder_mesh(local)[0])
        own[i] = len(instances)
        instances.append((index[fingerprint], st.matrix))
    return placed_occluders.PlacedOccluders(core_mesh.Occluders.join(plain), sources,
                                            instances), own


class FrameBounce:
    """The bounce transfer of the objects synced into a frame state."""

    def __init__(self, receivers, clusters_count, bounces, blob_keys):
        #: (index into state.objects, its bounce arrays) of each static object with rows
        self.receivers = receivers
        self.clusters = clusters_count
        self.bounces = int(bounces)
        self.key = blob_keys

    @classmethod
    def of(cls, state, bounces: int):
        """The frame's bounce, or None when the scene has no bounces, or no object carries
        transfer rows of its current precompute (a note says so when some are missing)."""
        if bounces <= 0:
            return None
        receivers, blob_keys, counts, missing = [], [], set(), []
        for i, st in enumerate(state.objects):
            # a static object shadowed by dynamic ones ("posed") keeps its bounce
            if st.status not in ("ok", "posed") or st.dynamic is not None:
                continue
            if st.bounce is None:
                missing.append(st.name)
                continue
            receivers.append((i, st.bounce))
            blob_keys.append(st.bounce.key)
            counts.add(st.bounce.clusters)
        if missing:
            state.note("Precomputed without bounced light (press Precompute for the Light "
                       "Paths' bounces): " + frame_status.listing(sorted(missing)))
        if not receivers or len(counts) != 1:
            return None
        return cls(receivers, counts.pop(), bounces, tuple(blob_keys))

    # ------------------------------------------------------------------ clusters
    def _samples(self):
        """The clusters' samples and rows gathered from every object, one blob decoded at
        a time: (sample cluster, weight, position, normal, the receiver it lies on,
        cluster rows' columns (K, W) and weights (K, W) float16); their visibility stays
        in the blobs (:meth:`_world`)."""
        parts, owner = [], []
        k_cols = np.zeros((self.clusters, 0), np.int32)
        k_w = np.zeros((self.clusters, 0), np.float16)
        for _, sb in self.receivers:
            d = sb()
            parts.append(tuple(d[n] for n in ("sample_cluster", "sample_weight",
                                              "sample_position", "sample_normal")))
            owner.append(np.full(len(d["sample_cluster"]), len(owner), np.int32))
            c = d["cluster_columns"]
            if c.shape[1] > k_cols.shape[1]:
                grow = ((0, 0), (0, c.shape[1] - k_cols.shape[1]))
                k_cols, k_w = np.pad(k_cols, grow), np.pad(k_w, grow)
            k_cols[d["cluster_ids"], :c.shape[1]] = c
            k_w[d["cluster_ids"], :c.shape[1]] = d["cluster_weights"]
        cluster, weight, pos, nrm = (np.concatenate(p) for p in zip(*parts))
        return cluster.astype(np.int64), weight, pos, nrm, np.concatenate(owner), k_cols, k_w

    def _world(self, world) -> np.ndarray:
        """(S, 3) the World's irradiance (less its compact sources) at every sample, from
        each object's stored sample visibility (one blob decoded at a time)."""
        res = self.receivers[0][1]()["sample_resolution"]
        cube, env = directions.cubemap(res), keys.environment_cubemap(world, res)
        out = []
        for _, sb in self.receivers:
            d = sb()
            out.append(reference.diffuse_irradiance(d["sample_bits"], d["sample_normal"],
                                                    cube, env))
        return np.concatenate(out)

    def _albedo(self, state) -> np.ndarray:
        """(K, 3) each cluster's reflectance: the area-weighted mean over its triangle
        sides of their material's, diffuse and glossy (a textured colour at its mean)."""
        total = np.zeros((self.clusters, 3))
        area = np.zeros(self.clusters)
        for i, sb in self.receivers:
            d = sb()
            st = state.objects[i]
            arrays = st.arrays
            tri = arrays.triangles[:arrays.front_triangles]
            a = core_mesh.triangle_areas(arrays.positions[arrays.corner_verts[tri]])
            slots = arrays.corner_materials[tri[:, 0]]
            table = np.array([core_bounce.reflectance(
                slot_material(st.materials, m), brdf.diffuse_view_weight)
                for m in range(max(len(st.materials), 1))])
            rho = table[np.clip(slots, 0, len(table) - 1)]
            for side in ("front", "back"):
                c = d.get(side)
                if c is None:
                    continue
                c = np.asarray(c, np.int64)
                area += np.bincount(c, weights=a, minlength=self.clusters)
                for ch in range(3):
                    total[:, ch] += np.bincount(c, weights=a * rho[:, ch],
                                                minlength=self.clusters)
        return total / np.maximum(area, 1e-300)[:, None]

    def _occluded(self, state):
        """``occluded(origins, dirs, dists)`` against the static objects (lamps' shadows)."""
        return occlusion_test([state.objects[i] for i, _ in self.receivers])

    def cluster_radiance(self, state) -> np.ndarray:
        """(K, 3) the radiance the clusters send, all bounces summed."""
        cluster, weight, pos, nrm, owner, k_cols, k_w = keys.held(
            _SCENE, ("samples", self.key), (), self._samples)
        direct = np.zeros((len(cluster), 3))
        world = state.world
        if world is not None and len(cluster):
            res = self.receivers[0][1]()["sample_resolution"]
            direct += keys.held(_WORLD, (self.key, keys.env_key(world, res)), (),
                                lambda: self._world(world))
        # the World's compact sources (a sun) as distant lights with shadow rays: through
        # the samples' coarse cubemap a sun falls in one texel, whose centre misses or
        # finds a window's edge for the whole texel
        lamps = [core_bounce.distant_source(s.direction, s.radiance, s.radius, s.point_like)
                 for s in state.sources]
        lamps += list(state.lamps) + list(state.drawn_lamps)
        if lamps and len(cluster):
            test = self._occluded(state)
            direct += core_bounce.lamp_irradiance(
                lamps, pos, nrm, lambda o, d, t, rows: test(o, d, t, owner[rows]))
        per_cluster = np.stack([np.bincount(cluster, weights=weight * direct[:, c],
                                            minlength=self.clusters) for c in range(3)], 1)
        mats = tuple(tuple(state.objects[i].materials) for i, _ in self.receivers)
        albedo = keys.held(_SCENE, ("albedo", self.key, mats), (), lambda: self._albedo(state))
        return core_bounce.bounce(per_cluster, albedo, k_cols, k_w, self.bounces)

    # ------------------------------------------------------------------ receivers
    def irradiance(self, state) -> list:
        """Per state object: its points' bounced irradiance (P, 3), or None."""
        radiance = self.cluster_radiance(state)
        k_cols, k_w = keys.held(_SCENE, ("samples", self.key), (), self._samples)[-2:]
        seen = core_bounce.seen_radiance(k_cols, k_w, radiance)
        out = [None] * len(state.objects)
        for i, sb in self.receivers:
            d = sb()
            arrays, pts = state.objects[i].arrays, state.objects[i].points
            # a row's rest at what its own triangles' clusters see (a two-sided mesh's back
            # triangles follow its front ones: core.scene.mesh.with_back_sides)
            sides = [d["front"]] + ([d["back"]] if "back" in d and arrays.two_sided else [])
            tri = arrays.triangles[:arrays.front_triangles * len(sides)]
            light = core_bounce.rest_radiance(
                seen, np.concatenate(sides), pts.point_of_corner[tri],
                core_mesh.triangle_areas(arrays.positions[arrays.corner_verts[tri]]), pts.count)
            out[i] = core_bounce.receive(d["columns"], d["weights"], radiance, d["rest"], light)
        return out
