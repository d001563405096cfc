"""Shadow rays against many placed copies of a few meshes, without placing their triangles.

embreex exposes no Embree instance geometry, and a scatter of a thousand 10k-triangle
instances placed as world triangles is a BVH of about a gigabyte.  A two-level test in its
stead: each source mesh is one Embree scene in its own frame, and a scene of the
instances' world bounding boxes (12 triangles each) says which instances a ray passes.
A ray is tested against every instance whose box it crosses or starts or ends in, in its
source's frame (the ray's origin and direction carried by the instance's inverse matrix:
the ray parameter, hence its length, is the same there).  It walks the box faces along
its line: a face before the segment's end is one the segment crosses, and a box's first
face being an exit (before the end, or within a box's diagonal past it) means the
segment starts (ends) inside it.  The objects that are not instances are one world
scene, tested first.
"""

from __future__ import annotations

import numpy as np

from .mesh import Occluders, bounding_box
from .rigid import invertible
from .visibility import build_occluder_scene

#: the 12 triangles of a box over its 8 corners (bit 0: x max, bit 1: y max, bit 2: z max),
#: two per face: z min, z max, y min, y max, x min, x max
_BOX = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                 [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int32)
#: each face's axis and outward sign (triangle k is face k // 2)
_FACE_AXIS = np.array([2, 2, 1, 1, 0, 0])
_FACE_SIGN = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])


