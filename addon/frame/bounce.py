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
from ...core.scene import mesh as core_mesh, visibility
from ...core.shading import brdf
from ...core.shading.materials import slot_material
from ...core.sphere import directions
from ...core.pipeline import frame_status
from ...core.store import layouts
from ...core.transport import bounce as core_bounce
from ..blender import storage
from . import keys

# decoded bounce blobs per stored blob (storage.key)
_ROWS = keys.cache(128)
# the clusters' samples and reflectance per set of stored blobs (and materials)
_SCENE = keys.cache(4)
# the static occluders' Embree scene per geometry (lamps' shadow rays)
_OCCLUDERS = keys.cache(1)
# the clusters' World irradiance per (blobs, lighting)
_WORLD = keys.cache(2)


def stored_rows(ob, points: int, note=None):
    """``(bounce arrays (core.store.layouts.bounce_arrays), blob key)`` of an object's
    stored bounce transfer of its current precompute, or None (none stored, or not for
    its points)."""
    k = storage.key(ob, layouts.BOUNCE)
    got = storage.load(ob, layouts.BOUNCE, _ROWS, layouts.bounce_arrays, note)
    if got is None or len(got["columns"]) != points:
        return None
    return got, k


def occlusion_test(objs):
    """``occluded(origins, dirs, dists)`` -> (N,) bool against the synced objects ``objs``
    (lamps' shadow rays; the Embree scene kept per geometry)."""
    key = tuple(st.fingerprint for st in objs)
    scene = keys.held(_OCCLUDERS, key, (), lambda: visibility.build_occluder_scene(
        np.concatenate([core_mesh.occluder_triangles(st.arrays)[0] for st in objs])))
    diag = core_mesh.bounding_diagonal(core_mesh.bounds([st.arrays for st in objs]))
    step = 1e-4 * max(diag, 1e-6)

    def occluded(origins, dirs, dists):
        o = np.ascontiguousarray(origins + step * dirs, np.float32)
        d = np.ascontiguousarray(dirs, np.float32)
        far = np.ascontiguousarray(np.minimum(dists - 2 * step, 1e30), np.float32)
        return scene.run(o, d, dists=far, query="OCCLUDED") != -1
    return occluded


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
            data, k = st.bounce
            receivers.append((i, data))
            blob_keys.append(k)
            counts.add(data["clusters"])
        if missing:
            state.note("Precomputed without bounced light (press Precompute for the Light "
                       "Paths' bounces): " + frame_status.listing(sorted(missing)))
        if not receivers or len(counts) != 1:
            return None
        return cls(receivers, counts.pop(), bounces, tuple(blob_keys))

    # ------------------------------------------------------------------ clusters
    def _samples(self):
        """The clusters' samples and rows gathered from every object: (sample cluster,
        weight, position, normal, bits, sample resolution, cluster rows' columns (K, W)
        and weights (K, W))."""
        parts = [tuple(d[n] for n in ("sample_cluster", "sample_weight", "sample_position",
                                      "sample_normal", "sample_bits"))
                 for _, d in self.receivers]
        cluster, weight, pos, nrm, bits = (np.concatenate(p) for p in zip(*parts))
        width = max(d["cluster_columns"].shape[1] for _, d in self.receivers)
        k_cols = np.zeros((self.clusters, width), np.int32)
        k_w = np.zeros((self.clusters, width), np.float32)
        for _, d in self.receivers:
            n = d["cluster_columns"].shape[1]
            k_cols[d["cluster_ids"], :n] = d["cluster_columns"]
            k_w[d["cluster_ids"], :n] = d["cluster_weights"]
        res = self.receivers[0][1]["sample_resolution"]
        return cluster.astype(np.int64), weight, pos, nrm, bits, res, k_cols, k_w

    def _albedo(self, state) -> np.ndarray:
        """(K, 3) each cluster's reflectance: the area-weighted mean over its triangle
        sides of their material's, diffuse and glossy (a textured colour at its mean)."""
        total = np.zeros((self.clusters, 3))
        area = np.zeros(self.clusters)
        for i, d in self.receivers:
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
        cluster, weight, pos, nrm, bits, res, k_cols, k_w = keys.held(
            _SCENE, ("samples", self.key), (), self._samples)
        direct = np.zeros((len(cluster), 3))
        world = state.world
        if world is not None and len(cluster):
            direct += keys.held(_WORLD, (self.key, keys.env_key(world, res)), (),
                                lambda: reference.diffuse_irradiance(
                                    bits, nrm, directions.cubemap(res),
                                    keys.environment_cubemap(world, res)))
        # the World's compact sources (a sun) as distant lights with shadow rays: through
        # the samples' coarse cubemap a sun falls in one texel, whose centre misses or
        # finds a window's edge for the whole texel
        lamps = [core_bounce.distant_source(s.direction, s.radiance, s.radius, s.point_like)
                 for s in state.sources]
        lamps += list(state.lamps) + list(state.drawn_lamps)
        if lamps and len(cluster):
            direct += core_bounce.lamp_irradiance(lamps, pos, nrm, self._occluded(state))
        per_cluster = np.stack([np.bincount(cluster, weights=weight * direct[:, c],
                                            minlength=self.clusters) for c in range(3)], 1)
        mats = tuple(tuple(state.objects[i].materials) for i, _ in self.receivers)
        albedo = keys.held(_SCENE, ("albedo", self.key, mats), (), lambda: self._albedo(state))
        return core_bounce.bounce(per_cluster, albedo, k_cols, k_w, self.bounces)

    # ------------------------------------------------------------------ receivers
    def irradiance(self, state) -> list:
        """Per state object: its points' bounced irradiance (P, 3), or None."""
        radiance = self.cluster_radiance(state)
        out = [None] * len(state.objects)
        for i, d in self.receivers:
            out[i] = core_bounce.receive(d["columns"], d["weights"], radiance)
        return out