class PlacedOccluders:
    """``occluded(origins, dirs, dists, start=None)`` -> (N,) bool, as an Embree scene of
    every triangle placed in the world would answer it.

    ``world``: the objects that are not instances (core.scene.mesh.Occluders or (T, 3, 3)
    world corners); ``sources``: each source mesh's occluders in its own frame;
    ``instances``: ``(source index, 4x4 matrix)`` per instance."""

    def __init__(self, world, sources, instances):
        # an instance flattened to no volume (a scale of 0) has no inverse: placed instead
        flat = [i for i, (_, mat) in enumerate(instances) if not invertible(mat)]
        if flat:
            placed = [Occluders((np.asarray(sources[instances[i][0]].vertices, np.float64)
                                 @ np.asarray(instances[i][1], np.float64)[:3, :3].T
                                 + np.asarray(instances[i][1], np.float64)[:3, 3]
                                 ).astype(np.float32), sources[instances[i][0]].triangles)
                      for i in flat]
            world = Occluders.join([world] + placed) if isinstance(world, Occluders) else \
                np.concatenate([np.asarray(world, np.float32).reshape(-1, 3, 3)]
                               + [o.positions.astype(np.float32) for o in placed])
        #: each given instance's index here (-1: placed with the world; the last: none)
        self.slot = np.full(len(instances) + 1, -1, np.int64)
        kept = sorted(set(range(len(instances))) - set(flat))
        self.slot[kept] = np.arange(len(kept))
        instances = [instances[i] for i in kept]
        self.world = build_occluder_scene(world) if len(world) else None
        self.sources = [build_occluder_scene(s) for s in sources]
        self.source_of = np.array([s for s, _ in instances], np.int64)
        m = np.array([np.asarray(mat, np.float64) for _, mat in instances]).reshape(-1, 4, 4)
        self.inverse = np.linalg.inv(m) if len(m) else m
        corners = []
        # once per source (a source with no finite corner: a point at the origin)
        boxes = [b if len(b) else np.zeros((2, 3))
                 for b in (bounding_box(src.vertices) for src in sources)]
        for s, mat in instances:
            w = _corners(*boxes[s]) @ np.asarray(mat, np.float64)[:3, :3].T \
                + np.asarray(mat, np.float64)[:3, 3]
            wlo, whi = w.min(axis=0), w.max(axis=0)
            pad = 1e-4 * max(float(np.max(whi - wlo)), 1e-9)
            corners.append(_corners(wlo - pad, whi + pad))
        corners = np.asarray(corners, np.float32).reshape(-1, 8, 3)
        #: how far past a box face a ray goes on (its parameter: the scene's scale)
        self.eps = 1e-6 * float(np.ptp(corners.reshape(-1, 3), axis=0).max()) \
            if len(corners) else 0.0
        #: the longest box diagonal: past a segment's end, a box it ends in is left within it
        self.reach = float(np.linalg.norm(corners[:, 7] - corners[:, 0], axis=1).max()) \
            if len(corners) else 0.0
        self.boxes = (build_occluder_scene(corners[:, _BOX].reshape(-1, 3, 3))
                      if len(corners) else None)

    def occluded(self, origins, dirs, dists, start=None) -> np.ndarray:
        """(N,) True where the segment ``origins + t dirs``, ``0 < t < dists``, hits a
        triangle; ``start`` (N,) the instance each ray starts on (-1: none)."""
        o = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        d = np.ascontiguousarray(dirs, np.float32).reshape(-1, 3)
        far = np.ascontiguousarray(np.minimum(np.asarray(dists, np.float64), 1e30),
                                   np.float32).reshape(-1)
        blocked = np.zeros(len(o), bool)
        if self.world is not None and len(o):
            blocked = self.world.run(o, d, dists=far, query="OCCLUDED") != -1
        if self.boxes is None:
            return blocked
        if start is not None:
            start = self.slot[np.asarray(start, np.int64).reshape(-1)]
            s = start
            sel = np.nonzero(~blocked & (s >= 0))[0]
            blocked[sel] = self._test(o[sel], d[sel], far[sel], s[sel])
        # walk the box faces along each free ray's line (module docstring)
        t0 = np.zeros(len(o), np.float32)
        last = np.full(len(o), -1, np.int64) if start is None \
            else np.array(start, np.int64).reshape(-1)
        seen = {}                     # (ray, instance) pairs past the end already judged
        stop = (far.astype(np.float64) + self.reach + 2.0 * self.eps).astype(np.float32)
        active = np.nonzero(~blocked)[0]
        while len(active):
            a = active
            oa = o[a] + t0[a, None] * d[a]
            got = self.boxes.run(np.ascontiguousarray(oa, np.float32), d[a],
                                 dists=np.maximum(stop[a] - t0[a], 0.0).astype(np.float32),
                                 query="INTERSECT", output=1)
            prim, tfar = got["primID"], got["tfar"]
            hit = prim >= 0
            a, tfar, prim = a[hit], tfar[hit], prim[hit]
            inst, face = prim // len(_BOX), prim % len(_BOX) // 2
            t = t0[a] + tfar
            leaving = _FACE_SIGN[face] * d[a, _FACE_AXIS[face]] > 0.0
            within = t <= far[a]
            # past the end only a box's first face matters: an exit means it ends inside
            key = a * len(self.source_of) + inst
            first = np.array([k not in seen for k in key.tolist()], bool) if (~within).any() \
                else np.ones(len(a), bool)
            for k in key[~within].tolist():
                seen[k] = True
            test = (inst != last[a]) & (within | (first & leaving))
            if test.any():
                blocked[a[test]] = self._test(o[a[test]], d[a[test]], far[a[test]], inst[test])
            last[a] = inst
            t0[a] = t + np.float32(self.eps)            # on, past the face
            active = a[~blocked[a] & (t0[a] < stop[a])]
        return blocked

    def _test(self, o, d, far, inst) -> np.ndarray:
        """Each ray against its instance, in its source's frame (grouped by source)."""
        out = np.zeros(len(o), bool)
        src = self.source_of[inst]
        for s in np.unique(src):
            sel = np.nonzero(src == s)[0]
            inv = self.inverse[inst[sel]]
            lo = np.einsum("nij,nj->ni", inv[:, :3, :3], o[sel].astype(np.float64)) + inv[:, :3, 3]
            ld = np.einsum("nij,nj->ni", inv[:, :3, :3], d[sel].astype(np.float64))
            out[sel] = self.sources[s].run(np.ascontiguousarray(lo, np.float32),
                                           np.ascontiguousarray(ld, np.float32),
                                           dists=far[sel], query="OCCLUDED") != -1
        return out


def _corners(lo, hi) -> np.ndarray:
    """(8, 3) the corners of the box ``lo``..``hi`` (corner ``b``: bit ``k`` takes axis
    ``k`` from ``hi``)."""
    return np.array([[(hi if b >> k & 1 else lo)[k] for k in range(3)] for b in range(8)])
